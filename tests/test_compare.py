"""Tests of racing_lib.planning.compare against analytic truths."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from racing_lib.errors import PlanningError
from racing_lib.planning.compare import (
    compare_plans,
    corner_summary,
    line_lap_time,
    speed_profile_trajectory,
    time_along_centerline,
    time_gap,
)
from racing_lib.tracks import circle_track, load_track

# A point mass with friction only: no drag, rolling resistance or powertrain limit, so that on a
# circle of radius R the speed is exactly sqrt(mu g R).
POINT_MASS = SimpleNamespace(mu=1.0, m=1000.0, C_xw=0.0, c_rr=0.0, l_f=1.0, l_r=1.5, pedal=None)


@pytest.fixture(scope="module")
def expressway():
    return load_track("expressway")


@pytest.fixture(scope="module")
def centerline_plan(expressway):
    line = expressway.centerline.position(expressway.centerline.sample(ds=3.0))
    return speed_profile_trajectory(expressway, line, POINT_MASS)


def test_circle_lap_time_is_circumference_over_cornering_speed():
    radius = 100.0
    track = circle_track(radius=radius, width=10.0)
    line = track.centerline.position(track.centerline.sample(n=400))
    lap = line_lap_time(track, line, POINT_MASS)
    v = math.sqrt(1.0 * 9.81 * radius)
    assert lap == pytest.approx(2.0 * math.pi * radius / v, rel=2e-3)


def test_circle_summary_curvature_is_inverse_radius():
    radius = 80.0
    track = circle_track(radius=radius, width=10.0)
    line = track.centerline.position(track.centerline.sample(n=300))
    traj = speed_profile_trajectory(track, line, POINT_MASS)
    (row,) = compare_plans({"circle": traj})
    assert row.mean_abs_kappa == pytest.approx(1.0 / radius, rel=1e-3)
    assert row.length_m == pytest.approx(2.0 * math.pi * radius, rel=1e-4)
    assert row.v_min_mps == pytest.approx(math.sqrt(9.81 * radius), rel=2e-3)


def test_faster_copy_gains_the_scaled_time_everywhere(expressway, centerline_plan):
    factor = 1.25
    fast = centerline_plan.scale_speed(factor)
    s, gap = time_gap(expressway, centerline_plan, fast, n=500)
    t_ref = time_along_centerline(expressway, centerline_plan, s)
    # Driving the same line 1.25 times as fast takes 1/1.25 of the time to every point.
    np.testing.assert_allclose(gap, t_ref * (1.0 / factor - 1.0), atol=1e-6)
    assert t_ref[0] == pytest.approx(0.0, abs=1e-9)
    assert np.all(np.diff(t_ref) > 0)
    rows = compare_plans({"ref": centerline_plan, "fast": fast})
    assert rows[1].gain_s == pytest.approx(centerline_plan.lap_time * (1 / factor - 1), rel=1e-9)


def test_constant_offset_line_reads_as_inside_or_outside_by_corner_direction(expressway):
    offset = 2.0  # m to the left of the centerline everywhere
    x, y, _ = expressway.centerline.to_cartesian(expressway.centerline.sample(ds=3.0), offset)
    traj = speed_profile_trajectory(expressway, (x, y), POINT_MASS)
    rows = corner_summary(expressway, {"left": traj})
    assert len(rows) == len(expressway.corners)
    for row, corner in zip(rows, expressway.corners, strict=True):
        # The direction of the corner from the heading change across it (first half for an S).
        end = corner.s if corner.angle == 0 else corner.s_exit
        turn = expressway.centerline.heading(end) - expressway.centerline.heading(corner.s_entry)
        direction = np.sign(turn)
        # A left offset is the inside of a left-hander and the outside of a right-hander.
        assert row.ey_entry_m == pytest.approx(direction * offset, abs=1e-3)
        assert row.ey_exit_m == pytest.approx(direction * offset, abs=1e-3)
        assert row.ey_apex_m == pytest.approx(direction * offset, abs=1e-3)


def test_out_in_out_bump_is_read_as_entry_apex_exit(expressway):
    hairpin = next(c for c in expressway.corners if c.number == 5)
    direction = np.sign(hairpin.angle)
    s = expressway.centerline.sample(ds=3.0)
    d = (s - hairpin.s + expressway.length / 2) % expressway.length - expressway.length / 2
    inside = -3.0 + 6.0 * np.exp(-((d / 25.0) ** 2))  # outside, 3 m inside at s_c, outside
    x, y, _ = expressway.centerline.to_cartesian(s, direction * inside)
    traj = speed_profile_trajectory(expressway, (x, y), POINT_MASS)
    (row,) = corner_summary(expressway, {"bump": traj}, [hairpin])
    assert row.ey_entry_m == pytest.approx(-3.0, abs=0.01)
    assert row.ey_apex_m == pytest.approx(3.0, abs=0.05)  # nodes 3 m apart straddle the peak
    assert row.ey_exit_m == pytest.approx(-3.0, abs=0.01)
    assert abs(row.s_apex_m - hairpin.s) < 3.0


def test_bad_lines_are_refused(expressway, centerline_plan):
    with pytest.raises(PlanningError, match="at least 4"):
        line_lap_time(expressway, ([0.0, 1.0, 2.0], [0.0, 1.0, 0.0]), POINT_MASS)
    with pytest.raises(PlanningError, match="cannot read a line"):
        line_lap_time(expressway, object(), POINT_MASS)
    backwards = (centerline_plan.x[::-1], centerline_plan.y[::-1])
    with pytest.raises(PlanningError, match="against the direction"):
        time_along_centerline(expressway, SimpleNamespace(x=backwards[0], y=backwards[1]), 0.0)
