"""The planning entry point, racing_lib.planning.plan: its arguments are checked before any solve,
and a large plan says what it will cost before it starts."""

from __future__ import annotations

import numpy as np
import pytest

import racing_lib.planning as planning
from racing_lib.errors import ArgumentError, PlanningError, RacingLibError
from racing_lib.geometry import (
    Path,
    Track,
)
from racing_lib.planning import LargePlanWarning, plan
from racing_lib.tracks import load_track


@pytest.fixture(scope="module")
def track():
    return load_track("shortcut")


def _no_solve(*args, **kwargs):
    raise AssertionError("a solver ran although the arguments were bad")


@pytest.mark.parametrize(
    ("kwargs", "error", "says"),
    [
        ({"bogus": 1}, ArgumentError, "unexpected keyword argument 'bogus'.*spacing"),
        ({"method": "fastest"}, PlanningError, "unknown planning method"),
        ({"spacing": 0.0}, PlanningError, "between 0.5 and 20 m"),
        ({"spacing": float("nan")}, PlanningError, "between 0.5 and 20 m"),
        ({"start": "hot"}, PlanningError, "'cold' or 'warm'"),
        ({"model": "identified"}, PlanningError, "CarModel"),
    ],
)
def test_bad_arguments_are_refused_before_any_solve(track, monkeypatch, kwargs, error, says):
    monkeypatch.setattr(planning, "solve_curvature", _no_solve)
    monkeypatch.setattr(planning, "solve_time_optimal", _no_solve)
    with pytest.raises(error, match=says) as err:
        plan(track, **kwargs)
    assert isinstance(err.value, RacingLibError)


def test_a_name_instead_of_a_track_says_how_to_load_one():
    with pytest.raises(PlanningError, match="load_track"):
        plan("expressway")


def test_a_very_long_track_warns_of_its_cost_before_the_solve(monkeypatch):
    # A 20 km loop: 6,700 nodes at 3 m.
    t = np.linspace(0.0, 2.0 * np.pi, 800, endpoint=False)
    radius = 20_000.0 / (2.0 * np.pi)
    big = Track(Path(radius * np.cos(t), radius * np.sin(t)), 6.0, 6.0, name="ring")

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop

    monkeypatch.setattr(planning, "solve_curvature", stop)
    lines = []
    with pytest.warns(LargePlanWarning, match=r"20\.0 km long: 6666 nodes .* --spacing 6"):
        with pytest.raises(Stop):
            plan(big, method="curvature", report=lines.append)
    assert lines[0].startswith("warning: track 'ring'")
    assert "min and" in lines[0] and "GB of memory" in lines[0]


class _Stop(Exception):
    pass


def test_the_nlp_starts_cold_unless_told_and_only_a_warm_start_reports_the_qp(track, monkeypatch):
    # The cold start is the default because it was the faster plan on every circuit measured
    # (benchmarks/bench_plan_speed.py); the warm start solves the curvature QP first.
    starts = []

    def record(*args, start, **kwargs):
        starts.append(start)
        raise _Stop

    monkeypatch.setattr(planning, "solve_time_optimal", record)
    reports = {}
    for start in (None, "warm"):
        lines = []
        kwargs = {} if start is None else {"start": start}
        with pytest.raises(_Stop):
            plan(track, report=lines.append, **kwargs)
        reports[start] = lines
    assert starts == ["cold", "warm"] and planning.DEFAULT_START == "cold"
    assert not any("curvature QP" in line for line in reports[None])
    assert any("curvature QP" in line for line in reports["warm"])
    assert any("warm start" in line for line in reports["warm"])


def test_the_command_line_passes_its_start_to_the_planner(monkeypatch):
    from racing_lib.face.cli import main

    starts = []

    def record(*args, start, **kwargs):
        starts.append(start)
        raise _Stop

    monkeypatch.setattr(planning, "solve_time_optimal", record)
    for extra in ([], ["--start", "warm"], ["--start", "cold"]):
        with pytest.raises(_Stop):
            main(["plan", "--track", "shortcut", *extra])
    assert starts == ["cold", "warm", "cold"]
