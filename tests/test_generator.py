"""The circuit generator: closed, valid, varied circuits, the same for the same seed."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from racing_lib.errors import TrackError
from racing_lib.face.cli import main
from racing_lib.geometry import Track
from racing_lib.tracks import CircuitSpec, generate

SEEDS = range(40)


def _profile(track: Track, n: int = 6000) -> dict[str, np.ndarray]:
    s = np.linspace(0.0, track.length, n, endpoint=False)
    return {
        "radius": 1.0 / np.maximum(np.abs(track.curvature(s)), 1e-9),
        "width": track.width_left(s) + track.width_right(s),
        "grade": np.abs(track.grade(s)),
    }


@pytest.fixture(scope="module")
def circuits() -> list[Track]:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no geometry warning either: the widths fit every corner
        return [generate(seed) for seed in SEEDS]


def test_every_circuit_is_within_the_spec(circuits):
    spec = CircuitSpec()
    for track in circuits:
        p = _profile(track)
        assert spec.length[0] <= track.length <= spec.length[1]
        assert p["radius"].min() >= 0.97 * spec.min_radius, track.name
        assert spec.width[0] - 1e-6 <= p["width"].min() <= p["width"].max() <= spec.width[1] + 1e-6
        assert not track.centerline.crossings  # closed and never crossing itself
        assert np.ptp(track.elevation(np.linspace(0, track.length, 100))) == 0.0


def test_circuits_have_the_variety_of_real_ones(circuits):
    lengths = np.array([t.length for t in circuits])
    tightest = np.array([_profile(t)["radius"].min() for t in circuits])
    # Every circuit has several corners, and the set spans short and long laps, hairpins and
    # fast circuits, both directions of travel.
    assert min(len(t.corners) for t in circuits) >= 3
    assert lengths.min() < 3000 and lengths.max() > 6000
    assert np.sum(tightest < 20.0) >= 8 and tightest.max() > 1.5 * tightest.min()
    sweeps = [any(c.radius > 100.0 and abs(c.angle) > 0.6 for c in t.corners) for t in circuits]
    assert np.mean(sweeps) > 0.5
    # Straights of a few hundred metres on every circuit.
    assert min(_longest_straight(t) for t in circuits) > 200.0


def _longest_straight(track: Track) -> float:
    """Length of the longest stretch with a radius above 2 km, m."""
    s = np.arange(0.0, track.length, 1.0)
    straight = np.abs(track.curvature(s)) < 1.0 / 2000.0
    best = run = 0
    for flat in np.concatenate([straight, straight]):  # twice round: a straight over the line
        run = run + 1 if flat else 0
        best = max(best, run)
    return float(min(best, len(s)))


def test_both_directions_and_s_bends(circuits):
    turning = [sum(c.angle for c in t.corners) for t in circuits]
    assert any(a > 0 for a in turning) and any(a < 0 for a in turning)
    # Corners turning both ways within one circuit (S-bends, chicanes) in most circuits.
    both = [any(c.angle > 0 for c in t.corners) and any(c.angle < 0 for c in t.corners)
            for t in circuits]  # fmt: skip
    assert np.mean(both) > 0.5


def test_the_same_seed_gives_the_same_circuit(tmp_path):
    a, b = generate(11), generate(11)
    a.to_csv(tmp_path / "a.csv")
    b.to_csv(tmp_path / "b.csv")
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    assert generate(12).length != a.length


def test_a_written_circuit_passes_the_track_checks_when_read(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for seed in (0, 3, 8):
            track = generate(seed, CircuitSpec(grade=True))
            track.to_csv(tmp_path / "c.csv")
            back = Track.from_csv(tmp_path / "c.csv")
            assert back.length == pytest.approx(track.length, rel=2e-3)
            assert _profile(back)["radius"].min() >= 0.95 * CircuitSpec().min_radius


def test_grade_stays_below_its_limit():
    spec = CircuitSpec(grade=True, max_grade=0.05)
    for seed in range(10):
        track = generate(seed, spec)
        p = _profile(track)
        assert 0.01 < p["grade"].max() <= 0.05
        assert np.ptp(track.elevation(np.linspace(0, track.length, 500))) > 1.0


def test_other_ranges_are_honoured():
    spec = CircuitSpec(length=(1500.0, 1600.0), width=(6.0, 7.0), min_radius=10.0)
    for seed in range(5):
        track = generate(seed, spec)
        p = _profile(track)
        assert 1500.0 <= track.length <= 1600.0
        assert p["width"].max() <= 7.0 + 1e-6 and p["radius"].min() >= 9.7


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        (CircuitSpec(length=(100.0, 200.0)), "length range"),
        (CircuitSpec(length=(5000.0, 3000.0)), "min <= max"),
        (CircuitSpec(width=(0.0, 10.0)), "width range"),
        (CircuitSpec(width=(8.0, 40.0)), "half the widest road"),
        (CircuitSpec(length=(1000.0, 1200.0), min_radius=100.0), "lengthen the lap"),
        (CircuitSpec(min_radius=float("nan")), "radius"),
        (CircuitSpec(grade=True, max_grade=0.5), "max_grade"),
        (CircuitSpec(boundary="cliff"), "boundary"),
    ],
)
def test_impossible_sizes_are_refused_before_drawing(spec, words):
    with pytest.raises(TrackError, match=words):
        generate(0, spec)


@pytest.mark.parametrize("seed", [-1, 1.5, "3", True])
def test_a_bad_seed_is_refused(seed):
    with pytest.raises(TrackError, match="seed"):
        generate(seed)


def test_command_line_writes_circuits_that_load(tmp_path, capsys):
    out = tmp_path / "circuits"
    assert main(["tracks", "--generate", "2", "--seed", "4", "--out", str(out), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["tracks"]
    assert [r["name"] for r in rows] == ["generated-4", "generated-5"]
    for row in rows:
        track = Track.from_csv(row["file"])
        assert track.length == pytest.approx(row["length_m"], rel=2e-3)
        assert track.length == pytest.approx(
            generate(int(row["name"].split("-")[1])).length, rel=2e-3
        )


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["tracks", "--generate", "2"], "needs --out"),
        (["tracks", "--generate", "0", "--out", "x"], "at least 1"),
        (["tracks", "--generate", "1", "--seed", "-2", "--out", "x"], "--seed"),
        (["tracks", "--generate", "1", "--length", "10", "20", "--out", "x"], "length range"),
    ],
)
def test_command_line_refuses_bad_generation_requests(tmp_path, monkeypatch, capsys, argv, words):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert words in capsys.readouterr().err
    assert not (tmp_path / "x").exists()  # refused before any folder is made
