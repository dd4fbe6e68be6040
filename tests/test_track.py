"""Tests of racing_lib.geometry: arc length, curvature, Frenet frame, tracker, CSV and validation.

Independent truths: a circle's curvature is 1/R and its length 2 pi R; Frenet -> Cartesian ->
Frenet is the identity inside the track; an arc-length parametrization has |dr/ds| = 1.
"""

from __future__ import annotations

import copy
import math
import os
from pathlib import Path as FsPath

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from racing_lib.errors import TrackError
from racing_lib.geometry import (
    FrenetTracker,
    Path,
    Track,
)
from racing_lib.tracks import circle_track, load_track

SHARED_TRACKS = FsPath(__file__).resolve().parents[2] / "shared" / "tracks"
REAL_CSV = SHARED_TRACKS / "Spielberg.csv"

HEADER = "# x_m,y_m,w_tr_right_m,w_tr_left_m"


def wrap_s(ds: np.ndarray | float, length: float) -> np.ndarray:
    """Difference of arc lengths modulo the lap, in [-L/2, L/2)."""
    return (np.asarray(ds) + 0.5 * length) % length - 0.5 * length


def write_csv(path: FsPath, rows, header: str = HEADER) -> FsPath:
    lines = [header] + [",".join(str(v) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def ellipse_rows(n: int = 120, a: float = 300.0, b: float = 150.0, w: float = 5.0) -> list:
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return [[a * math.cos(u), b * math.sin(u), w, w] for u in t]


@pytest.fixture(scope="module")
def csv_track(tmp_path_factory) -> Track:
    """A real circuit from ../shared/tracks if present, else an ellipse written to a temp CSV."""
    if REAL_CSV.exists():
        return Track.from_csv(REAL_CSV)
    path = write_csv(tmp_path_factory.mktemp("csv") / "ellipse.csv", ellipse_rows())
    return Track.from_csv(path)


# ------------------------------------------------------------------ geometry of a circle


@pytest.mark.parametrize("radius", [15.0, 50.0, 300.0])
def test_circle_curvature_length_heading(radius):
    track = circle_track(radius, width=8.0)
    path = track.centerline
    s = np.linspace(0.0, path.length, 2001)
    assert path.length == pytest.approx(2.0 * math.pi * radius, rel=1e-6)
    np.testing.assert_allclose(path.curvature(s), 1.0 / radius, rtol=1e-4)
    # dkappa/ds of a cubic spline is piecewise linear: small on the scale 1/R^2, not zero.
    np.testing.assert_allclose(path.curvature_derivative(s), 0.0, atol=0.05 / radius**2)
    # Counter-clockwise from (R, 0): heading = pi/2 + s/R (continuous over the lap).
    np.testing.assert_allclose(path.heading(s[:-1]), 0.5 * math.pi + s[:-1] / radius, atol=1e-6)
    x, y = path.position(s)
    np.testing.assert_allclose(np.hypot(x, y), radius, rtol=1e-7)


def test_arc_length_parametrization(csv_track):
    for track in (circle_track(40.0), load_track("expressway"), csv_track):
        path = track.centerline
        s = np.linspace(0.0, path.length, 50_001)
        assert np.max(np.abs(path.speed(s) - 1.0)) < 1e-5, track.name
        # The chord between close samples equals their arc-length difference.
        x, y = path.position(s)
        chord = np.hypot(np.diff(x), np.diff(y))
        np.testing.assert_allclose(chord, np.diff(s), rtol=1e-5)


def test_scalar_in_float_out():
    path = circle_track(30.0).centerline
    x, y = path.position(1.0)
    assert isinstance(x, float) and isinstance(y, float)
    s, e_y, e_psi = path.to_frenet(31.0, 0.0)
    assert isinstance(s, float) and isinstance(e_y, float)
    assert math.isnan(e_psi)
    assert isinstance(path.curvature(3.0), float)
    xc, yc, psi = path.to_cartesian(0.0, -1.0, 0.1)
    assert (xc, yc) == pytest.approx((31.0, 0.0))
    assert psi == pytest.approx(0.5 * math.pi + 0.1)


def test_e_y_positive_left():
    # Counter-clockwise circle: left is towards the centre.
    path = circle_track(50.0).centerline
    _, e_y, _ = path.to_frenet(45.0, 0.0)
    assert e_y == pytest.approx(5.0, abs=1e-9)
    _, e_y, _ = path.to_frenet(56.0, 0.0)
    assert e_y == pytest.approx(-6.0, abs=1e-9)


def test_curvature_derivative_on_clothoid():
    # Expressway: the clothoid into the R 20 m hairpin (30 m long) from a straight has
    # dkappa/ds = (1/20) / 30 = 1/600 1/m^2 at its middle.
    track = load_track("expressway")
    hairpin = next(c for c in track.corners if c.label == "hairpin")
    s_mid = hairpin.s_entry + 15.0
    assert track.centerline.curvature_derivative(s_mid) == pytest.approx(1.0 / 600.0, rel=0.02)
    assert track.centerline.curvature(s_mid) == pytest.approx(0.5 / 20.0, rel=0.02)
    # And it is the derivative of the curvature (central difference).
    h = 1e-3
    fd = (track.centerline.curvature(s_mid + h) - track.centerline.curvature(s_mid - h)) / (2 * h)
    assert track.centerline.curvature_derivative(s_mid) == pytest.approx(fd, rel=1e-4)


# ------------------------------------------------------------------ Frenet round trips


def _round_trip(track: Track, s: float, frac: float, e_psi: float) -> None:
    path = track.centerline
    half = track.width_left(s) if frac >= 0 else track.width_right(s)
    e_y = frac * half
    # Beyond the centre of curvature the closest point is elsewhere; real tracks never go there.
    assume(abs(e_y * path.curvature(s)) < 0.9)
    x, y, psi = path.to_cartesian(s, e_y, e_psi)
    s2, e_y2, e_psi2 = path.to_frenet(x, y, psi)
    assert abs(wrap_s(s2 - s, path.length)) < 1e-6
    assert abs(e_y2 - e_y) < 1e-6
    assert abs(wrap_s(e_psi2 - e_psi, 2 * math.pi)) < 1e-9
    x3, y3, _ = path.to_cartesian(s2, e_y2)
    assert math.hypot(x3 - x, y3 - y) < 1e-6


round_trip_args = dict(
    u=st.floats(0.0, 1.0, exclude_max=True),
    frac=st.floats(-1.0, 1.0),
    e_psi=st.floats(-3.0, 3.0),
)


@pytest.mark.parametrize("name", ["expressway", "shortcut"])
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(**round_trip_args)
def test_frenet_round_trip_builtin(name, u, frac, e_psi):
    track = load_track(name)
    _round_trip(track, u * track.length, frac, e_psi)


@settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.function_scoped_fixture],
)
@given(**round_trip_args)
def test_frenet_round_trip_csv(csv_track, u, frac, e_psi):
    _round_trip(csv_track, u * csv_track.length, frac, e_psi)


