"""Learning from laps (chapter 09): the sparse GP, the model correction and the loop.

The GP is checked against a function it must recover, its CasADi form against its NumPy form;
the correction against the equations it is added to (exactly its mean, nothing else); the residuals
on real laps of the simulated car (learning must improve the prediction of a lap it did not see);
the loop for its files, its resumption and its refusals.
"""

from __future__ import annotations

import dataclasses
import json

import casadi as ca
import numpy as np
import pytest

from racing_lib.errors import ArgumentError, ModelError
from racing_lib.experiments.lap import LapLog
from racing_lib.experiments.learning import (
    EDGE_SAFETY,
    EXCURSION_WINDOW,
    MIN_CAUTION,
    IterationResult,
    LearningRun,
    LearnSettings,
    _caution,
    _iteration_model,
    _line,
    edge_excursions,
    known_best_lap,
    learn,
    planning_track,
    slip_share,
)
from racing_lib.experiments.learning_results import beyond_text
from racing_lib.experiments.pipeline import race
from racing_lib.experiments.track_margins import margin_excess
from racing_lib.face.cli import main
from racing_lib.model import (
    CarModel,
    ModelCorrection,
    ModelParams,
    identified_model,
    model_terms,
    time_dynamics,
)
from racing_lib.model.drive import Drive
from racing_lib.model.gp import SparseGP, fit_sparse_gp
from racing_lib.model.residuals import (
    ResidualSamples,
    fit_correction,
    one_step_errors,
    residual_samples,
)
from racing_lib.planning import TimeOptimalSettings
from racing_lib.planning.grid import default_margin
from racing_lib.tracks import load_track


def _smooth(x: np.ndarray) -> np.ndarray:
    return np.sin(1.5 * x[:, 0]) + 0.5 * x[:, 1] ** 2


