"""The whole pipeline in one call: it plans, picks the weights and drives the lap as the library
would step by step, and refuses bad names with one clear error before any work."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from racing_lib.control.nominal import MODERATE_SPEED_SCALE
from racing_lib.errors import ControlError, PlanningError, RacingLibError, TrackError
from racing_lib.experiments.configs import (
    configuration_name,
    tuned_weights,
)
from racing_lib.experiments.lap import drive_lap
from racing_lib.experiments.pipeline import (
    RaceResult,
    race,
)
from racing_lib.model import CarModel, ModelOptions
from racing_lib.planning import plan
from racing_lib.planning.trajectory import Trajectory

TRIAL_FIELDS = {
    "seed", "completed", "lap_time_s", "vx_mae_mps", "vx_max_err_mps", "ey_mae_m", "ey_max_m",
    "wall_contacts", "wall_contact_time_s", "offtrack_time_s", "solve_time_ms_median",
    "solve_time_ms_p99",
}  # fmt: skip


# --------------------------------------------------------------------------------------------------
# The real track: curvature plan and coupled MPC (about 15 s)

#: Seeds of the curvature-plan laps. Their fate is a property of several laps, never of one: a
#: single closed lap can flip with last-bit floating-point differences between machines.
CURVATURE_SEEDS = 3


@pytest.fixture(scope="module")
def curvature_race() -> RaceResult:
    return race(
        "expressway", method="curvature", controller="coupled-mpc", seed=0, trials=CURVATURE_SEEDS
    )


def test_the_lap_tracks_the_plan_that_was_made(curvature_race):
    r = curvature_race
    assert r.track.name == "expressway"
    assert r.plan is not None and r.plan.method == "curvature" and r.plan.success
    # An MPC tracks the plan itself: its reference lap time is the plan's.
    assert r.spec.trajectory is r.plan.trajectory
    assert r.planned_lap_time == r.plan.lap_time
    assert r.seeds == list(range(CURVATURE_SEEDS))


def test_the_curvature_plan_is_driven_robustly(curvature_race):
    # Robust properties with margins (measured: every seed completes, +2-3 % over the plan).
    metrics = [lap.metrics for lap in curvature_race.laps]
    done = [m for m in metrics if m.completed]
    assert len(done) >= len(metrics) - 1
    for m in done:
        assert np.isfinite(m.lap_time_s)
        assert m.lap_time_s < 1.08 * curvature_race.planned_lap_time, f"seed {m.seed}"
        assert m.controller_stats["fallback_brake"] <= 5, f"seed {m.seed}"
    assert 0.0 < curvature_race.lap_time_gap < 6.0


def test_the_weights_are_those_the_library_picks(curvature_race):
    config = configuration_name("coupled-mpc", "curvature")
    assert config == "curvature-plan" == curvature_race.configuration
    assert curvature_race.spec.weights == tuned_weights(config)


def test_driving_the_spec_again_gives_the_same_lap(curvature_race):
    # race adds nothing to the library's lap: the same spec and seed give the same log, bit for
    # bit, in the same process (completed or not).
    again = drive_lap(curvature_race.spec, seed=0)
    np.testing.assert_array_equal(again.metrics.lap_time_s, curvature_race.metrics.lap_time_s)
    np.testing.assert_array_equal(again.log.vx, curvature_race.lap.log.vx)
    np.testing.assert_array_equal(again.log.ey, curvature_race.lap.log.ey)


def test_summary_has_the_fields_of_the_lap_command(curvature_race):
    summary = curvature_race.summary()
    assert set(summary) == {"track", "controller", "planned_lap_time_s", "trials", "summary"}
    assert summary["controller"] == "coupled-mpc"
    assert summary["planned_lap_time_s"] == curvature_race.plan.lap_time
    trials = summary["trials"]
    assert [t["seed"] for t in trials] == curvature_race.seeds
    assert all(set(t) == TRIAL_FIELDS for t in trials)
    metrics = [lap.metrics for lap in curvature_race.laps]
    done = [m.lap_time_s for m in metrics if m.completed]
    assert summary["summary"]["completed"] == len(done)
    if done:
        assert summary["summary"]["lap_time_mean_s"] == pytest.approx(np.mean(done))
    table = curvature_race.table()
    assert "curvature" in table and f"{len(done)} of {len(metrics)}" in table


# --------------------------------------------------------------------------------------------------
# A short walled track with a ready-made reference (about 1 s per lap)


@pytest.fixture(scope="module")
def stadium():
    from racing_lib.model.identified import identified_params
    from racing_lib.tracks import Arc, Straight, track_from_segments

    track = track_from_segments(
        [Straight(250.0), Arc.degrees(50.0, 180.0), Straight(250.0), Arc.degrees(50.0, 180.0)],
        width=10.0,
        boundary="walls",
        name="stadium",
    )
    # A reference with grip in reserve, labelled as a time-optimal plan so that the main
    # configuration's weights apply to it.
    # The MPC predicts with the identified set; the plan keeps a fifth of its grip (mu 1.0).
    model = CarModel(identified_params(), grip_margin=0.2)
    reference = Trajectory.from_centerline(track, model.planning_params()).with_model(model)
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


def test_a_plan_driven_with_other_model_effects_warns(stadium):
    from racing_lib.experiments.pipeline import ModelMismatchWarning

    track, reference = stadium
    no_drag = reference.model.replace(options=ModelOptions(drag=False))
    lines = []
    with pytest.warns(ModelMismatchWarning, match="drag: plan True, controller False"):
        race(track, controller="coupled-mpc", reference=reference, model=no_drag,
             report=lines.append)  # fmt: skip
    assert any(line.startswith("warning: the plan and the controller") for line in lines)
    # Without a model of its own, the run drives the plan with the model the plan carries.
    with warnings.catch_warnings():
        warnings.simplefilter("error", ModelMismatchWarning)
        result = race(track, controller="coupled-mpc", reference=reference)
    assert result.spec.model == reference.model


def test_every_door_predicts_with_the_plans_model(stadium, tmp_path):
    """CoupledMPC, build_controller and race all predict with the model the plan carries."""
    from racing_lib.control import build_controller
    from racing_lib.control.mpc import CoupledMPC
    from racing_lib.experiments.lap import make_controller
    from racing_lib.model import CarModel, identified_params

    track, _ = stadium
    # Not the default model in any field the MPC reads: friction, drag, steering actuator.
    model = CarModel(
        identified_params().replace(mu=1.05),
        ModelOptions(drag=False),
        steer_tau=0.1,
        steer_rate_max=1.0,
        grip_margin=0.1,
    )
    plan_result = plan(track, "centerline", model)
    traj = plan_result.trajectory
    assert traj.model == model
    # The plan was made with the grip margin applied; the controller predicts without it.
    on_the_limit = Trajectory.from_centerline(track, model.params, options=model.options)
    assert traj.lap_time > 1.02 * on_the_limit.lap_time
    for controller in (
        CoupledMPC(traj, track=track),
        build_controller("coupled-mpc", traj, track=track),
        build_controller("decoupled-mpc", traj, track=track),
    ):
        assert controller.model == model and controller.params == model.params
    result = race(track, method="centerline", controller="coupled-mpc", model=model, trials=1)
    assert result.plan.trajectory.model == model and result.spec.model == model
    assert make_controller(result.spec).model == model
    # A plan saved to its file and driven from it brings the same model.
    path = tmp_path / "plan.csv"
    traj.save_csv(path)
    from_file = race(track, controller="coupled-mpc", reference=path, trials=1)
    assert from_file.spec.model == model
    assert make_controller(from_file.spec).model == model


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
        ({"seed": -5}, RacingLibError, "seed must be a whole number >= 0"),
        ({"seed": 1.5}, RacingLibError, "seed must be a whole number"),
        ({"bogus": 1}, RacingLibError, "unexpected keyword argument 'bogus'.*parameters are"),
        ({"track": None}, TrackError, "track name or a CSV path"),
    ],
)
def test_bad_names_are_one_clear_error(kwargs, error, hint, monkeypatch):
    def no_planning(*args, **kw):
        raise AssertionError("race planned before checking its arguments")

    if "method" not in kwargs:
        monkeypatch.setattr("racing_lib.experiments.pipeline.plan", no_planning)
    with pytest.raises(error, match=hint):
        race(**kwargs)


# --------------------------------------------------------------------------------------------------
# A circuit that crosses itself on a bridge (about 15 s)


def test_a_figure_eight_loads_plans_and_drives():
    from racing_lib.tracks import figure_eight_track

    track = figure_eight_track(radius=80.0, width=12.0)
    (crossing,) = track.centerline.crossings
    r = race(track, method="time-optimal", controller="coupled-mpc", trials=2)
    assert r.plan.success
    # The plan's line crosses itself too, at the same place, and the MPC follows it through.
    assert len(r.plan.trajectory.path.crossings) == 1
    for lap in r.laps:
        m = lap.metrics
        assert m.completed and m.wall_contacts == 0, f"seed {m.seed}"
        # Projected on the wrong branch at the crossing, e_y would jump by tens of metres.
        assert m.ey_max_m < 3.0, f"seed {m.seed}"
        # s_ref runs through the crossing without a jump (the lap is driven once round).
        s = np.unwrap(lap.log.s_ref, period=r.plan.trajectory.length)
        assert np.all(np.diff(s) > 0.0) and np.all(np.diff(s) < 10.0)
    assert 0.0 < r.lap_time_gap < 5.0


def test_every_door_warns_when_told_to_predict_with_another_model(stadium):
    """CoupledMPC, build_controller and LapSpec all warn when given a model that predicts
    differently from the plan's; the same model, or one differing only in margins, is silent."""
    from racing_lib.control import build_controller
    from racing_lib.control.mpc import CoupledMPC
    from racing_lib.experiments.lap import LapSpec, make_controller
    from racing_lib.model import ModelMismatchWarning

    track, reference = stadium
    other = reference.model.replace(steer_tau=0.12)
    with pytest.warns(ModelMismatchWarning, match="steer_tau: plan 0.08, controller 0.12"):
        CoupledMPC(reference, other, track=track)
    with pytest.warns(ModelMismatchWarning, match="steer_tau"):
        build_controller("decoupled-mpc", reference, track=track, model=other)
    with pytest.warns(ModelMismatchWarning, match="steer_tau"):
        make_controller(LapSpec(track, reference, "coupled-mpc", model=other))
    with warnings.catch_warnings():
        warnings.simplefilter("error", ModelMismatchWarning)
        CoupledMPC(reference, reference.model.replace(grip_margin=0.0), track=track)
        build_controller("coupled-mpc", reference, track=track)


def test_a_plan_without_a_model_is_driven_with_the_default_and_says_so(stadium):
    from racing_lib.model import ModelMismatchWarning, identified_model

    track, reference = stadium
    lines: list[str] = []
    with pytest.warns(ModelMismatchWarning, match="carries no model"):
        result = race(track, controller="coupled-mpc", reference=reference.with_model(None),
                      report=lines.append)  # fmt: skip
    assert result.spec.model == identified_model()
    assert any("carries no model" in line for line in lines)
