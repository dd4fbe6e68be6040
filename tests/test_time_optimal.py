"""Tests of the minimum-lap-time NLP on a small oval (and one slow run on the expressway)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from racing_lib.errors import PlanningError
from racing_lib.model import ModelOptions, ModelParams, discretize, identified_params
from racing_lib.planning.curvature import solve_curvature
from racing_lib.planning.curvature_settings import CurvatureSettings
from racing_lib.planning.time_optimal import (
    TimeOptimalSettings,
    lap_time_with_model,
    solve_time_optimal,
)
from racing_lib.tracks.segments import Arc, Straight, track_from_segments

SETTINGS = TimeOptimalSettings(spacing=2.5)
PARAMS = ModelParams()
OPTIONS = ModelOptions()


@pytest.fixture(scope="module")
def oval():
    layout = [Straight(200), Arc(50, math.pi), Straight(120), Arc(30, math.pi), Straight(30)]
    return track_from_segments(layout, width=12.0, name="oval", transition=20.0)


@pytest.fixture(scope="module")
def qp(oval):
    return solve_curvature(oval, PARAMS, OPTIONS, CurvatureSettings(spacing=2.5))


@pytest.fixture(scope="module")
def nlp(oval, qp):
    return solve_time_optimal(oval, PARAMS, OPTIONS, SETTINGS, start=qp)


def test_nlp_converges(nlp):
    assert nlp.success, nlp.status
    assert nlp.status == "Solve_Succeeded"
    assert nlp.iterations > 0 and nlp.solve_time > 0
    assert nlp.trajectory is not None and nlp.trajectory.method == "time-optimal"
    assert nlp.trajectory.lap_time == pytest.approx(nlp.lap_time)


def test_nlp_satisfies_the_model_between_nodes(oval, nlp):
    # Re-integrate every interval with the model's own RK4 step (8 sub-steps, inputs linear in s
    # as in the collocation, the centerline's exact curvature) and compare with the next node.
    sol, grid = nlp.solution, nlp.grid
    F = discretize(PARAMS, OPTIONS, None, "rk4", "spatial")
    states = np.vstack([sol["vx"], sol["vy"], sol["r"], sol["epsi"], sol["ey"], grid.s])
    inputs = np.vstack([sol["delta"], sol["ax"]])
    n, sub = grid.n, 8
    errors = np.zeros((5, n))
    for k in range(n):
        k1 = (k + 1) % n
        h = grid.ds[k] / sub
        xi = states[:, k].copy()
        for j in range(sub):
            frac = (j + 0.5) / sub
            u = (1 - frac) * inputs[:, k] + frac * inputs[:, k1]
            s_mid = grid.s[k] + (j + 0.5) * h
            kappa = float(oval.centerline.curvature(s_mid))
            theta = float(oval.grade(s_mid))
            xi = np.asarray(F(xi, u, kappa, theta, h)).ravel()
        errors[:, k] = np.abs(xi[:5] - states[:5, k1])
    # Tolerances per 2.5 m interval: 0.03 m/s on v_x, 0.1 m/s on v_y, 0.03 rad/s on r, 0.01 rad
    # on e_psi, 0.02 m on e_y. Trapezoidal collocation is second order in the node spacing: at 5 m
    # the worst v_y error is about 0.27 m/s (fast lateral modes at corner entry), at 2.5 m 0.05.
    tol = np.array([0.03, 0.1, 0.03, 0.01, 0.02])
    worst = errors.max(axis=1)
    assert np.all(worst < tol), worst


def test_nlp_stays_inside_the_track_and_respects_the_limits(oval, nlp):
    sol, grid = nlp.solution, nlp.grid
    assert np.all(sol["ey"] <= grid.ey_max + 1e-6)
    assert np.all(sol["ey"] >= grid.ey_min - 1e-6)
    half = 0.5 * SETTINGS.car_width
    assert np.all(sol["ey"] + half < oval.width_left(grid.s))
    assert np.all(-sol["ey"] + half < oval.width_right(grid.s))
    xi = np.column_stack([sol["vx"], sol["vy"], sol["r"], sol["epsi"], sol["ey"], grid.s])
    lo, hi = PARAMS.pedal.limits(xi)
    assert np.all(sol["ax"] >= lo - 1e-4) and np.all(sol["ax"] <= hi + 1e-4)
    a_f, a_r = PARAMS.peak_slip_angle()
    from racing_lib.model import Model

    terms = Model(PARAMS, OPTIONS).terms(
        xi, np.column_stack([sol["delta"], sol["ax"]]), grid.kappa, grid.theta
    )
    assert np.all(np.abs(terms["alpha_f"]) <= a_f + 1e-4)
    assert np.all(np.abs(terms["alpha_r"]) <= a_r + 1e-4)


def test_nlp_is_faster_than_the_curvature_plan(qp, nlp):
    # The curvature plan's lap time with the same time formula: its line at its speed profile.
    t_qp = lap_time_with_model(qp.grid, qp.v_x, qp.v_y, qp.e_psi, qp.e_y)
    assert nlp.lap_time < t_qp - 0.2


def test_removing_drag_makes_the_plan_faster(oval, nlp):
    no_drag = solve_time_optimal(oval, PARAMS, ModelOptions(drag=False), SETTINGS, start="cold")
    assert no_drag.success, no_drag.status
    assert no_drag.lap_time < nlp.lap_time - 0.05


def test_cold_start_reaches_the_same_optimum(oval, nlp):
    cold = solve_time_optimal(oval, PARAMS, OPTIONS, SETTINGS, start="cold")
    assert cold.success, cold.status
    assert cold.start == "cold"
    assert cold.lap_time == pytest.approx(nlp.lap_time, abs=0.05)
    assert cold.build_time == 0.0  # the built problem came from the cache


def test_paper_pedal_limit_iteration_agrees_with_exact_limits(oval, nlp):
    # The paper re-evaluates the state-dependent a_x limits on the last solution and re-solves;
    # with an affine pedal map the exact linear constraints must give the same plan.
    settings = TimeOptimalSettings(spacing=2.5, pedal_limits="iterate")
    res = solve_time_optimal(oval, PARAMS, OPTIONS, settings, start="cold")
    assert res.success, res.status
    assert 2 <= res.outer_iterations <= settings.max_outer
    assert len(res.iterations_per_solve) == res.outer_iterations
    assert res.lap_time == pytest.approx(nlp.lap_time, abs=0.05)


@pytest.mark.parametrize("graph", ["sx", "mx"])
def test_casadis_own_derivatives_give_the_same_plan(oval, nlp, graph):
    settings = TimeOptimalSettings(spacing=2.5, graph=graph)
    res = solve_time_optimal(oval, PARAMS, OPTIONS, settings, start="cold")
    assert res.success, res.status
    assert res.lap_time == pytest.approx(nlp.lap_time, abs=0.01)


def test_ipopt_failure_names_the_solver_and_status(oval):
    short = TimeOptimalSettings(spacing=2.5, max_iter=3)
    with pytest.raises(PlanningError) as err:
        solve_time_optimal(oval, PARAMS, OPTIONS, short, start="cold")
    msg = str(err.value)
    assert "IPOPT" in msg and "Maximum_Iterations_Exceeded" in msg
    assert "warm start" in msg
    failed = solve_time_optimal(oval, PARAMS, OPTIONS, short, start="cold", raise_on_failure=False)
    assert not failed.success
    assert failed.status == "Maximum_Iterations_Exceeded"


def test_an_unknown_ipopt_option_is_named_not_blamed_on_the_start(oval):
    settings = TimeOptimalSettings(spacing=2.5, ipopt_options=(("linear_solver", "ma27"),))
    with pytest.raises(PlanningError, match="Invalid_Option") as err:
        solve_time_optimal(oval, PARAMS, OPTIONS, settings, start="cold")
    msg = str(err.value)
    assert "ipopt_options" in msg and "'ma27'" in msg
    assert "warm start" not in msg and "spacing" not in msg  # neither would help


@pytest.mark.parametrize(
    "settings",
    [
        TimeOptimalSettings(spacing=2.5, tol=-1.0),
        TimeOptimalSettings(spacing=2.5, ipopt_options=(("no_such_option", 1),)),
    ],
    ids=["bad-value", "unknown-name"],
)
def test_options_ipopt_refuses_are_one_planning_error(oval, settings):
    # CasADi checks them as it builds the solver, before any iteration.
    with pytest.raises(PlanningError, match="IPOPT refused the options") as err:
        solve_time_optimal(oval, PARAMS, OPTIONS, settings, start="cold")
    assert "check the IPOPT options of the settings" in str(err.value)


def test_compiled_and_interpreted_derivatives_give_the_same_plan_to_the_bit(oval):
    compiled = solve_time_optimal(oval, PARAMS, OPTIONS, SETTINGS, start="cold")
    plain = TimeOptimalSettings(spacing=2.5, jit=False)
    interpreted = solve_time_optimal(oval, PARAMS, OPTIONS, plain, start="cold")
    assert compiled.iterations == interpreted.iterations
    for key, value in compiled.solution.items():
        np.testing.assert_array_equal(value, interpreted.solution[key], err_msg=key)
    # Where the solve's time went: evaluations are a part of it, IPOPT's own work the rest.
    for res in (compiled, interpreted):
        assert 0.0 < res.evaluation_time < res.solve_time


def test_friction_too_low_is_refused_before_solving(oval):
    with pytest.raises(PlanningError, match="friction too low"):
        solve_time_optimal(oval, ModelParams(mu=0.05), OPTIONS, SETTINGS, start="cold")
    # Allowed by mu_min but too slippery for the 30 m hairpin at the planner's minimum speed.
    settings = TimeOptimalSettings(spacing=2.5, mu_min=0.0)
    with pytest.raises(PlanningError, match="friction too low.*corner"):
        solve_time_optimal(oval, ModelParams(mu=0.02), OPTIONS, settings, start="cold")


def test_track_narrower_than_the_car_is_refused():
    layout = [Straight(100), Arc(40, math.pi), Straight(100), Arc(40, math.pi)]
    narrow = track_from_segments(layout, width=2.5, name="lane")
    with pytest.raises(PlanningError, match="too narrow"):
        solve_time_optimal(narrow, PARAMS, OPTIONS, SETTINGS, start="cold")


@pytest.mark.slow
def test_expressway_cold_start():
    from racing_lib.tracks import load_track

    res = solve_time_optimal(load_track("expressway"), identified_params(), start="cold")
    assert res.success, res.status
    assert 85.0 < res.lap_time < 105.0


def test_what_the_plan_asks_of_the_car_against_what_it_has(oval, nlp):
    from racing_lib.planning.demands import plan_demands
    from racing_lib.planning.grid import OPEN_MARGIN

    demands = {d.name: d for d in plan_demands(nlp.trajectory, PARAMS, track=oval)}
    # The plan drives at the limit of the ellipse it was given (the full model here: no margin)
    # and no further, measured from its own motion (first differences on a 2.5 m grid).
    assert 0.9 < demands["tyre use"].share < 1.03
    # Its slip stays below the bound of the NLP (95 % of the peak force), so well below the peak.
    bounds = PARAMS.slip_angle_at(SETTINGS.slip_force_share)
    assert demands["front slip"].peak < math.degrees(bounds[0]) + 0.05
    assert demands["rear slip"].peak < math.degrees(bounds[1]) + 0.05
    assert demands["steering angle"].share < 1.0
    # ModelParams() carries the placeholder pedal map, which has no power limit: the plan asks
    # for more than the engine's 71 kW at the wheels, and the check must say so (the identified
    # map's power limit keeps real plans within it: bench_circuits, chapter 08).
    assert demands["drive power"].share > 1.1
    assert demands["edge clearance"].peak > OPEN_MARGIN - 0.05


def test_demands_of_one_stretch_of_the_plan(oval, nlp):
    from racing_lib.errors import PlanningError
    from racing_lib.planning.demands import plan_demands

    plan_ = nlp.trajectory
    whole = {d.name: d for d in plan_demands(plan_, PARAMS)}
    # A stretch around the node of the largest steering angle holds that node; a stretch that
    # wraps past the line is accepted; each stretch's largest value is no more than the lap's.
    at = whole["steering angle"].s
    near = {d.name: d for d in plan_demands(plan_, PARAMS, where=(at - 30.0, at + 30.0))}
    assert near["steering angle"].peak == whole["steering angle"].peak
    wrapped = plan_demands(plan_, PARAMS, where=(plan_.length - 40.0, 40.0))
    for d in wrapped:
        assert d.s <= 40.0 or d.s >= plan_.length - 40.0
        assert d.peak <= whole[d.name].peak
    lap = plan_demands(plan_, PARAMS, where=(100.0, 100.0 + plan_.length))  # a whole lap
    assert [d.peak for d in lap] == [d.peak for d in whole.values()]
    with pytest.raises(PlanningError, match="no plan node"):
        plan_demands(plan_, PARAMS, where=(10.0, 10.1))


W_DAX = TimeOptimalSettings().w_dax


@pytest.mark.parametrize("drag", [True, False])
def test_at_the_top_speed_the_plan_neither_crabs_nor_flickers(oval, qp, drag):
    # A top speed the oval's long straight reaches. The bound is on the speed, not v_x alone:
    # under a bound on v_x the optimum slid sideways down the straight, counting v_y as progress.
    # And with v_x riding the bound, trapezoidal collocation fixes only pairwise means of a_x:
    # without the a_x regularization the plan's a_x alternated node by node.
    v_top = 27.0  # not the speed row's scale (30 m/s), so a bound left at its default shows
    params = PARAMS if drag else PARAMS.replace(C_xw=0.0, c_rr=0.0)
    st = TimeOptimalSettings(spacing=2.5, v_top=v_top, w_dax=W_DAX)
    res = solve_time_optimal(oval, params, OPTIONS, st, start=qp)
    traj = res.trajectory
    speed = np.hypot(traj.vx, traj.vy)
    assert speed.max() <= v_top * (1 + 1e-6), speed.max()
    top = speed > v_top - 0.05
    assert top.sum() > 20, "the straight should ride the top speed"
    # Where the speed rides its bound, a_x is what holds it there (drag), not a zig-zag about it
    # (the nodes where the car arrives at the bound and leaves it aside).
    runs = np.split(np.flatnonzero(top), np.flatnonzero(np.diff(np.flatnonzero(top)) > 1) + 1)
    for run in runs:
        inner = traj.ax[run[3:-3]]
        if inner.size > 2:
            assert np.max(np.abs(np.diff(inner))) < 0.25, np.round(inner[:12], 2)


#: A car with the same tyres front and rear and a high centre of gravity, like CommonRoad's BMW
#: 320i (its identified values, rounded): braking hard from speed, it oversteers by itself.
_OVERSTEERING = ModelParams(m=1093.3, l_f=1.156, l_r=1.422, h_c=0.614, I_zz=1797.3, C_xw=0.0,
                            c_rr=0.0, mu=1.049, B_f=15.7, C_f=1.4, D_f=0.95, B_r=15.8, C_r=1.2,
                            D_r=1.1)  # fmt: skip


def _nodes(res) -> tuple[np.ndarray, np.ndarray]:
    """A plan's states (N, 6) and inputs (N, 2) at its nodes."""
    sol, grid = res.solution, res.grid
    states = np.column_stack([sol[k] for k in ("vx", "vy", "r", "epsi", "ey")] + [grid.s])
    return states, np.column_stack([sol["delta"], sol["ax"]])