def test_frenet_vectorized_matches_scalar(csv_track):
    path = csv_track.centerline
    rng = np.random.default_rng(3)
    s = rng.uniform(0.0, path.length, 500)
    e_y = rng.uniform(-3.0, 3.0, 500)
    x, y, _ = path.to_cartesian(s, e_y)
    s2, e_y2, _ = path.to_frenet(x, y)
    assert np.max(np.abs(wrap_s(s2 - s, path.length))) < 1e-6
    assert np.max(np.abs(e_y2 - e_y)) < 1e-6
    for i in range(0, 500, 100):
        si, ei, _ = path.to_frenet(float(x[i]), float(y[i]))
        assert si == pytest.approx(s2[i], abs=1e-9) and ei == pytest.approx(e_y2[i], abs=1e-9)


@pytest.mark.parametrize("name", ["expressway", "shortcut", "circle"])
def test_wrap_around_start_finish(name):
    track = circle_track(60.0) if name == "circle" else load_track(name)
    path = track.centerline
    length = path.length
    for s in (0.0, 1e-12, 1e-7, 0.3, length - 0.3, length - 1e-7, length, length + 2.0, -2.0):
        for e_y in (-3.0, 0.0, 2.5):
            x, y, _ = path.to_cartesian(s, e_y)
            s2, e_y2, _ = path.to_frenet(x, y)
            assert 0.0 <= s2 < length
            assert abs(wrap_s(s2 - s, length)) < 1e-6
            assert e_y2 == pytest.approx(e_y, abs=1e-6)
            # Local search from the other side of the line converges too.
            s3, e_y3, _ = path.to_frenet(x, y, s_hint=(s + 4.0) % length)
            assert abs(wrap_s(s3 - s, length)) < 1e-6
    # Position is periodic.
    np.testing.assert_allclose(path.position(length + 5.0), path.position(5.0), atol=1e-9)


