"""Tests of racing_lib.vehicle: parameters and force laws against closed-form truths."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from racing_lib.errors import ModelError, RacingLibError
from racing_lib.vehicle import (
    CASADI_OPS,
    MATH_OPS,
    NUMPY_OPS,
    VehicleParams,
    drag_force,
    drive_force,
    drive_force_envelope,
    engine_torque,
    engine_torque_ops,
    lateral_load_transfer,
    longitudinal_load_transfer,
    ops_for,
    pacejka_lateral,
    rolling_resistance,
    static_axle_loads,
    wheel_loads,
)

P = VehicleParams()


def test_defaults_are_the_papers_table():
    assert (P.m, P.l_f, P.l_r, P.width, P.h_c) == (1355.2, 0.9338, 1.6363, 2.008, 0.6161)
    assert (P.mu, P.C_xw, P.I_zz) == (1.25, 0.1302, 2475.33)


@pytest.mark.parametrize("change", [{"m": float("nan")}, {"m": -1.0}, {"engine_rpm": (1.0,)}])
def test_bad_params_raise_model_error(change):
    with pytest.raises(ModelError) as err:
        VehicleParams(**change)
    assert isinstance(err.value, RacingLibError)


def test_ops_for_picks_the_backend():
    assert ops_for(1.0, 2) is MATH_OPS
    assert ops_for(1.0, np.zeros(3)) is NUMPY_OPS
    assert ops_for(ca.SX.sym("a"), 1.0) is CASADI_OPS


def test_pacejka_peak_and_backends_agree():
    b, c, d, mu, fz = 10.0, 1.9, 1.0, 1.25, 4000.0
    alpha_peak = math.tan(math.pi / (2.0 * c)) / b  # where C atan(B alpha) = pi / 2
    assert pacejka_lateral(alpha_peak, fz, mu, b, c, d) == pytest.approx(mu * fz * d, rel=1e-12)
    assert pacejka_lateral(0.0, fz, mu, b, c, d) == 0.0
    alphas = np.linspace(-0.3, 0.3, 7)
    as_array = pacejka_lateral(alphas, fz, mu, b, c, d)
    a = ca.SX.sym("a")
    f = ca.Function("f", [a], [pacejka_lateral(a, fz, mu, b, c, d)])
    for al, fa in zip(alphas, as_array, strict=True):
        assert pacejka_lateral(float(al), fz, mu, b, c, d) == pytest.approx(fa, rel=1e-12)
        assert float(f(al)) == pytest.approx(fa, rel=1e-12)
    # odd and bounded by the friction limit
    np.testing.assert_allclose(as_array, -as_array[::-1], atol=1e-9)
    assert np.all(np.abs(as_array) <= mu * fz * d + 1e-9)


def test_drag_and_rolling_resistance():
    assert drag_force(50.0, 0.13) == pytest.approx(325.0)
    assert drag_force(-10.0, 0.13) == pytest.approx(-13.0)  # against the motion
    assert rolling_resistance(10_000.0, 0.012) == pytest.approx(120.0)


def test_load_transfer_conserves_load_and_moves_it_the_right_way():
    f_zf, f_zr = static_axle_loads(P.m, P.l_f, P.l_r, P.g)
    assert f_zf + f_zr == pytest.approx(P.m * P.g)
    assert f_zf * P.l_f == pytest.approx(f_zr * P.l_r)  # moment balance about the CoG
    dw = longitudinal_load_transfer(P.m, 3.0, P.h_c, P.l_f, P.l_r)
    assert dw == pytest.approx(P.m * 3.0 * P.h_c / (P.l_f + P.l_r))
    dwf, dwr = lateral_load_transfer(P.m, 5.0, P.h_c, P.l_t, P.l_f, P.l_r)
    # the roll moment m a_y h_c is carried by the two axles' load differences times l_t
    assert (dwf + dwr) * P.l_t == pytest.approx(P.m * 5.0 * P.h_c)
    theta = 0.05
    fl, fr, rl, rr = wheel_loads(P, 3.0, 5.0, theta)
    assert fl + fr + rl + rr == pytest.approx(P.m * P.g * math.cos(theta))
    assert rl + rr > f_zr * math.cos(theta)  # accelerating loads the rear
    assert fr > fl and rr > rl  # a left turn loads the right wheels
    # numpy and casadi give the same loads
    ax = ca.SX.sym("ax")
    f = ca.Function("f", [ax], [ca.vertcat(*wheel_loads(P, ax, 5.0, theta))])
    np.testing.assert_allclose(np.asarray(f(3.0)).ravel(), [fl, fr, rl, rr], rtol=1e-12)


@pytest.mark.parametrize(("a_x", "a_y"), [(0.0, 9.7), (-6.0, -5.0), (3.0, 5.0), (0.0, 0.0)])
def test_wheel_loads_balance_the_pitch_and_roll_moments(a_x, a_y):
    # An independent truth: the wheel loads alone must hold the car against the inertial moments
    # of its centre of gravity, m a_x h_c in pitch and m a_y h_c in roll (wheels at x = l_f or
    # -l_r, y = +-l_t/2, left positive). The paper's Eq. 15 as printed reacts half the roll moment.
    fl, fr, rl, rr = wheel_loads(P, a_x, a_y)
    assert min(fl, fr, rl, rr) > 0.0  # no wheel lifts at these accelerations
    assert fl + fr + rl + rr == pytest.approx(P.m * P.g)
    half_t = 0.5 * P.l_t
    roll = half_t * (fl + rl) - half_t * (fr + rr)
    assert roll == pytest.approx(-P.m * a_y * P.h_c, abs=1e-6)
    pitch = P.l_f * (fl + fr) - P.l_r * (rl + rr)
    assert pitch == pytest.approx(-P.m * a_x * P.h_c, abs=1e-6)


def test_engine_curve_power_limit_and_backends():
    rpms = np.linspace(500.0, 6000.0, 45)
    floats = np.array([engine_torque(P, float(r)) for r in rpms])
    np.testing.assert_allclose(engine_torque_ops(P, rpms), floats, rtol=1e-12, atol=1e-9)
    r = ca.SX.sym("r")
    f = ca.Function("f", [r], [engine_torque_ops(P, r)])
    np.testing.assert_allclose(np.asarray(f(rpms.reshape(1, -1))).ravel(), floats, atol=1e-9)
    power = floats * rpms * 2.0 * math.pi / 60.0
    assert power.max() <= P.power_max + 1e-6
    assert power.max() > 0.95 * P.power_max  # the curve reaches the rated power
    assert engine_torque(P, P.engine_rpm[-1] + 100.0) == 0.0  # rev limiter


def test_gearing_puts_the_rev_limiter_near_190_kmh():
    top_ratio = P.gear_ratios[-1] * P.final_drive
    v_limit = P.engine_rpm[-1] * 2.0 * math.pi / 60.0 / top_ratio * P.r_w
    assert 50.0 < v_limit < 56.0


def test_envelope_is_the_best_gear():
    for v in (5.0, 15.0, 30.0, 45.0):
        best = max(drive_force(P, v, 1.0, g) for g in range(1, len(P.gear_ratios) + 1))
        assert drive_force_envelope(P, v) == pytest.approx(best, rel=1e-9)
    v = ca.SX.sym("v")
    f = ca.Function("f", [v], [drive_force_envelope(P, v)])
    assert float(f(30.0)) == pytest.approx(drive_force_envelope(P, 30.0), rel=1e-9)
