"""CMA-ES tuning: the objective on hand-made logs, the machinery on functions with known minima,
executors (process pool, Dask), checkpoints and resume, and a short tuning of real laps."""

from __future__ import annotations

import functools
import json
import math
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from racing_lib.errors import ControlError
from racing_lib.experiments.configs import (
    tuned_configurations,
    tuned_weights,
)
from racing_lib.experiments.lap import (
    LapLog,
    LapMetrics,
    LapSpec,
    drive_lap,
)
from racing_lib.experiments.tuning import (
    INCOMPLETE_PENALTY,
    evaluate_nominal_gains,
    evaluate_weights,
    mpc_weight_space,
    nominal_gain_space,
    tune_nominal_gains,
    tune_weights,
    tuning_objective,
)
from racing_lib.model import CarModel, identified_params
from racing_lib.optim.cmaes import (
    HISTORY_FILE,
    STATE_FILE,
    SearchSpace,
    TuningSettings,
    tune,
)
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tracks import circle_track

# --------------------------------------------------------------------------------------------------
# The objective on hand-made logs


def _log(ey, vx, vx_ref, s_track, in_lap=None) -> LapLog:
    n = len(ey)
    z = np.zeros(n)
    return LapLog(
        t=0.1 * np.arange(n),
        x=z,
        y=z,
        psi=z,
        vx=np.asarray(vx, float) * np.ones(n),
        vy=z,
        r=z,
        steer=z,
        pedal=z,
        s_ref=np.asarray(s_track, float),
        ey=np.asarray(ey, float),
        vx_ref=np.asarray(vx_ref, float) * np.ones(n),
        s_track=np.asarray(s_track, float),
        solve_ms=z,
        in_lap=np.ones(n, bool) if in_lap is None else np.asarray(in_lap, bool),
    )


def _metrics(completed=True, wall=0.0, offtrack=0.0) -> LapMetrics:
    nan = float("nan")
    return LapMetrics(
        seed=0,
        completed=completed,
        lap_time_s=10.0 if completed else nan,
        vx_mae_mps=nan,
        vx_max_err_mps=nan,
        ey_mae_m=nan,
        ey_max_m=nan,
        wall_contacts=int(wall > 0),
        wall_contact_time_s=wall,
        offtrack_time_s=offtrack,
        solve_time_ms_median=nan,
        solve_time_ms_p99=nan,
    )


def test_constant_lateral_error_scores_twice_the_error_minus_the_distance():
    c, n, ds = 0.3, 101, 2.0
    s = ds * np.arange(n)  # 200 m travelled in 100 steps
    log = _log(np.full(n, -c), 20.0, 20.0, s)
    assert tuning_objective(log, _metrics(), w_s=0.0) == pytest.approx(2 * c)
    assert tuning_objective(log, _metrics(), w_s=0.001, track_length=1000.0) == pytest.approx(
        2 * c - 0.001 * 200.0
    )
    # The per-step reading: mean distance per step.
    assert tuning_objective(log, _metrics(), w_s=0.5, distance="mean") == pytest.approx(
        2 * c - 0.5 * ds
    )


def test_objective_terms_add_up():
    # max |e_y| = 3, mean |e_y| = 1, |v_x - v_ref| = 1.5, 0.4 s at the wall + 0.2 s off track
    ey = [0.0, 1.0, -3.0, 0.0]
    log = _log(ey, 18.5, 20.0, [0.0, 1.0, 2.0, 3.0])
    value = tuning_objective(log, _metrics(wall=0.4, offtrack=0.2), w_t=10.0, w_s=0.0)
    assert value == pytest.approx(3.0 + 1.0 + 1.5 + 10.0 * 0.6)


def test_only_the_steps_of_the_lap_count():
    # A large error in the run-up (not in the lap) must not count.
    ey = [5.0, 5.0, 0.2, 0.2, 0.2]
    log = _log(ey, 20.0, 20.0, [0, 1, 2, 3, 4], in_lap=[0, 0, 1, 1, 1])
    assert tuning_objective(log, _metrics(), w_s=0.0) == pytest.approx(0.4)


def test_incomplete_laps_rank_by_distance_and_above_completed_ones():
    length = 1000.0
    # Crosses the line (950 -> 1000 = 0 -> 250): 300 m covered; the wrap must be undone.
    s_far = np.concatenate([np.linspace(950.0, 995.0, 10), np.linspace(0.0, 250.0, 20)])
    s_near = np.linspace(950.0, 990.0, 30)  # 40 m covered
    far = tuning_objective(_log(np.zeros(30), 0, 0, s_far), _metrics(False), track_length=length)
    near = tuning_objective(_log(np.zeros(30), 0, 0, s_near), _metrics(False), track_length=length)
    assert INCOMPLETE_PENALTY < far < near <= 2 * INCOMPLETE_PENALTY
    assert far == pytest.approx(INCOMPLETE_PENALTY * (1 + math.exp(-300.0 / length)))
    bad_complete = tuning_objective(
        _log(np.full(30, 5.0), 0, 30, s_near), _metrics(True, wall=20.0)
    )
    assert bad_complete < far
    assert math.isfinite(near)