def test_hairpin_robustness():
    track = load_track("expressway")
    path = track.centerline
    hairpin = next(c for c in track.corners if c.label == "hairpin")
    assert hairpin.radius <= 25.0
    s = np.linspace(hairpin.s_entry - 20.0, hairpin.s_exit + 20.0, 301)
    for frac in np.linspace(-1.0, 1.0, 9):
        e_y = frac * np.where(frac >= 0, track.width_left(s), track.width_right(s))
        x, y, _ = path.to_cartesian(s, e_y)
        s2, e_y2, _ = path.to_frenet(x, y)
        assert np.max(np.abs(wrap_s(s2 - s, path.length))) < 1e-6
        assert np.max(np.abs(e_y2 - e_y)) < 1e-6
        # Starting the local search 15 m off (half the hairpin) still lands on the right point.
        s3, _, _ = path.to_frenet(x, y, s_hint=s + 15.0)
        assert np.max(np.abs(wrap_s(s3 - s, path.length))) < 1e-6


# ------------------------------------------------------------------ tracker


@pytest.mark.parametrize("name", ["expressway", "shortcut"])
def test_tracker_continuity_over_laps(name):
    track = load_track(name)
    path = track.centerline
    s = np.arange(0.0, 2.0 * path.length, 1.5)  # 1.5 m steps: 54 m/s at 36 sub-steps per 1 s
    w = np.minimum(track.width_left(s), track.width_right(s))
    e_y = 0.8 * w * np.sin(s / 37.0)
    x, y, _ = path.to_cartesian(s, e_y)
    tracker = FrenetTracker(path)
    out = np.array([tracker.project(xi, yi) for xi, yi in zip(x.tolist(), y.tolist(), strict=True)])
    ds = wrap_s(np.diff(out[:, 0]), path.length)
    assert np.all(ds > 0.0)  # s increases monotonically (modulo the lap)
    assert np.max(np.abs(wrap_s(out[:, 0] - s, path.length))) < 1e-6
    assert np.max(np.abs(out[:, 1] - e_y)) < 1e-6


def test_tracker_heading_is_the_paths_at_the_projection():
    from racing_lib.geometry.spline import wrap_angle

    path = load_track("shortcut").centerline
    tracker = FrenetTracker(path)
    # Local steps, a jump the global search resolves, and a fresh start after a reset.
    for s_true in [*np.arange(10.0, 400.0, 7.0), 1800.0, 1803.0]:
        x, y, _ = path.to_cartesian(s_true, 1.5)
        s, _ = tracker.project(x, y)
        expected = wrap_angle(float(path.heading(s)))
        assert -np.pi <= tracker.heading < np.pi
        assert abs(wrap_angle(tracker.heading - expected)) < 1e-9
    tracker.reset()
    x, y, _ = path.to_cartesian(50.0, 0.0)
    s, _ = tracker.project(x, y)
    assert abs(wrap_angle(tracker.heading - float(path.heading(s)))) < 1e-9