@pytest.fixture(scope="module")
def gp() -> tuple[SparseGP, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    x = rng.uniform(-1.5, 1.5, size=(600, 2))
    y = _smooth(x) + 0.05 * rng.standard_normal(600)
    return fit_sparse_gp(x, y, inducing=30, seed=0), x, y


def test_the_gp_recovers_a_smooth_function(gp):
    model, _, _ = gp
    test = np.random.default_rng(4).uniform(-1.2, 1.2, size=(300, 2))
    err = model.mean(test) - _smooth(test)
    assert np.sqrt(np.mean(err**2)) < 0.1  # the noise is 0.05, the signal about 1
    assert 0.02 < model.sn < 0.1


def test_the_gp_is_unsure_far_from_its_data(gp):
    model, x, _ = gp
    near = model.std(x[:50]).max()
    far = model.std(np.array([[50.0, 50.0]]))[0]
    assert near < 0.3 * model.sf
    assert far == pytest.approx(model.sf, rel=1e-3)
    assert abs(model.mean(np.array([[50.0, 50.0]]))[0]) < 1e-3  # back to the prior mean


def test_the_gp_in_casadi_is_the_gp_in_numpy(gp):
    model, _, _ = gp
    z = ca.SX.sym("z", 2)
    f = ca.Function("f", [z], [model.casadi_mean(z), model.casadi_std(z)])
    pts = np.array([[0.3, -0.2], [1.0, 1.0], [5.0, 0.0]])
    for p, m, s in zip(pts, model.mean(pts), model.std(pts), strict=True):
        got_m, got_s = (float(v) for v in f(p))
        assert got_m == pytest.approx(m, abs=1e-10)
        assert got_s == pytest.approx(s, abs=2e-3 * model.sf)  # the smooth floor of the sqrt


def test_the_gp_is_deterministic_and_round_trips(gp):
    model, x, y = gp
    again = fit_sparse_gp(x, y, inducing=30, seed=0)
    assert np.array_equal(again.w, model.w)
    back = SparseGP.from_dict(json.loads(json.dumps(model.to_dict())))
    assert np.array_equal(back.mean(x[:5]), model.mean(x[:5]))


@pytest.mark.parametrize(
    ("x", "y", "match"),
    [
        (np.zeros((5, 2)), np.zeros(5), "at least 10"),
        (np.zeros((20, 2)), np.zeros(19), "must be"),
        (np.full((20, 2), np.nan), np.zeros(20), "NaN"),
    ],
)
def test_the_gp_refuses_bad_data(x, y, match):
    with pytest.raises(ModelError, match=match):
        fit_sparse_gp(x, y)


def _correction(scale: float = 1.0) -> ModelCorrection:
    """A correction with GPs fitted on made-up residuals over the four features."""
    rng = np.random.default_rng(1)
    z = np.column_stack(
        [
            rng.uniform(10, 50, 300),
            rng.uniform(-0.08, 0.08, 300),
            rng.uniform(-0.08, 0.08, 300),
            rng.uniform(-8, 3, 300),
        ]
    )
    ys = [scale * 0.3 * z[:, 3] / 8, scale * 20 * z[:, 1], -scale * 10 * z[:, 2]]
    return ModelCorrection([fit_sparse_gp(z, y, inducing=12) for y in ys], label="test")


def test_the_equations_add_exactly_the_correction():
    base = identified_model().params
    corr = _correction()
    xi = np.array([30.0, 0.4, 0.2, 0.01, 0.5, 100.0])
    u = np.array([0.05, -2.0])
    f0 = np.asarray(time_dynamics(base, identified_model().options)(xi, u, 0.01, 0.0)).ravel()
    params = base.replace(correction=corr)
    f1 = np.asarray(time_dynamics(params, identified_model().options)(xi, u, 0.01, 0.0)).ravel()
    terms = model_terms(base, identified_model().options)(xi=xi, u=u, kappa=0.01, theta=0.0)
    z = np.array([[xi[0], float(terms["alpha_f"]), float(terms["alpha_r"]), u[1]]])
    expected = corr.mean(z)[0]
    assert np.allclose(f1[:3] - f0[:3], expected, atol=1e-12)
    assert np.array_equal(f1[3:], f0[3:])  # the kinematics are not corrected


def test_a_correction_travels_with_its_model():
    model = identified_model()
    corrected = model.replace(params=model.params.replace(correction=_correction()))
    data = json.loads(json.dumps(corrected.to_dict()))
    back = CarModel.from_dict(data)
    assert back == corrected
    assert hash(back.params.correction) == hash(corrected.params.correction)
    assert "correction" not in model.params.to_dict()  # files without one are unchanged
    assert model.differences(corrected) == ["parameters correction"]
    assert _correction(2.0) != _correction()


def test_every_correction_of_one_layout_shares_one_build():
    # The GP data are an input of the compiled code, not constants in it: a second correction
    # of the same layout reuses the first one's build and gives its own model's numbers.
    from racing_lib.control.mpc.linearize import _substep_linearization, substep_linearization
    from racing_lib.model.correction import correction_template
    from racing_lib.model.equations import correction_as_input, discretize

    model = identified_model()
    first, second = _correction(), _correction(2.0)
    assert first.layout == second.layout
    build, values = correction_as_input(model.params.replace(correction=second))
    assert build.correction is correction_template(second.layout)
    assert np.array_equal(np.asarray(values[0]).ravel(), second.packed())
    xi, u = np.array([30.0, 0.4, 0.2, 0.01, 0.5, 100.0]), np.array([0.05, -2.0])
    x, v = ca.SX.sym("x", 6), ca.SX.sym("v", 2)
    _substep_linearization.cache_clear()
    substep_linearization.cache_clear()
    for corr in (first, second):
        params = model.params.replace(correction=corr)
        lin = substep_linearization(params, model.options, 0.1, 2, True)
        step = discretize(params, model.options, 0.05)  # the GP data as constants of the graph
        end = step(step(x, v, 0.01, 0.0), v, 0.01, 0.0)
        jac_x, jac_u = ca.jacobian(end, x), ca.jacobian(end, v)
        ref = ca.Function("ref", [x, v], [jac_x, jac_u, end - jac_x @ x - jac_u @ v])
        for got, want in zip(lin(xi, u, 0.01, 0.0), ref(xi, u), strict=True):
            assert np.allclose(np.asarray(got), np.asarray(want), rtol=1e-11, atol=1e-11)
    assert _substep_linearization.cache_info().misses == 1  # one build for both corrections
    with pytest.raises(ModelError, match="symbols"):
        build.correction.to_dict()


def test_the_plans_derivatives_with_the_data_as_input_are_those_with_constants():
    from racing_lib.planning.time_optimal import TimeOptimalSettings, _shape_settings
    from racing_lib.planning.time_optimal_nlp import _interval_functions, interval_functions

    model = identified_model()
    params = model.params.replace(correction=_correction())
    st = _shape_settings(TimeOptimalSettings(uncertainty_margin=2.0, jit=False))
    bound = interval_functions(params, model.options, st)  # the template, then its data
    constants = _interval_functions(params, model.options, st)  # the data in the graph
    rng = np.random.default_rng(5)
    args = [rng.uniform(0.5, 1.5, 7), rng.uniform(0.5, 1.5, 7), [0.02, 0.0, 100.0],
            [0.02, 0.0, 103.0], 3.0]  # fmt: skip
    for name in ("con", "con_jac", "obj_grad", "inv_sdot"):
        fn_args = args[:1] + args[2:3] if name == "inv_sdot" else args
        got = np.asarray(getattr(bound, name)(*fn_args))
        want = np.asarray(getattr(constants, name)(*fn_args))
        assert np.allclose(got, want, rtol=1e-7, atol=1e-9), name  # round-off only
    lam = rng.normal(0.0, 1.0, bound.n_con)
    got, want = bound.hess(*args, 0.7, lam), constants.hess(*args, 0.7, lam)
    assert np.allclose(np.asarray(got), np.asarray(want), rtol=1e-7, atol=1e-9)


def test_a_damaged_correction_is_refused():
    with pytest.raises(ModelError, match="racing-lib learn"):
        ModelParams.from_dict({"correction": {"oops": 1}})
    with pytest.raises(ModelError, match="features"):
        ModelParams.from_dict({"correction": {"features": ["v_x"], "gps": [None, None, None]}})
    with pytest.raises(ModelError, match="ModelCorrection"):
        ModelParams(correction="learned")  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def two_laps():
    """Two laps of the main job on the expressway, different seeds (a few seconds)."""
    result = race("expressway", trials=2, seed=7)
    return result.track, [lap.log for lap in result.laps]


def _with_excursion(track, log, s_at: float, size: float):
    """``log`` with its car on its line but for one excursion of ``size`` m near ``s_at``."""
    ey = np.zeros_like(log.ey)
    ey[int(np.argmin(np.abs(np.mod(log.s_track, track.length) - s_at)))] = size
    return dataclasses.replace(log, ey=ey)


def test_the_edge_margin_follows_the_laps_along_the_track(two_laps):
    track, (lap, _) = two_laps
    log = _with_excursion(track, lap, 1000.0, 1.2)
    s, excursion = edge_excursions([log], track)
    where = float(s[np.argmax(excursion > 0)] + EXCURSION_WINDOW)  # the middle of the stretch
    assert abs(where - 1000.0) < 10.0
    assert np.all(excursion[np.abs(s - where) < EXCURSION_WINDOW - 2.0] == 1.2)
    assert np.all(excursion[np.abs(s - where) > EXCURSION_WINDOW + 2.0] == 0.0)
    # the track the next plan is made on with a 0.4 m margin: narrower there on both sides by
    # what the margin leaves of the excursion and the safety, unchanged elsewhere, on the same
    # centerline
    narrowed = planning_track(track, [log], 0.4)
    knots = track.centerline.knots
    for side in ("width_left", "width_right"):
        cut = getattr(track, side)(knots) - getattr(narrowed, side)(knots)
        assert cut.max() == pytest.approx(1.2 + EDGE_SAFETY - 0.4, abs=1e-6)
        far = np.abs(knots - where) > EXCURSION_WINDOW + 5.0
        np.testing.assert_allclose(cut[far], 0.0, atol=1e-9)
    assert narrowed.centerline is track.centerline and narrowed.checksum() != track.checksum()
    # laps that stayed within what the margin leaves: the track itself
    assert planning_track(track, [_with_excursion(track, lap, 1000.0, 0.2)], 0.4) is track
    # the lap is a loop: an excursion just after the line counts just before it
    s, excursion = edge_excursions([_with_excursion(track, lap, 5.0, 0.5)], track)
    assert excursion[-5] == 0.5
    # an excursion wider than the track narrows it only so far that the car and the safety fit
    wide = planning_track(track, [_with_excursion(track, lap, 1000.0, 50.0)], 0.4)
    total = wide.width_left(knots) + wide.width_right(knots)
    from racing_lib.planning.grid import DEFAULT_CAR_WIDTH

    assert total.min() >= DEFAULT_CAR_WIDTH + 2 * 0.4


def test_the_laps_beyond_their_margin_are_measured_where_they_strayed(two_laps):
    track, (lap, _) = two_laps
    on_line = _with_excursion(track, lap, 1000.0, 0.0)
    # on the track itself, the plan's 0.4 m margin: 0.7 m off the line is 0.3 m beyond it,
    # whichever side; a lap on its line is 0.4 m inside it
    assert margin_excess([on_line], track, track, 0.4) == pytest.approx(-0.4)
    assert margin_excess([_with_excursion(track, lap, 1000.0, 0.7)], track, track, 0.4) == (
        pytest.approx(0.3)
    )
    assert margin_excess([_with_excursion(track, lap, 1000.0, -0.7)], track, track, 0.4) == (
        pytest.approx(0.3)
    )
    # the worst lap counts; no margin given: the planner's default on this track
    two = [on_line, _with_excursion(track, lap, 2000.0, 0.5)]
    assert margin_excess(two, track, track, 0.4) == pytest.approx(0.1)
    assert margin_excess(two, track, track, None) == pytest.approx(0.5 - default_margin(track))
    assert margin_excess([], track, track, 0.4) is None
    # only the lap between its line crossings counts (the whole log of one that never crossed)
    outside = _with_excursion(track, lap, 1000.0, 0.0)
    outside.ey[int(np.argmin(lap.in_lap))] = 3.0
    assert not lap.in_lap.all() and margin_excess([outside], track, track, 0.4) == (
        pytest.approx(-0.4)
    )
    never = dataclasses.replace(outside, in_lap=np.zeros_like(lap.in_lap))
    assert margin_excess([never], track, track, 0.4) == pytest.approx(2.6)
    # where the plan was made on a narrowed track, the margin there is wider by the narrowing:
    # the same excursion is within it at that point, and beyond it elsewhere
    narrowed = planning_track(track, [_with_excursion(track, lap, 1000.0, 1.2)], 0.4)
    assert margin_excess([_with_excursion(track, lap, 1000.0, 1.2)], track, narrowed, 0.4) == (
        pytest.approx(-EDGE_SAFETY, abs=1e-3)
    )
    assert margin_excess([_with_excursion(track, lap, 3000.0, 1.2)], track, narrowed, 0.4) == (
        pytest.approx(0.8, abs=1e-6)
    )


def _excess(i: int, driven: float, excess: float | None, clean: bool = True) -> IterationResult:
    return dataclasses.replace(_iteration(i, driven=driven, clean=clean), margin_excess_m=excess)


def test_the_result_is_the_fastest_clean_iteration_that_kept_within_its_margins():
    beyond = _excess(2, 103.5, 0.3)
    within = _excess(3, 103.9, -0.1)
    wall = _excess(4, 103.0, -0.2, clean=False)
    assert beyond.clean and not beyond.within_margins and within.within_margins
    assert _excess(5, 104.0, 0.0).within_margins and not _excess(5, 104.0, 1e-4).within_margins
    assert not wall.within_margins
    run = LearningRun("expressway", None, [_excess(0, 105.0, -0.3), _excess(1, 104.2, -0.2),
                                           beyond, within, wall])  # fmt: skip
    assert run.best() is within
    # not measured (no lap to measure): counted as within
    unmeasured = _excess(6, 103.8, None)
    assert LearningRun("expressway", None, [within, unmeasured]).best() is unmeasured
    # with no clean iteration within its margins, the fastest clean one
    slower_beyond = _excess(7, 103.7, 0.1)
    assert LearningRun("expressway", None, [slower_beyond, beyond, wall]).best() is beyond
    assert LearningRun("expressway", None, [wall]).best() is None
    # the JSON of the command carries it, and the line for people says it
    assert run.to_dict()["iterations"][2]["margin_excess_m"] == 0.3
    assert "0.30 m beyond its edge margins" in _line(beyond)
    assert "beyond" not in _line(within) and "beyond" not in _line(unmeasured)
    # however little beyond, a table does not show it as nothing
    assert beyond_text(0.003) == "< 0.01 m" and beyond_text(0.0) == beyond_text(None) == "-"


def test_learning_improves_the_prediction_of_an_unseen_lap(two_laps):
    track, (seen, unseen) = two_laps
    model = identified_model()
    corr = fit_correction(residual_samples(seen, track, model), seed=0)
    learned = model.replace(params=model.params.replace(correction=corr))
    before = one_step_errors([unseen], track, model)
    after = one_step_errors([unseen], track, learned)
    # Measured: v_x 0.51 -> 0.19 m/s^2, v_y 0.42 -> 0.10 m/s^2, r 0.44 -> 0.06 rad/s^2
    assert after["v_x"] < 0.7 * before["v_x"]
    assert after["v_y"] < 0.5 * before["v_y"]
    assert after["r"] < 0.5 * before["r"]


def test_residuals_are_taken_against_the_model_as_identified(two_laps):
    track, (seen, _) = two_laps
    model = identified_model()
    corrected = model.replace(params=model.params.replace(correction=_correction()))
    a = residual_samples(seen, track, model)
    b = residual_samples(seen, track, corrected)
    assert np.array_equal(a.residuals, b.residuals)
    assert np.all(a.features[:, 0] > 5.0)


def test_broken_logs_are_refused(two_laps):
    track, (seen, _) = two_laps
    cut = Drive(
        *(getattr(seen, k)[:2] for k in ("t", "x", "y", "psi", "vx", "vy", "r", "steer", "pedal"))
    )
    with pytest.raises(ModelError, match="at least 3"):
        residual_samples(cut, track, identified_model())
    cols = {
        k: getattr(seen, k)[:20].copy()
        for k in ("t", "x", "y", "psi", "vx", "vy", "r", "steer", "pedal")
    }
    cols["t"][5] = cols["t"][4]
    with pytest.raises(ModelError, match="time stamps"):
        residual_samples(Drive(**cols), track, identified_model())
    few = residual_samples(seen, track, identified_model())
    with pytest.raises(ModelError, match="too few"):
        fit_correction(ResidualSamples(few.features[:20], few.residuals[:20], few.s[:20]))
    with pytest.raises(ModelError, match="no residual samples"):
        ResidualSamples.concatenate([])
    driving = np.flatnonzero(few.features[:, 3] > 0.0)[:60]
    only_driving = ResidualSamples(few.features[driving], few.residuals[driving], few.s[driving])
    with pytest.raises(ModelError, match="driving slower than 6 m/s"):
        fit_correction(only_driving, below_speed=6.0)


def test_the_correction_leaves_out_driving_near_the_top_speed(two_laps):
    track, (seen, _) = two_laps
    samples = residual_samples(seen, track, identified_model())
    below = float(np.quantile(samples.features[:, 0], 0.8))
    fast, braking = samples.features[:, 0] >= below, samples.features[:, 3] <= 0.0
    assert np.any(fast & braking) and np.any(fast & ~braking)
    keep = ~fast | braking
    kept = ResidualSamples(samples.features[keep], samples.residuals[keep], samples.s[keep])
    cut = fit_correction(samples, inducing=10, below_speed=below)
    assert cut == fit_correction(kept, inducing=10)
    assert cut != fit_correction(samples, inducing=10)


def test_the_best_possible_lap_is_known_for_the_expressway():
    assert known_best_lap(load_track("expressway")) == pytest.approx(102.95, abs=0.01)
    assert known_best_lap(load_track("shortcut")) is None


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"iterations": -1}, "iterations"),
        ({"seeds": 0}, "seeds"),
        ({"edge_margin": -0.1}, "edge"),
        ({"top_speed_band": 0.5}, "top_speed_band"),
        ({"top_speed_band": -0.01}, "top_speed_band"),
    ],
)
def test_bad_learning_settings_are_refused(kwargs, match):
    with pytest.raises(ArgumentError, match=match):
        LearnSettings(**kwargs)