def test_a_car_that_oversteers_under_braking_fails_the_test_there():
    from racing_lib.model import lateral_eigenvalue_test

    test = lateral_eigenvalue_test(_OVERSTEERING, ModelOptions())
    xi = [40.0, 0, 0, 0, 0, 0]
    rolling = [float(x) for x in test(xi, [0.0, 0.0], 0.0, 0.0, 0.0)]
    braking = [float(x) for x in test(xi, [0.0, -6.0], 0.0, 0.0, 0.0)]
    assert rolling[0] > 0.0 and rolling[1] < 0.0  # stable
    assert braking[0] < 0.0  # a real eigenvalue in the right half plane: it diverges


@pytest.mark.slow
def test_a_plan_with_a_stability_margin_keeps_the_lateral_dynamics_stable():
    from racing_lib.tracks import load_track

    track = load_track("shortcut")
    free = solve_time_optimal(track, _OVERSTEERING, ModelOptions(), TimeOptimalSettings())
    st = TimeOptimalSettings(lateral_stability=1.0, steer_rate=0.4)
    bound = solve_time_optimal(track, _OVERSTEERING, ModelOptions(), st)
    assert free.success and bound.success, (free.status, bound.status)
    # Unbounded, the time-optimal plan brakes where the car diverges by itself (up to about
    # 5 1/s for this car); bounded, no real eigenvalue is right of -1 1/s, and all are stable
    # (a slow pair near the tyres' peak in a corner may lie between -1 and 0) ...
    from racing_lib.model import lateral_eigenvalue_test
    from racing_lib.model.lateral import lateral_growth

    assert np.max(lateral_growth(_OVERSTEERING, *_nodes(free))) > 1.0
    states, inputs = _nodes(bound)
    growth = lateral_growth(_OVERSTEERING, states, inputs, theta=bound.grid.theta)
    assert np.max(growth) < 1e-3
    # Both eigenvalues on one side of -1 1/s (the shifted determinant): under braking the
    # diverging one is kept left of it while the other lies far left.
    test = lateral_eigenvalue_test(_OVERSTEERING, ModelOptions()).map(len(states))
    det = np.asarray(test(states.T, inputs.T, bound.grid.kappa, bound.grid.theta, 1.0)[0])
    assert np.min(det) >= -1e-4
    # ... the steering changes no faster than 0.4 rad/s from node to node ...
    sol = bound.solution
    rate = np.abs(np.diff(np.append(sol["delta"], sol["delta"][0]))) / sol["dt"]
    assert np.max(rate) <= 0.4 * (1 + 1e-4)
    # ... and it costs lap time, not much (about 1.5 %).
    assert free.lap_time < bound.lap_time < 1.05 * free.lap_time


@pytest.mark.parametrize(
    "bad",
    [
        {"lateral_stability": -1.0},
        {"lateral_stability": True},
        {"steer_rate": 0.0},
        {"steer_rate": float("nan")},
    ],  # fmt: skip
)
def test_a_stability_or_steering_bound_that_is_no_number_is_refused(bad):
    name = next(iter(bad))
    with pytest.raises(PlanningError, match=f"TimeOptimalSettings.{name} must be a finite"):
        TimeOptimalSettings(**bad)