def test_two_trackers_on_one_path_get_what_each_would_get_alone():
    # The path remembers its last projection (a lap projects each position twice onto the plan's
    # line); a tracker sharing the path must see exactly what it sees on a path of its own, and
    # a different start point must not be answered from the memory.
    shared = load_track("shortcut").centerline
    own = copy.deepcopy(shared)  # the same line, with a memory of its own
    own._last_projection = (None, ())
    assert own is not shared
    s = np.arange(0.0, 600.0, 2.5)
    x, y, _ = shared.to_cartesian(s, 1.2 * np.sin(s / 23.0))
    a, b, alone = FrenetTracker(shared), FrenetTracker(shared), FrenetTracker(own)
    lagging = FrenetTracker(shared)  # every second point only: it starts two points back
    for k, (xi, yi) in enumerate(zip(x.tolist(), y.tolist(), strict=True)):
        want = alone.project(xi, yi)
        assert a.project(xi, yi) == want
        assert b.project(xi, yi) == want  # answered from the memory
        if k % 2 == 0:
            assert lagging.project(xi, yi) == pytest.approx(want, abs=1e-9)
    x5, y5 = float(x[5]), float(y[5])
    assert shared._newton_scalar(x5, y5, 7.0) == own._newton_scalar_from(x5, y5, 7.0)
    shared._newton_scalar(x5, y5, 9.0)
    assert shared._last_projection[0] == (x5, y5, 9.0)  # computed afresh, not answered


def test_tracker_reset_and_jump():
    track = load_track("shortcut")
    path = track.centerline
    tracker = FrenetTracker(path)
    x, y, _ = path.to_cartesian(100.0, 1.0)
    assert tracker.project(x, y) == pytest.approx((100.0, 1.0), abs=1e-6)
    # A jump to the other side of the track: local search gives up, global search decides.
    x, y, _ = path.to_cartesian(1800.0, -2.0)
    assert tracker.project(x, y) == pytest.approx((1800.0, -2.0), abs=1e-6)
    tracker.reset()
    assert tracker.s is None
    x, y, _ = path.to_cartesian(5.0, 0.5)
    assert tracker.project(x, y) == pytest.approx((5.0, 0.5), abs=1e-6)
    with pytest.raises(TrackError, match="NaN"):
        tracker.project(float("nan"), 0.0)


# ------------------------------------------------------------------ Track profiles


def test_grade_is_slope_of_elevation():
    track = load_track("expressway")
    s = np.linspace(0.0, track.length, 400, endpoint=False)
    h = 1e-3
    slope = (track.elevation(s + h) - track.elevation(s - h)) / (2 * h)
    np.testing.assert_allclose(track.grade(s), np.arctan(slope), atol=1e-7)
    assert isinstance(track.width_left(3.0), float)


def test_checksum_stable_and_sensitive():
    track = load_track("shortcut")
    a = track.checksum()
    rebuilt = Track(
        track.centerline, 6.0, 6.0, track.elevation(track.centerline.knots), name="other"
    )
    assert rebuilt.checksum() == a  # same geometry, other name
    wider = Track(track.centerline, 6.1, 6.0, track.elevation(track.centerline.knots))
    assert wider.checksum() != a
    assert len(a) == 16 and int(a, 16) >= 0


# ------------------------------------------------------------------ CSV


def test_csv_round_trip(tmp_path):
    track = load_track("expressway")
    out = tmp_path / "expressway.csv"
    track.to_csv(out, spacing=2.0)
    assert out.read_text().splitlines()[0] == HEADER + ",z_m"
    assert [p.name for p in tmp_path.iterdir()] == ["expressway.csv"]  # no temp file left
    back = Track.from_csv(out, boundary="walls")
    assert back.name == "expressway" and back.boundary == "walls"
    assert back.length == pytest.approx(track.length, abs=0.01)
    s = np.linspace(0.0, track.length, 3000, endpoint=False)
    x0, y0 = track.centerline.position(s)
    x1, y1 = back.centerline.position(s)
    assert np.max(np.hypot(x1 - x0, y1 - y0)) < 0.02
    np.testing.assert_allclose(back.width_left(s), track.width_left(s), atol=1e-3)
    np.testing.assert_allclose(back.width_right(s), track.width_right(s), atol=1e-3)
    np.testing.assert_allclose(back.elevation(s), track.elevation(s), atol=1e-3)


def test_csv_flat_track_has_no_z_column(tmp_path):
    out = tmp_path / "circle.csv"
    circle_track(80.0, 9.0).to_csv(out)
    assert out.read_text().splitlines()[0] == HEADER
    back = load_track(str(out))
    assert back.length == pytest.approx(2 * math.pi * 80.0, rel=1e-5)
    assert back.width_left(1.0) == pytest.approx(4.5)


