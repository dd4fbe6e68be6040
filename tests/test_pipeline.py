"""The whole pipeline in one call: it plans, picks the weights and drives the lap as the library
would step by step, and refuses bad names with one clear error before any work."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from racing_lib.control.nominal import MODERATE_SPEED_SCALE
from racing_lib.errors import ControlError, PlanningError, RacingLibError, TrackError
from racing_lib.experiment import drive_lap
from racing_lib.pipeline import RaceResult, race
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tuning import configuration_name, tuned_weights

TRIAL_FIELDS = {
    "seed", "completed", "lap_time_s", "vx_mae_mps", "vx_max_err_mps", "ey_mae_m", "ey_max_m",
    "wall_contacts", "wall_contact_time_s", "offtrack_time_s", "solve_time_ms_median",
    "solve_time_ms_p99",
}  # fmt: skip


# --------------------------------------------------------------------------------------------------
# The real track: curvature plan and coupled MPC (about 5 s)


@pytest.fixture(scope="module")
def curvature_race() -> RaceResult:
    return race("expressway", method="curvature", controller="coupled-mpc", seed=0)


def test_the_lap_tracks_the_plan_that_was_made(curvature_race):
    r = curvature_race
    assert r.track.name == "expressway"
    assert r.plan is not None and r.plan.method == "curvature" and r.plan.success
    # An MPC tracks the plan itself: its reference lap time is the plan's.
    assert r.spec.trajectory is r.plan.trajectory
    assert r.planned_lap_time == r.plan.lap_time
    assert r.completed and r.lap.metrics.completed
    assert np.isfinite(r.metrics.lap_time_s) and r.metrics.lap_time_s > 0.0
    assert r.seeds == [0]


def test_the_weights_are_those_the_library_picks(curvature_race):
    config = configuration_name("coupled-mpc", "curvature")
    assert config == "curvature-plan" == curvature_race.configuration
    assert curvature_race.spec.weights == tuned_weights(config)


def test_driving_the_spec_again_gives_the_same_lap(curvature_race):
    # race adds nothing to the library's lap: the same spec and seed give the same log.
    again = drive_lap(curvature_race.spec, seed=0)
    assert again.metrics.lap_time_s == curvature_race.metrics.lap_time_s
    np.testing.assert_array_equal(again.log.vx, curvature_race.lap.log.vx)
    np.testing.assert_array_equal(again.log.ey, curvature_race.lap.log.ey)


def test_summary_has_the_fields_of_the_lap_command(curvature_race):
    summary = curvature_race.summary()
    assert set(summary) == {"track", "controller", "planned_lap_time_s", "trials", "summary"}
    assert summary["controller"] == "coupled-mpc"
    assert summary["planned_lap_time_s"] == curvature_race.plan.lap_time
    (trial,) = summary["trials"]
    assert set(trial) == TRIAL_FIELDS
    assert summary["summary"]["completed"] == 1
    assert summary["summary"]["lap_time_mean_s"] == curvature_race.metrics.lap_time_s
    table = curvature_race.table()
    assert "curvature" in table and "1 of 1" in table
    assert f"{curvature_race.metrics.lap_time_s:.2f} s" in table


# --------------------------------------------------------------------------------------------------
# A short walled track with a ready-made reference (about 1 s per lap)


@pytest.fixture(scope="module")
def stadium():
    from racing_lib.sysid import identified_params
    from racing_lib.tracks import Arc, Straight, track_from_segments

    track = track_from_segments(
        [Straight(250.0), Arc.degrees(50.0, 180.0), Straight(250.0), Arc.degrees(50.0, 180.0)],
        width=10.0,
        boundary="walls",
        name="stadium",
    )
    # A reference with grip in reserve, labelled as a time-optimal plan so that the main
    # configuration's weights apply to it.
    reference = Trajectory.from_centerline(track, params=identified_params().replace(mu=1.0))
    return track, dataclasses.replace(reference, method="time-optimal")


def test_tuned_default_and_given_weights(stadium):
    track, reference = stadium
    tuned = race(track, controller="coupled-mpc", reference=reference, weights="tuned")
    assert tuned.plan is None and tuned.configuration == "main"
    assert tuned.spec.trajectory is reference
    shipped = tuned_weights("main")
    if shipped:
        assert tuned.spec.weights == shipped and tuned.weights_source == "tuned for 'main'"
    else:  # the shipped file is being regenerated: the MPC falls back to its defaults
        assert tuned.spec.weights is None and tuned.weights_source.startswith("defaults")
    default = race(track, controller="coupled-mpc", reference=reference, weights="default")
    assert default.spec.weights is None and default.weights_source == "defaults"
    given = race(track, controller="coupled-mpc", reference=reference, weights={"w_ey": 7})
    assert given.spec.weights == {"w_ey": 7.0} and given.weights_source == "given"
    assert tuned.completed and default.completed and given.completed


def test_a_plan_file_and_the_nominal_controller(stadium, tmp_path):
    track, reference = stadium
    path = tmp_path / "plan.csv"
    reference.save_csv(path)
    lines = []
    r = race(track, controller="nominal", reference=path, trials=2, seed=3, report=lines.append)
    assert r.plan is None and r.spec.weights is None
    # The nominal driver tracks the plan at a moderate fraction of its speed.
    assert r.planned_lap_time == pytest.approx(reference.lap_time / MODERATE_SPEED_SCALE)
    assert r.seeds == [3, 4] and len(r.summary()["trials"]) == 2
    assert r.completed
    assert any(line.startswith("seed 4:") for line in lines)
    # Loaded on another track, the plan file is refused.
    with pytest.raises(RacingLibError, match="stadium"):
        race("expressway", controller="nominal", reference=path)


# --------------------------------------------------------------------------------------------------
# Bad input: one clear error, before any planning


@pytest.mark.parametrize(
    ("kwargs", "error", "hint"),
    [
        ({"track": "nurburgring"}, TrackError, "expressway"),
        ({"method": "fastest"}, PlanningError, "time-optimal"),
        ({"controller": "pid"}, ControlError, "coupled-mpc"),
        ({"weights": "best"}, ControlError, "tuned"),
        ({"weights": 3.0}, ControlError, "dict"),
        ({"controller": "nominal", "weights": {"w_ey": 1.0}}, ControlError, "nominal"),
        ({"trials": 0}, RacingLibError, "at least 1"),
    ],
)
def test_bad_names_are_one_clear_error(kwargs, error, hint, monkeypatch):
    def no_planning(*args, **kw):
        raise AssertionError("race planned before checking its arguments")

    if "method" not in kwargs:
        monkeypatch.setattr("racing_lib.pipeline.plan", no_planning)
    with pytest.raises(error, match=hint):
        race(**kwargs)