# --------------------------------------------------------------------------------------------------
# The machinery on functions with known minima


def shifted_sphere(params: dict[str, float], center: tuple[float, ...]) -> float:
    """(log10 p_i - c_i)^2 summed: minimum 0 at p_i = 10^c_i."""
    return float(sum((math.log10(params[f"p{i}"]) - c) ** 2 for i, c in enumerate(center)))


def rosenbrock_log(params: dict[str, float]) -> float:
    """Rosenbrock in log10 space (a curved valley: a non-trivial CMA-ES path)."""
    a, b = math.log10(params["a"]), math.log10(params["b"])
    return (1.0 - a) ** 2 + 100.0 * (b - a * a) ** 2


def _runs(history):
    """A history without its wall times (the only part that may differ between equal runs)."""
    return [{k: v for k, v in h.items() if k != "elapsed"} for h in history]


def _space(names, start=1.0, lo=1e-3, hi=1e3) -> SearchSpace:
    return SearchSpace.from_bounds({n: (lo, start, hi) for n in names})


CENTER = (1.0, -0.5, 2.0, 0.3)


def test_cma_es_solves_a_shifted_sphere_in_log_space():
    f = functools.partial(shifted_sphere, center=CENTER)
    space = _space([f"p{i}" for i in range(4)])
    res = tune(f, space, TuningSettings(sigma0=1.0, max_generations=200, seed=3), progress=False)
    assert res.success
    assert res.best_objective < 1e-6
    got = np.log10([res.best_weights[f"p{i}"] for i in range(4)])
    np.testing.assert_allclose(got, CENTER, atol=1e-3)
    assert res.generations == len(res.history)
    assert res.evaluations == sum(len(h["objectives"]) for h in res.history)
    # best-so-far never gets worse
    best = [h["best_objective"] for h in res.history]
    assert all(b1 <= b0 for b0, b1 in zip(best, best[1:], strict=False))


def test_the_box_is_respected():
    # The unconstrained minimum (p0 = 1e4) lies beyond the upper bound 1e3: the best is on it.
    f = functools.partial(shifted_sphere, center=(4.0,))
    res = tune(f, _space(["p0"]), TuningSettings(max_generations=40, seed=0), progress=False)
    assert res.best_weights["p0"] == pytest.approx(1e3, rel=1e-3)
    for h in res.history:
        assert all(1e-3 <= c["p0"] <= 1e3 for c in h["candidates"])


def test_same_seed_same_run_and_global_rng_untouched():
    f = functools.partial(shifted_sphere, center=CENTER)
    space = _space([f"p{i}" for i in range(4)])
    st = TuningSettings(max_generations=5, seed=11)
    # pycma samples from numpy's legacy global generator unless told otherwise; ours must not.
    np.random.seed(123)  # noqa: NPY002
    before = np.random.random()  # noqa: NPY002
    np.random.seed(123)  # noqa: NPY002
    r1 = tune(f, space, st, progress=False)
    assert np.random.random() == before  # noqa: NPY002
    r2 = tune(f, space, st, progress=False)
    assert _runs(r1.history) == _runs(r2.history)
    r3 = tune(f, space, TuningSettings(max_generations=5, seed=12), progress=False)
    assert _runs(r3.history) != _runs(r1.history)


class _Interrupt:
    """Evaluates ``f`` and raises KeyboardInterrupt at call number ``at`` (a Ctrl-C mid-run)."""

    def __init__(self, f, at: int) -> None:
        self.f, self.at, self.calls = f, at, 0

    def __call__(self, params):
        self.calls += 1
        if self.calls == self.at:
            raise KeyboardInterrupt
        return self.f(params)