def test_csv_overwrite_is_atomic(tmp_path, monkeypatch):
    out = tmp_path / "t.csv"
    out.write_text("old contents\n")

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        circle_track(50.0).to_csv(out)
    assert out.read_text() == "old contents\n"
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]


@pytest.mark.skipif(not SHARED_TRACKS.exists(), reason="../shared/tracks not present")
@pytest.mark.parametrize("name", ["BrandsHatch", "Norisring", "Oschersleben", "Spielberg"])
def test_real_circuits_load(name):
    track = load_track(str(SHARED_TRACKS / f"{name}.csv"))
    expected = {"BrandsHatch": 3.9e3, "Norisring": 2.3e3, "Oschersleben": 3.7e3, "Spielberg": 4.3e3}
    assert track.length == pytest.approx(expected[name], rel=0.03)
    # The spline passes through the file's points.
    data = np.loadtxt(SHARED_TRACKS / f"{name}.csv", delimiter=",", comments="#")
    s, e_y, _ = track.centerline.to_frenet(data[:, 0], data[:, 1])
    assert np.max(np.abs(e_y)) < 1e-6
    np.testing.assert_allclose(track.width_right(s), data[:, 2], atol=1e-6)


# ------------------------------------------------------------------ bad input


def test_last_row_repeating_first_is_accepted(tmp_path):
    rows = ellipse_rows()
    a = Track.from_csv(write_csv(tmp_path / "a.csv", rows))
    b = Track.from_csv(write_csv(tmp_path / "b.csv", rows + [rows[0]]))
    assert b.length == pytest.approx(a.length, abs=1e-9)


def test_missing_file():
    with pytest.raises(TrackError, match="does not exist"):
        Track.from_csv("/no/such/track.csv")
    with pytest.raises(TrackError, match="does not exist"):
        load_track("no_such_track.csv")


def test_unreadable_file(tmp_path):
    path = tmp_path / "binary.csv"
    path.write_bytes(b"\xff\xfe\x00garbage\x81")
    with pytest.raises(TrackError, match="cannot be read"):
        Track.from_csv(path)


@pytest.mark.parametrize(
    "header",
    ["# x_m,y_m,w_tr_left_m", "# x,y,wr,wl", "# x_m,y_m,w_tr_left_m,w_tr_right_m"],
)
def test_wrong_columns(tmp_path, header):
    path = write_csv(tmp_path / "cols.csv", ellipse_rows(), header=header)
    with pytest.raises(TrackError, match="wrong columns") as err:
        Track.from_csv(path)
    assert "cols.csv" in str(err.value) and "x_m,y_m,w_tr_right_m,w_tr_left_m" in str(err.value)


def test_row_with_wrong_count_or_text(tmp_path):
    rows = ellipse_rows()
    rows[5] = rows[5][:3]
    with pytest.raises(TrackError, match="line 7: 3 values, expected 4"):
        Track.from_csv(write_csv(tmp_path / "short.csv", rows))
    rows = ellipse_rows()
    rows[2][1] = "abc"
    with pytest.raises(TrackError, match="line 4.*not numeric"):
        Track.from_csv(write_csv(tmp_path / "text.csv", rows))


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_nan_and_inf(tmp_path, bad):
    rows = ellipse_rows()
    rows[10][0] = bad
    with pytest.raises(TrackError, match="line 12: NaN or infinite"):
        Track.from_csv(write_csv(tmp_path / "nan.csv", rows))


def test_too_few_points(tmp_path):
    rows = [[0, 0, 5, 5], [100, 0, 5, 5], [0, 100, 5, 5]]
    with pytest.raises(TrackError, match="3 centerline point.*at least 4"):
        Track.from_csv(write_csv(tmp_path / "few.csv", rows))
    with pytest.raises(TrackError, match="at least 4"):
        Path([0, 1, 0], [0, 0, 1])


