"""The stress setting of chapter 07: the controller ablations on a plan without a grip margin."""

from __future__ import annotations

import numpy as np
import pytest

from racing_lib.errors import ArgumentError
from racing_lib.experiments.ablation.stress import (
    Comparison,
    StressResult,
    compare_to_main,
    stress_run,
    stress_table,
)
from racing_lib.experiments.lap import LapMetrics


def _metrics(seed: int, lap: float, walls: int = 0, completed: bool = True) -> LapMetrics:
    return LapMetrics(
        seed=seed,
        completed=completed,
        lap_time_s=lap,
        vx_mae_mps=0.2,
        vx_max_err_mps=1.0,
        ey_mae_m=0.1,
        ey_max_m=0.5,
        wall_contacts=walls,
        wall_contact_time_s=0.0,
        offtrack_time_s=0.0,
        solve_time_ms_median=1.0,
        solve_time_ms_p99=2.0,
    )


@pytest.fixture(scope="module")
def at_the_limit() -> StressResult:
    return stress_run("expressway", grip_margin=0.0, seeds=3, configs=("main", "decoupled"))


def test_at_the_limit_the_decoupled_mpc_falls_behind_the_coupled_one(at_the_limit):
    main, decoupled = at_the_limit.laps["main"], at_the_limit.laps["decoupled"]
    assert [m.seed for m in main] == [m.seed for m in decoupled] == [0, 1, 2]
    assert all(m.completed for m in main + decoupled)
    # Measured (10 seeds): main about 105.7 s and clean, decoupled about 107.6 s, a contact a lap.
    assert sum(m.wall_contacts for m in main) == 0
    lap = {c: at_the_limit.values(c, "lap_time_s").mean() for c in at_the_limit.laps}
    assert lap["decoupled"] > lap["main"] + 1.0
    verdicts = {c.measure: c.verdict for c in compare_to_main(at_the_limit)}
    assert verdicts["lap time"] == "worse"
    assert at_the_limit.planned_lap_s < lap["main"]


def test_the_weighing_calls_a_difference_inside_the_spread_indistinguishable():
    laps = {
        "main": [_metrics(s, t) for s, t in enumerate((100.0, 100.4, 99.8))],
        "decoupled": [_metrics(s, t) for s, t in enumerate((100.1, 100.5, 99.9))],
        "no-smooth-transition": [_metrics(s, 104.0 + 0.1 * s, walls=2) for s in range(3)],
    }
    result = StressResult("expressway", 0.0, 99.0, laps)
    by = {(c.config, c.measure): c for c in compare_to_main(result)}
    assert by["decoupled", "lap time"].verdict == "indistinguishable"
    assert by["no-smooth-transition", "lap time"].verdict == "worse"
    assert by["no-smooth-transition", "wall contacts"].low > 0
    assert Comparison("x", "lap time", "s", 1.0, 2.0, -1.5, -0.5).verdict == "better"
    header, rows = stress_table(result)
    assert len(rows) == 3 and all(len(r) == len(header) for r in rows)
    assert rows[2][6] == "6" and rows[0][1] == "3/3"


def test_an_incomplete_lap_is_left_out_of_the_means_and_counted():
    laps = {"main": [_metrics(0, 100.0), _metrics(1, 0.0, completed=False)]}
    result = StressResult("expressway", 0.0, 99.0, laps)
    assert np.array_equal(result.values("main", "lap_time_s"), [100.0])
    assert stress_table(result)[1][0][1] == "1/2"


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        ({"grip_margin": 5.0}, "a share, not a %"),
        ({"configs": ("decoupled",)}, "must include 'main'"),
        ({"configs": ("main", "no-such-row")}, "unknown: ['no-such-row']"),
        ({"configs": ("main", "no-drag")}, "plan differently from main"),
        ({"seeds": []}, "seeds is empty"),
    ],
)
def test_bad_arguments_get_one_clear_error_before_any_lap(kwargs, named):
    with pytest.raises(ArgumentError, match=named.replace("[", r"\[").replace("]", r"\]")):
        stress_run("expressway", **kwargs)