@pytest.mark.slow
def test_the_loop_keeps_and_resumes_its_iterations(tmp_path):
    settings = LearnSettings(iterations=0, seeds=1, inducing=10)
    first = learn("expressway", settings, out=tmp_path)
    assert (tmp_path / "iteration_00" / "summary.json").is_file()
    lines: list[str] = []
    again = learn("expressway", LearnSettings(iterations=1, seeds=1, inducing=10), out=tmp_path,
                  report=lines.append)  # fmt: skip
    assert lines[0].startswith("iteration 0: kept")
    assert again.iterations[0] == first.iterations[0]
    one = again.iterations[1]
    assert one.samples > 500 and one.grip_margin == 0.0
    # fitted on iteration 0's laps but where they drove near the model's top speed
    names_0 = json.loads((tmp_path / "iteration_00" / "summary.json").read_text())["clean_logs"]
    base = identified_model()
    laps_0 = [
        residual_samples(
            LapLog.load(tmp_path / "iteration_00" / name), load_track("expressway"), base
        )
        for name in names_0
    ]
    seen = ResidualSamples.concatenate(laps_0).features
    near_top = (seen[:, 0] >= (1 - LearnSettings().top_speed_band) * base.v_top) & (
        seen[:, 3] > 0.0
    )
    assert near_top.sum() > 100 and one.samples == len(seen) - near_top.sum()
    assert one.prediction_error["learned"]["r"] < one.prediction_error["identified"]["r"]
    assert json.loads(json.dumps(again.to_dict()))["best_possible_lap_s"] == pytest.approx(
        102.95, abs=0.01
    )
    # The main job is what it was: no correction in its model, and its plan, made after a learned
    # one in this process, is iteration 0's to the last digit.
    from racing_lib.planning import plan

    assert identified_model().params.correction is None
    assert plan(load_track("expressway")).lap_time == first.iterations[0].planned_lap_s
    # After a clean learned iteration, the next plan is made on the track narrowed by its laps'
    # tracking errors, which a resumed run rebuilds from the kept laps.
    assert one.clean
    two = learn("expressway", LearnSettings(iterations=2, seeds=1, inducing=10), out=tmp_path)
    track = load_track("expressway")
    assert [t.checksum() for t in two.plan_tracks[:2]] == [track.checksum()] * 2
    names = json.loads((tmp_path / "iteration_01" / "summary.json").read_text())["clean_logs"]
    laps_1 = [LapLog.load(tmp_path / "iteration_01" / name) for name in names]
    assert two.plan_tracks[2].checksum() == planning_track(track, laps_1, 0.4).checksum()
    assert two.models[2].edge_margin == 0.4 <= two.iterations[2].edge_margin
    # Each iteration records how far its laps strayed beyond their margins; a run kept before
    # that was recorded has it measured again from its laps when it resumes.
    summary_path = tmp_path / "iteration_01" / "summary.json"
    summary = json.loads(summary_path.read_text())
    assert summary["result"]["margin_excess_m"] == two.iterations[1].margin_excess_m is not None
    del summary["result"]["margin_excess_m"]
    summary_path.write_text(json.dumps(summary))
    resumed = learn("expressway", LearnSettings(iterations=2, seeds=1, inducing=10), out=tmp_path)
    assert resumed.iterations[1].margin_excess_m == pytest.approx(two.iterations[1].margin_excess_m)
    # A damaged lap that the loop learns from (iteration 0's laps, driven with the blanket
    # margins, are clean) is refused when the run resumes.
    kept = json.loads((tmp_path / "iteration_00" / "summary.json").read_text())["clean_logs"]
    assert kept
    (tmp_path / "iteration_00" / kept[0]).write_bytes(b"not a lap")
    with pytest.raises(ArgumentError, match="delete the folder"):
        learn("expressway", LearnSettings(iterations=1, seeds=1, inducing=10), out=tmp_path)