@pytest.mark.parametrize("col,side", [(2, "right"), (3, "left")])
@pytest.mark.parametrize("value", [0.0, -1.5])
def test_non_positive_width(tmp_path, col, side, value):
    rows = ellipse_rows()
    rows[20][col] = value
    with pytest.raises(TrackError, match=f"line 22: {side} width.*not positive"):
        Track.from_csv(write_csv(tmp_path / "w.csv", rows))


def test_duplicate_consecutive_point(tmp_path):
    rows = ellipse_rows()
    rows.insert(31, list(rows[30]))
    with pytest.raises(TrackError, match="lines 32 and 33: duplicate consecutive point"):
        Track.from_csv(write_csv(tmp_path / "dup.csv", rows))


def test_coincident_points(tmp_path):
    # A loop that passes through the same point twice (touching itself).
    t = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False)
    x, y = 200.0 * np.sin(t), 100.0 * np.sin(t) * np.cos(t)  # figure eight through (0, 0) twice
    rows = [[a, b, 4.0, 4.0] for a, b in zip(x, y, strict=True)]
    with pytest.raises(TrackError, match="same point.*twice"):
        Track.from_csv(write_csv(tmp_path / "touch.csv", rows))


def test_a_figure_eight_with_a_bridge_loads(tmp_path):
    # A lemniscate: the two stretches through the origin are half a lap apart and cross at 53
    # degrees, a bridge as on a real figure-eight circuit.
    t = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False) + 0.01
    x, y = 200.0 * np.sin(t), 100.0 * np.sin(t) * np.cos(t)
    rows = [[a, b, 4.0, 4.0] for a, b in zip(x, y, strict=True)]
    track = Track.from_csv(write_csv(tmp_path / "eight.csv", rows))
    (crossing,) = track.centerline.crossings
    assert crossing.angle_deg == pytest.approx(53.13, abs=0.5)
    gap = crossing.s_b - crossing.s_a
    assert gap == pytest.approx(0.5 * track.length, rel=0.02)
    assert len(Path(x, y).crossings) == 1


def test_a_crossing_that_is_no_bridge_is_refused(tmp_path):
    # Two rows swapped: the line folds back over itself between neighbouring rows.
    rows = ellipse_rows()
    rows[30], rows[31] = rows[31], rows[30]
    with pytest.raises(TrackError, match="crosses itself between lines") as err:
        Track.from_csv(write_csv(tmp_path / "swapped.csv", rows))
    assert "swapped.csv" in str(err.value) and "bridges" in str(err.value)
    xy = np.array(rows)[:, :2]
    with pytest.raises(TrackError, match="crosses itself"):
        Path(xy[:, 0], xy[:, 1])
    # Far apart along the lap but grazing (6 degrees): a misplaced stretch, not a bridge.
    t = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False) + 0.01
    x, y = 200.0 * np.sin(t), 10.0 * np.sin(t) * np.cos(t)
    rows = [[a, b, 2.0, 2.0] for a, b in zip(x, y, strict=True)]
    with pytest.raises(TrackError, match="crosses itself.* at 6 degrees"):
        Track.from_csv(write_csv(tmp_path / "grazing.csv", rows))


def test_the_tracker_stays_on_its_branch_through_a_crossing():
    from racing_lib.tracks import figure_eight_track

    track = figure_eight_track()
    path = track.centerline
    (crossing,) = path.crossings
    # A car driving along the second stretch through the crossing, 2 m left of the line: the
    # nearest branch flips at the crossing, the tracker's answer must not.
    s_true = crossing.s_b + np.linspace(-30.0, 30.0, 121)
    x, y = path.position(s_true)
    nx, ny = -np.sin(path.heading(s_true)), np.cos(path.heading(s_true))
    s, e_y = path.to_frenet_along(x + 2.0 * nx, y + 2.0 * ny)
    np.testing.assert_allclose(s, s_true, atol=1e-6)
    np.testing.assert_allclose(e_y, 2.0, atol=1e-6)
    # The nearest-point projection does jump to the other branch there.
    s_global, _, _ = path.to_frenet(x + 2.0 * nx, y + 2.0 * ny)
    assert np.max(np.abs(s_global - s_true)) > 100.0