def test_an_interrupted_run_resumes_to_the_identical_result(tmp_path):
    space = _space(["a", "b"], start=0.1, lo=1e-2, hi=1e2)
    st4 = TuningSettings(popsize=6, max_generations=4, seed=5)
    straight = tune(rosenbrock_log, space, st4, progress=False)

    # Stopped after generation 2 (budget), then resumed with the larger budget.
    st2 = TuningSettings(popsize=6, max_generations=2, seed=5)
    part = tune(rosenbrock_log, space, st2, out_dir=tmp_path / "a", progress=False)
    assert part.generations == 2
    resumed = tune(rosenbrock_log, space, st4, out_dir=tmp_path / "a", resume=True, progress=False)
    assert _runs(resumed.history) == _runs(straight.history)
    assert resumed.best_weights == straight.best_weights
    assert resumed.best_objective == straight.best_objective
    assert resumed.evaluations == straight.evaluations == 24

    # Interrupted in the middle of generation 3 (Ctrl-C): generations 1-2 are on disk.
    with pytest.raises(KeyboardInterrupt):
        tune(_Interrupt(rosenbrock_log, at=15), space, st4, out_dir=tmp_path / "b", progress=False)
    saved = json.loads((tmp_path / "b" / HISTORY_FILE).read_text())
    assert saved["generations"] == 2 and len(saved["history"]) == 2
    assert (tmp_path / "b" / STATE_FILE).exists()
    again = tune(rosenbrock_log, space, st4, out_dir=tmp_path / "b", resume=True, progress=False)
    assert again.best_weights == straight.best_weights
    assert _runs(again.history) == _runs(straight.history)

    # The saved history describes the finished run.
    saved = json.loads((tmp_path / "b" / HISTORY_FILE).read_text())
    assert saved["status"] == "max_generations" and saved["generations"] == 4
    assert saved["best_objective"] == pytest.approx(straight.best_objective)
    assert len(saved["history"][0]["candidates"]) == 6


def test_resuming_with_other_settings_is_refused(tmp_path):
    space = _space(["a", "b"])
    st = TuningSettings(popsize=4, max_generations=1)
    tune(rosenbrock_log, space, st, out_dir=tmp_path, progress=False)
    with pytest.raises(ControlError, match="other settings"):
        tune(
            rosenbrock_log,
            space,
            TuningSettings(popsize=4, max_generations=2, sigma0=0.9),
            out_dir=tmp_path,
            resume=True,
            progress=False,
        )


def test_bad_search_spaces_are_refused():
    with pytest.raises(ControlError, match="> 0"):
        SearchSpace.from_bounds({"w": (0.0, 1.0, 10.0)})
    with pytest.raises(ControlError, match="lower <= initial <= upper"):
        SearchSpace.from_bounds({"w": (1.0, 100.0, 10.0)})


def test_fast_mode_shrinks_the_budget_only(monkeypatch):
    monkeypatch.setenv("RACING_LIB_FAST", "1")
    fast = TuningSettings.default()
    monkeypatch.setenv("RACING_LIB_FAST", "0")
    full = TuningSettings.default()
    assert fast.max_generations < full.max_generations
    assert fast.sigma0 == full.sigma0 and fast.tolfun == full.tolfun


def test_mpc_weight_space_holds_the_six_weights_of_the_paper():
    space = mpc_weight_space()
    assert space.names == ("w_vx", "w_vy", "w_r", "w_epsi", "w_ey", "w_ddelta")
    assert all(
        lo <= x0 <= hi for lo, x0, hi in zip(space.lower, space.initial, space.upper, strict=True)
    )


# --------------------------------------------------------------------------------------------------
# Real laps (nominal controller on a circle: 0.2 s per lap)


@pytest.fixture(scope="module")
def circle_spec() -> LapSpec:
    track = circle_track(radius=100.0, width=12.0)
    reference = Trajectory.from_centerline(track, identified_params()).scale_speed(0.75)
    return LapSpec(track=track, trajectory=reference, controller="nominal", run_up=30.0)


def test_lap_evaluation_is_the_objective_of_the_lap(circle_spec):
    res = drive_lap(circle_spec, seed=0)
    expected = tuning_objective(res.log, res.metrics, track_length=circle_spec.track.length)
    assert evaluate_weights(circle_spec, {}, (0,)) == expected
    # build_controller's nominal driver has the default gains: the same lap
    assert evaluate_nominal_gains(circle_spec, {}, 0) == expected
    assert res.metrics.completed and expected < INCOMPLETE_PENALTY


def test_weights_scored_on_several_circuits_get_the_mean_objective(circle_spec):
    import dataclasses

    from racing_lib.tracks import circle_track

    wider = circle_track(radius=150.0, width=12.0)
    other = dataclasses.replace(
        circle_spec,
        track=wider,
        trajectory=Trajectory.from_centerline(wider, identified_params()).scale_speed(0.75),
    )
    one, two = evaluate_weights(circle_spec, {}, (0,)), evaluate_weights(other, {}, (0,))
    assert one != two
    assert evaluate_weights([circle_spec, other], {}, (0,)) == pytest.approx(0.5 * (one + two))


SMALL = TuningSettings(popsize=4, max_generations=2, seed=2)


@pytest.fixture(scope="module")
def serial_nominal(circle_spec):
    return tune_nominal_gains(circle_spec, (0,), settings=SMALL, workers=1, progress=False)