@pytest.mark.slow
def test_the_loop_is_deterministic_under_its_seed(tmp_path):
    settings = LearnSettings(iterations=1, seeds=1, inducing=10, seed=3)
    kept = learn("expressway", settings, out=tmp_path)
    again = learn("expressway", settings)  # in memory, from scratch
    for a, b in zip(kept.iterations, again.iterations, strict=True):
        assert a.planned_lap_s == b.planned_lap_s
        assert (a.driven_lap_s, a.walls) == (b.driven_lap_s, b.walls)
    assert again.models[1] == kept.models[1]  # the same correction, to the last digit


@pytest.mark.parametrize("argv", [["--iterations", "-1"], ["--seeds", "0"]])
def test_the_learn_command_refuses_bad_numbers(argv, capsys):
    assert main(["learn", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --") and err.count("\n") == 1


def test_an_unknown_car_is_refused_before_anything_is_driven(capsys):
    assert main(["learn", "--car", "no-such-car", "--iterations", "0"]) == 2
    err = capsys.readouterr().err
    assert "unknown car 'no-such-car'" in err and "commonroad:vehicle2" in err


def _iteration(i: int, *, clean: bool = True, caution: float = 1.0, ey_max: float = 0.1,
               driven: float | None = 104.0) -> IterationResult:  # fmt: skip
    return IterationResult(
        iteration=i, planned_lap_s=103.0, driven_lap_s=driven, driven_lap_std_s=0.0,
        gap_to_best_pct=None, walls=0 if clean else 2, offtrack_s=0.0, completed=4, laps=4,
        ey_max_m=ey_max, prediction_error={}, grip_margin=0.0, edge_margin=0.4, caution=caution,
        samples=0,
    )  # fmt: skip


def test_the_margins_follow_what_the_laps_showed():
    # caution: 1 for the first learned iteration; halved after a clean one, down to MIN_CAUTION;
    # doubled after one that touched a wall
    assert _caution(None) == _caution(_iteration(0, clean=False)) == 1.0
    assert _caution(_iteration(1, caution=1.0)) == 0.5
    assert _caution(_iteration(2, caution=MIN_CAUTION)) == MIN_CAUTION
    assert _caution(_iteration(2, clean=False, caution=0.5)) == 1.0
    # the edge margin of a learned model is the settings' (where laps strayed further, the track
    # the plan is made on is narrower: planning_track)
    base, corr, settings = identified_model(), _correction(), LearnSettings(edge_margin=0.4)
    assert _iteration_model(base, None, settings, 1.0) is base
    learned = _iteration_model(base, corr, settings, 1.0)
    assert learned.edge_margin == 0.4 and learned.grip_margin == 0.0
    # the slip margin below the tyres' peak force: the planner's 5 % times the caution
    assert learned.slip_share == pytest.approx(TimeOptimalSettings().slip_force_share)
    assert _iteration_model(base, corr, settings, 0.5).slip_share == pytest.approx(0.975)
    assert slip_share(2.0) == pytest.approx(0.9) and slip_share(64.0) == 0.5
    # the stability margin of a car that diverged under braking: the identified one times the
    # caution; a car without one gets none
    assert learned.lateral_stability is None
    braking = base.replace(lateral_stability=1.8)
    assert _iteration_model(braking, corr, settings, 1.0).lateral_stability == pytest.approx(1.8)
    assert _iteration_model(braking, corr, settings, 0.5).lateral_stability == pytest.approx(0.9)
    assert _iteration_model(braking, None, settings, 0.5).lateral_stability == pytest.approx(1.8)


def test_a_run_reports_its_gain_over_the_identified_model():
    run = LearningRun("expressway", None, [_iteration(0, driven=105.0), _iteration(1),
                                           _iteration(2, driven=None)])  # fmt: skip
    data = json.loads(json.dumps(run.to_dict()))
    assert data["identified_lap_s"] == 105.0
    gains = [it["gain_over_identified_pct"] for it in data["iterations"]]
    assert gains[0] == 0.0 and gains[1] == pytest.approx(100 / 105) and gains[2] is None


def test_a_plan_that_fails_inside_the_loop_says_which_iteration_and_what_to_try(
    monkeypatch, tmp_path
):
    import racing_lib.experiments.learning as learning
    from racing_lib.errors import PlanningError

    def no_plan(*args, **kwargs):
        raise PlanningError("IPOPT returned 'Infeasible_Problem_Detected'")

    monkeypatch.setattr(learning, "plan", no_plan)
    with pytest.raises(PlanningError) as info:
        learn("expressway", LearnSettings(iterations=0, seeds=1), out=tmp_path)
    message = str(info.value)
    assert message.startswith("learning iteration 0 could not plan a lap")
    assert str(tmp_path) in message and "Infeasible_Problem_Detected" in message