def test_open_centerline(tmp_path):
    rows = ellipse_rows()[:-20]  # the last sixth of the ellipse is missing
    with pytest.raises(TrackError, match="centerline is open.*must be closed") as err:
        Track.from_csv(write_csv(tmp_path / "open.csv", rows))
    assert "line 101" in str(err.value)


def test_unknown_track_name():
    with pytest.raises(TrackError) as err:
        load_track("monza")
    msg = str(err.value)
    assert "'monza'" in msg and "expressway" in msg and "shortcut" in msg and "CSV" in msg


def test_track_rejects_bad_arguments():
    path = circle_track(50.0).centerline
    with pytest.raises(TrackError, match="boundary"):
        Track(path, 5.0, 5.0, boundary="fence")  # type: ignore[arg-type]
    with pytest.raises(TrackError, match="right width is not positive"):
        Track(path, 5.0, 0.0)
    with pytest.raises(TrackError, match="NaN"):
        path.to_frenet(np.nan, 1.0)


# --------------------------------------------------------------------------------------------------
# Geometry a file can state but a car cannot drive


def test_an_inner_width_past_the_turn_centre_is_clipped_with_a_warning_that_says_where():
    from racing_lib.geometry.checks import (
        INNER_WIDTH_SHARE,
        TrackGeometryWarning,
    )

    # A circle of radius 3 m driven anticlockwise: the left side is the inside.
    t = np.linspace(0.0, 2.0 * np.pi, 40, endpoint=False)
    line = Path(3.0 * np.cos(t), 3.0 * np.sin(t))
    with pytest.warns(TrackGeometryWarning, match=r"left \(inner\) width .* radius 2\.99 m"):
        track = Track(line, 5.0, 5.0, name="hairpin")
    s = line.sample(n=50)
    # Nowhere does the inner edge reach the centre any more; the outer width is untouched.
    assert np.max(track.width_left(s)) <= INNER_WIDTH_SHARE * 3.0 + 0.01
    np.testing.assert_allclose(track.width_right(s), 5.0)


def test_overlapping_stretches_of_road_are_refused():
    # An oval pinched in its middle: the long sides run 7 m apart with 4 m of road each side.
    t = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    x = 200.0 * np.cos(t)
    y = np.sin(t) * (40.0 - 36.5 * np.exp(-((x / 50.0) ** 2)))
    with pytest.raises(TrackError, match=r"overlaps the road near s = .* by 0\.9\d m"):
        Track(Path(x, y), 4.0, 4.0, name="pinched")
    Track(Path(x, y), 3.0, 3.0, name="pinched")  # 1 m apart: fine


def test_a_bridge_is_not_an_overlap():
    from racing_lib.tracks import figure_eight_track

    track = figure_eight_track()
    assert track.centerline.crossings  # it does cross, on a bridge


def test_a_byte_order_mark_is_accepted(tmp_path):
    plain = write_csv(tmp_path / "plain.csv", ellipse_rows())
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    assert Track.from_csv(bom).checksum() == Track.from_csv(plain).checksum()


def test_very_dense_points_are_thinned_with_a_warning(tmp_path):
    from racing_lib.geometry.checks import TrackGeometryWarning

    # A circle of radius 80 m every 0.1 m, its coordinates rounded to 6 decimals as in the
    # racetrack-database files.
    radius = 80.0
    n = int(2 * np.pi * radius / 0.1)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    x, y = np.round(radius * np.cos(t), 6), np.round(radius * np.sin(t), 6)
    rows = [(a, b, 5.0, 5.0) for a, b in zip(x, y, strict=True)]
    path = write_csv(tmp_path / "dense.csv", rows)
    with pytest.warns(TrackGeometryWarning, match=r"0\.10 m apart .* Every 10th row"):
        track = Track.from_csv(path)
    s = track.centerline.sample(ds=1.0)

    def noise(line: Path) -> float:
        return float(np.max(np.abs(line.curvature(s) * radius - 1.0)))

    assert noise(Path(x, y)) > 0.01  # every point kept: over 1 % curvature noise
    assert noise(track.centerline) < 0.001  # thinned: under 0.1 %
