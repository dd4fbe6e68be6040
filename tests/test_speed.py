"""Tests of the quasi-steady-state speed profile against analytic results."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from racing_lib.errors import PlanningError
from racing_lib.model import ModelOptions, ModelParams
from racing_lib.planning.speed import speed_profile

G = 9.81
NO_DRAG = ModelOptions(drag=False)


def circle(radius: float, n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    s = np.linspace(0.0, 2.0 * math.pi * radius, n, endpoint=False)
    return s, np.full(n, 1.0 / radius)


@pytest.mark.parametrize("radius", [20.0, 60.0, 150.0])
def test_circle_speed_is_sqrt_mu_g_r_without_drag(radius):
    s, kappa = circle(radius)
    params = ModelParams(c_rr=0.0)
    prof = speed_profile(s, kappa, params, options=NO_DRAG, v_top=200.0)
    v_expected = math.sqrt(params.mu * G * radius)
    assert prof.success
    np.testing.assert_allclose(prof.v, v_expected, rtol=1e-9)
    # Lap time of a constant speed is the circumference over the speed.
    assert prof.lap_time == pytest.approx(2 * math.pi * radius / v_expected, rel=1e-9)


def test_drag_lowers_the_circle_speed_to_the_friction_ellipse_value():
    radius = 150.0
    s, kappa = circle(radius, 600)
    params = ModelParams()
    no_drag = speed_profile(s, kappa, params, options=NO_DRAG, v_top=200.0)
    drag = speed_profile(s, kappa, params, options=ModelOptions(), v_top=200.0)
    # Steady state: lateral v^2/R and longitudinal (drag + rolling) share the friction circle.
    grip = params.mu * G
    c = params.C_xw / params.m
    # (v^2 / R)^2 + (c v^2 + c_rr g)^2 = grip^2, solved for v^2.
    a = 1 / radius**2 + c**2
    b = 2 * c * params.c_rr * G
    cc = (params.c_rr * G) ** 2 - grip**2
    v_ss = math.sqrt((-b + math.sqrt(b * b - 4 * a * cc)) / (2 * a))
    assert np.all(drag.v < no_drag.v)
    np.testing.assert_allclose(drag.v, v_ss, atol=0.05)


def test_straight_forward_pass_matches_constant_acceleration():
    s = np.linspace(0.0, 500.0, 501)
    v0 = 10.0
    # A point mass: no drag, no rolling resistance, no pedal map, so a = mu g everywhere.
    point_mass = SimpleNamespace(mu=1.25, m=1355.2, C_xw=0.0, c_rr=0.0, D_f=1.0, D_r=1.0)
    prof = speed_profile(
        s, np.zeros_like(s), point_mass, options=NO_DRAG, v_top=1e3, closed=False, v_start=v0
    )
    a = 1.25 * G
    np.testing.assert_allclose(prof.v, np.sqrt(v0**2 + 2 * a * s), rtol=1e-9)
    np.testing.assert_allclose(prof.a_x[:-1], a, rtol=1e-9)


def test_pedal_map_limits_the_acceleration_and_top_speed():
    params = ModelParams()
    s = np.linspace(0.0, 3000.0, 1501)
    prof = speed_profile(
        s, np.zeros_like(s), params, v_top=100.0, closed=False, v_start=5.0, options=NO_DRAG
    )
    xi = np.zeros((s.size, 6))
    xi[:, 0] = prof.v
    _, a_max = params.pedal.limits(xi)
    resist = params.c_rr * G
    # Net acceleration never beats full throttle minus rolling resistance.
    assert np.all(prof.a_x[:-1] <= a_max[:-1] - resist + 1e-6)
    # The map's full-throttle acceleration falls with speed: the car tops out where it equals the
    # rolling resistance, m_0 + m_vx v + m_thr = c_rr g.
    pm = params.pedal
    v_limit = (pm.m_0 + pm.m_thr - resist) / -pm.m_xi[0]
    assert prof.v[-1] < v_limit
    assert prof.v[-1] > 0.9 * v_limit


def test_braking_before_a_corner_is_limited():
    # A straight into a tight hairpin on a closed loop: the speed must fall to the hairpin's
    # limit and the deceleration must stay within mu g (plus drag).
    n = 800
    s = np.linspace(0.0, 2000.0, n, endpoint=False)
    kappa = np.where((s > 900) & (s < 960), 1 / 15.0, 0.0)
    params = ModelParams()
    prof = speed_profile(s, kappa, params)
    assert prof.v[(s > 910) & (s < 950)].max() <= math.sqrt(params.mu * G * 15.0) + 1e-9
    assert prof.a_x.min() >= -(params.mu * G + 1.0)
    assert prof.v.max() > 40.0


def test_expressway_centerline_lap_time_is_plausible():
    from racing_lib.tracks import load_track

    track = load_track("expressway")
    s = track.centerline.sample(ds=3.0)
    prof = speed_profile(
        s,
        track.centerline.curvature(s),
        ModelParams(),
        theta=track.grade(s),
        length=track.length,
    )
    assert prof.success
    assert 95.0 < prof.lap_time < 115.0


def test_bad_input_raises_planning_error():
    with pytest.raises(PlanningError, match="NaN"):
        speed_profile(np.arange(5.0), np.array([0, 0, np.nan, 0, 0]), ModelParams())
    with pytest.raises(PlanningError, match="increasing"):
        speed_profile(np.array([0.0, 2.0, 1.0, 3.0]), np.zeros(4), ModelParams())
