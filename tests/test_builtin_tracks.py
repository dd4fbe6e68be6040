"""Tests of the built-in tracks and of the segment builder (racing_lib.tracks).

The specs come from the track design (docs of racing_lib/tracks): lengths, widths, corner radii,
no self-intersection and walls that never overlap. The lap-time check is a rough independent
estimate, not the project's speed profile: v(s) = min(v_max, sqrt(mu g / |kappa|)) limited by
4 m/s^2 of acceleration and 9 m/s^2 of braking, a forward-backward pass.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from racing_lib.errors import TrackError
from racing_lib.geometry import Path
from racing_lib.geometry import wall_clearance as track_wall_clearance
from racing_lib.geometry.crossings import self_intersections
from racing_lib.tracks import (
    Arc,
    Straight,
    build_centerline,
    builtin_track_names,
    circle_track,
    corner_positions,
    crucial_corners,
    load_track,
    track_from_segments,
)

G = 9.81  # [m/s^2]


def rough_lap_time(track, mu=1.25, v_max=53.0, accel=4.0, brake=9.0, ds=1.0) -> float:
    """Lap time, s, of a point mass limited by friction, top speed, acceleration and braking."""
    s = track.centerline.sample(ds=ds)
    h = track.length / len(s)
    kappa = np.abs(track.centerline.curvature(s))
    v = np.minimum(v_max, np.sqrt(mu * G / np.maximum(kappa, 1e-9)))
    n = len(v)
    for _ in range(2):  # two laps of passes settle the periodic wrap
        for i in range(1, 2 * n):
            v[i % n] = min(v[i % n], math.sqrt(v[(i - 1) % n] ** 2 + 2.0 * accel * h))
        for i in range(2 * n, 0, -1):
            v[(i - 1) % n] = min(v[(i - 1) % n], math.sqrt(v[i % n] ** 2 + 2.0 * brake * h))
    return float(np.sum(h / v))


def test_names_and_loading():
    assert builtin_track_names() == ["expressway", "shortcut"]
    a = load_track("Expressway")
    assert load_track(" EXPRESSWAY ") is a  # cached: generated once per session
    assert a.name == "expressway"


@pytest.mark.parametrize("name", ["expressway", "shortcut"])
def test_geometry_is_sound(name):
    track = load_track(name)
    path = track.centerline
    # Closed, simple, and both edges simple too.
    assert not self_intersections(np.column_stack(path.position(path.knots)))
    xl, yl, xr, yr = track.edges()
    assert not self_intersections(np.column_stack([xl, yl]))
    assert not self_intersections(np.column_stack([xr, yr]))
    # The road never reaches past a centre of curvature (Frenet coordinates stay unique).
    s = path.sample(ds=0.5)
    kappa = path.curvature(s)
    inner = np.where(kappa > 0, track.width_left(s), track.width_right(s))
    assert np.max(np.abs(kappa) * inner) < 0.5
    # Non-adjacent parts of the track are farther apart than the road is wide.
    assert track_wall_clearance(track) > 5.0
    # Arc length parametrization.
    assert np.max(np.abs(path.speed(s) - 1.0)) < 1e-6
    # Heading turns by exactly one counter-clockwise lap.
    turn = path.heading(path.length - 1e-6) - path.heading(0.0)
    assert turn == pytest.approx(2.0 * math.pi, abs=1e-4)


def test_expressway_spec():
    track = load_track("expressway")
    assert 4300.0 <= track.length <= 4500.0
    assert track.boundary == "walls"
    s = track.centerline.sample(ds=1.0)
    width = track.width_left(s) + track.width_right(s)
    assert 9.99 <= width.min() and width.max() <= 12.01 and np.ptp(width) > 1.0
    z = track.elevation(s)
    assert 3.0 <= np.ptp(z) <= 12.0 and np.max(np.abs(z)) <= 6.0
    assert np.max(np.abs(track.grade(s))) < math.radians(3.0)

    corners = crucial_corners("expressway")
    assert len(corners) == 6 and corners == track.corners
    assert (
        corner_positions("expressway")
        == track.corner_positions()
        == {c.number: c.s for c in corners}
    )
    assert [c.number for c in corners] == [1, 2, 3, 4, 5, 6]
    assert np.all(np.diff([c.s for c in corners]) > 0)
    radii = np.array([c.radius for c in corners])
    assert np.sum((radii >= 15.0) & (radii <= 25.0)) >= 1  # near-hairpin
    hairpin = corners[int(np.argmin(radii))]
    assert math.degrees(abs(hairpin.angle)) >= 130.0
    assert np.sum((radii >= 150.0) & (radii <= 300.0)) >= 2  # fast sweepers
    # The S-bend: left then right, total turning ~0.
    s_bend = next(c for c in corners if c.label == "S-bend")
    ks = track.centerline.curvature(np.linspace(s_bend.s_entry, s_bend.s_exit, 200))
    assert ks[:60].max() > 0.01 and ks[-60:].min() < -0.01 and abs(s_bend.angle) < 1e-9
    # Each corner's apex has the design curvature, checked on the generated centerline (short
    # arcs are all clothoid, so the peak is a kink that the C2 spline rounds off a little).
    for c in corners:
        if c.label != "S-bend":
            kappa = track.centerline.curvature(c.s)
            assert abs(kappa) == pytest.approx(1.0 / c.radius, rel=0.03), c.label
            assert np.sign(kappa) == np.sign(c.angle)
    # Long straights: at least two stretches of 500 m with |kappa| < 1e-4.
    straight = np.abs(track.centerline.curvature(s)) < 1e-4
    runs, run = [], 0
    for flag in np.concatenate([straight, straight]):
        run = run + 1 if flag else 0
        runs.append(run)
    assert np.sum(np.diff(np.array(runs) >= 500).astype(int) == 1) >= 2


def test_expressway_lap_time_estimate():
    # The paper's car did 99.5 s on the Tokyo Expressway; our layout is tuned to be comparable.
    t = rough_lap_time(load_track("expressway"))
    assert 95.0 <= t <= 115.0


def test_shortcut_spec():
    track = load_track("shortcut")
    assert 3000.0 <= track.length <= 4000.0
    assert track.boundary == "open"
    s = track.centerline.sample(ds=1.0)
    np.testing.assert_allclose(track.width_left(s) + track.width_right(s), 12.0, atol=1e-9)
    corners = track.corners
    assert len(corners) == 6
    u_turns, sharp = corners[:2], corners[2:]
    for c in u_turns:
        assert math.degrees(abs(c.angle)) == pytest.approx(180.0, abs=1.0)
        assert 30.0 <= c.radius <= 50.0
    assert all(20.0 <= c.radius <= 40.0 for c in sharp)
    assert max(c.s for c in u_turns) < min(c.s for c in sharp)  # U corners come first
    assert 60.0 <= rough_lap_time(track) <= 120.0


def test_circle_track():
    track = circle_track(25.0, 6.0)
    s = track.centerline.sample(ds=1.0)
    np.testing.assert_allclose(track.curvature(s), 1.0 / 25.0, rtol=1e-4)
    assert track.width_left(0.0) == pytest.approx(3.0)
    with pytest.raises(TrackError, match="width"):
        circle_track(5.0, 12.0)


# ------------------------------------------------------------------ the segment builder


def test_oval_length_and_closure():
    radius, straight = 50.0, 200.0
    oval = [Straight(straight), Arc(radius, math.pi), Straight(straight), Arc(radius, math.pi)]
    cl = build_centerline(oval, transition=20.0)
    # Clothoids centred on the junctions keep the total length and turning.
    assert cl.length == pytest.approx(2 * straight + 2 * math.pi * radius, abs=1e-6)
    assert max(abs(d) for d in cl.closure["straight_changes"]) < 1e-3
    track = track_from_segments(oval, width=12.0, transition=20.0, name="oval")
    assert track.length == pytest.approx(cl.length, abs=1e-3)
    # Curvature: 1/R in the middle of the arcs, 0 mid-straight, linear ramp in the clothoid.
    kappa = track.centerline.curvature
    assert kappa(straight + 0.5 * math.pi * radius) == pytest.approx(1.0 / radius, rel=1e-3)
    assert abs(kappa(0.5 * straight)) < 1e-5
    assert kappa(straight) == pytest.approx(0.5 / radius, rel=1e-2)  # middle of the clothoid
    assert track.centerline.curvature_derivative(straight) == pytest.approx(
        1.0 / (radius * 20.0), rel=1e-2
    )


def test_builder_closes_a_loop_that_does_not_close():
    # A square with unequal sides and 89 + 91 + 90 + 90 degrees: the straights must change.
    layout = [
        Straight(300.0),
        Arc.degrees(30.0, 89.0),
        Straight(200.0),
        Arc.degrees(30.0, 91.0),
        Straight(320.0),
        Arc.degrees(30.0, 90.0),
        Straight(210.0),
        Arc.degrees(30.0, 90.0),
    ]
    cl = build_centerline(layout, transition=15.0)
    assert math.hypot(cl.x[0] - cl.x[-1], cl.y[0] - cl.y[-1]) < 1.5  # consecutive points
    changes = np.array(cl.closure["straight_changes"])
    assert 1.0 < np.max(np.abs(changes)) < 40.0
    path = Path(cl.x, cl.y)  # closes smoothly: heading continuous across s = 0
    turn = path.heading(path.length - 1e-6) - path.heading(0.0)
    assert turn == pytest.approx(2.0 * math.pi, abs=1e-3)
    # s = 0 is the middle of the clothoid from the last arc into the first straight.
    kappa = path.curvature(np.array([path.length - 0.5, 0.0, 0.5, 150.0]))
    np.testing.assert_allclose(
        kappa[:3], [0.5 / 30 + 0.5 / 450, 0.5 / 30, 0.5 / 30 - 0.5 / 450], rtol=0.02
    )
    assert abs(kappa[3]) < 1e-4


def test_builder_scales_small_angle_error_and_refuses_large():
    near = [Straight(300.0), Arc.degrees(50.0, 178.0), Straight(300.0), Arc.degrees(50.0, 178.0)]
    cl = build_centerline(near)
    assert cl.closure["angle_scale"] == pytest.approx(360.0 / 356.0)
    far = [Straight(300.0), Arc.degrees(50.0, 150.0), Straight(300.0), Arc.degrees(50.0, 150.0)]
    with pytest.raises(TrackError, match="300.00 degrees"):
        build_centerline(far)
    with pytest.raises(TrackError, match="radius must be > 0"):
        build_centerline([Straight(10.0), Arc(-5.0, 1.0)])
    with pytest.raises(TrackError, match="Straight"):
        build_centerline([Straight(10.0), "arc"])  # type: ignore[list-item]