def test_tuning_improves_the_nominal_gains(circle_spec):
    space = nominal_gain_space()
    start = evaluate_nominal_gains(
        circle_spec, dict(zip(space.names, space.initial, strict=True)), (0,)
    )
    res = tune_nominal_gains(
        circle_spec,
        (0,),
        settings=TuningSettings(popsize=6, max_generations=3, seed=0),
        workers=1,
        progress=False,
    )
    assert res.success
    assert res.best_objective < 0.8 * start
    # The best gains really are that good when driven again.
    assert evaluate_nominal_gains(circle_spec, res.best_weights, (0,)) == res.best_objective


def test_process_pool_gives_the_serial_result(circle_spec, serial_nominal):
    with ProcessPoolExecutor(max_workers=2) as pool:
        res = tune_nominal_gains(circle_spec, (0,), settings=SMALL, executor=pool, progress=False)
    assert _runs(res.history) == _runs(serial_nominal.history)
    assert res.best_weights == serial_nominal.best_weights


def test_dask_cluster_gives_the_serial_result(circle_spec, serial_nominal):
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        res = tune_nominal_gains(
            circle_spec, (0,), settings=SMALL, executor=client.get_executor(), progress=False
        )
        # A Client itself is accepted too.
        f = functools.partial(shifted_sphere, center=(1.0,))
        st = TuningSettings(popsize=4, max_generations=3, seed=1)
        by_client = tune(f, _space(["p0"]), st, executor=client, progress=False)
    assert _runs(res.history) == _runs(serial_nominal.history)
    assert res.best_weights == serial_nominal.best_weights
    assert (
        by_client.history[-1]["x"] == tune(f, _space(["p0"]), st, progress=False).history[-1]["x"]
    )


# --------------------------------------------------------------------------------------------------
# Shipped tuned weights


def test_tuned_weights_loader():
    assert tuned_weights("no-such-configuration") is None
    for name in tuned_configurations():
        weights = tuned_weights(name)
        assert set(weights) == set(mpc_weight_space().names)
        assert all(w > 0 and math.isfinite(w) for w in weights.values())


def test_every_shipped_set_is_tuned_by_one_protocol_on_circuits_nothing_reports_on():
    """Same circuits, seeds and budget for every row; none of them a circuit the course reports."""
    from racing_lib.experiments.configs import main_tuning_tracks, tuning_record
    from racing_lib.tracks import builtin_track_names

    tuning_names = [t.name for t in main_tuning_tracks()]
    main = tuning_record("main")
    assert main["track"] == tuning_names
    assert main["started_from"] == "defaults"
    for name in tuned_configurations():
        record = tuning_record(name)
        assert record["track"] == tuning_names, name
        assert record["seeds"] == main["seeds"], name
        assert record["settings"] == main["settings"], name
        assert record["generations"] == main["generations"], name
        if name != "main":
            assert record["started_from"] == "tuned 'main'", name
    # Drawn by the generator, so no real circuit and none of the built-in tracks is among them.
    assert all(name.startswith("generated-") for name in tuning_names)
    assert set(builtin_track_names()).isdisjoint(tuning_names)


# --------------------------------------------------------------------------------------------------
# The MPC weights (a short walled track: about 1 s per lap)


@pytest.fixture(scope="module")
def stadium_spec() -> LapSpec:
    from racing_lib.model.identified import identified_params
    from racing_lib.tracks import Arc, Straight, track_from_segments

    track = track_from_segments(
        [Straight(250.0), Arc.degrees(50.0, 180.0), Straight(250.0), Arc.degrees(50.0, 180.0)],
        width=10.0,
        boundary="walls",
        name="stadium",
    )
    # A plan with grip in reserve, as in test_mpc: the test is about tuning, not about the plan.
    # The MPC predicts with the identified set; the plan keeps a fifth of its grip (mu 1.0).
    model = CarModel(identified_params(), grip_margin=0.2)
    plan = Trajectory.from_centerline(track, model.planning_params()).with_model(model)
    return LapSpec(track=track, trajectory=plan, controller="coupled-mpc", run_up=50.0)


@pytest.mark.slow
def test_tuning_improves_the_mpc_weights(stadium_spec):
    space = mpc_weight_space()
    start = evaluate_weights(stadium_spec, dict(zip(space.names, space.initial, strict=True)), 0)
    res = tune_weights(
        stadium_spec,
        (0,),
        settings=TuningSettings(popsize=6, max_generations=2, seed=0),
        workers=2,
        progress=False,
    )
    assert res.success and res.evaluations == 12
    # Measured: 0.03 -> -0.21 (J includes -w_s * lap length = -0.81, so the error terms of J
    # drop from 0.84 to 0.60).
    assert res.best_objective < start - 0.1
    assert set(res.best_weights) == set(space.names)


def test_weights_that_are_no_settings_are_refused(stadium_spec):
    with pytest.raises(ControlError, match="w_bogus"):
        evaluate_weights(stadium_spec, {"w_bogus": 1.0}, 0)
