"""Tests of the MPC tracking controllers and their QP layer (racing_lib.control.mpc)."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest
from scipy.linalg import expm

from racing_lib.config import fast_mode
from racing_lib.control.mpc import (
    MX,
    CoupledMPC,
    DecoupledMPC,
    MPCSettings,
    augment_steering_lag,
    expm_batch,
    steering_lag_coefficients,
)
from racing_lib.control.mpc.coupled import LEARNED_SLIP_SHARE
from racing_lib.control.mpc.qp_cvxpy import CvxpyTrackingQP
from racing_lib.control.mpc.qp_osqp import TrackingQP
from racing_lib.control.mpc.qp_problem import (
    QPData,
    QPSettings,
    QPShape,
    QPSolution,
    tracking_cost,
)
from racing_lib.control.mpc.settings import COUPLED_SLICE, COUPLED_STATES
from racing_lib.errors import ControlError
from racing_lib.interfaces import (
    Command,
    Controller,
)
from racing_lib.model import NU, NX, CarModel, U, X, discretize

TIGHT = QPSettings(eps_abs=1e-10, eps_rel=1e-10, max_iter=200000, polish=True)


# --------------------------------------------------------------------------------------------------
# QP layer
# --------------------------------------------------------------------------------------------------


def _random_problem(rng, n=5, m=2, N=12, band=True):
    """A well-posed random instance: stable-ish dynamics, a band that binds for some stages."""
    A = np.array([np.eye(n) + 0.05 * rng.standard_normal((n, n)) for _ in range(N)])
    B = 0.1 * rng.standard_normal((N, n, m))
    d = 0.05 * rng.standard_normal((N, n))
    data = QPData(
        x0=rng.standard_normal(n),
        A=A,
        B=B,
        d=d,
        x_ref=rng.standard_normal((N, n)),
        u_prev=0.5 * rng.uniform(-1, 1, m),
        u_min=-np.ones((N, m)),
        u_max=np.ones((N, m)),
        band_min=np.full(N, -0.3) if band else None,
        band_max=np.full(N, 0.3) if band else None,
    )
    shape = QPShape.make(
        n,
        m,
        N,
        state_weights=rng.uniform(0.5, 2.0, n),
        rate_weights=rng.uniform(0.1, 2.0, m),
        input_weights=[0.0] * m,
        band_index=n - 1 if band else None,
        slack_linear=50.0,
        slack_quadratic=100.0,
        rate_limits=[0.3] + [np.inf] * (m - 1),
    )
    return shape, data


@pytest.mark.parametrize("seed", range(4))
def test_fast_qp_matches_cvxpy_on_random_problems(seed):
    rng = np.random.default_rng(seed)
    shape, data = _random_problem(rng, band=seed % 2 == 0)
    fast = TrackingQP(shape, TIGHT).solve(data)
    ref = CvxpyTrackingQP(shape).solve(data)
    assert fast.success and ref.success
    # Same minimizer (the QP is strictly convex in the inputs) to 1e-5, same optimal cost.
    np.testing.assert_allclose(fast.u, ref.u, atol=1e-5)
    np.testing.assert_allclose(fast.x, ref.x, atol=1e-5)
    c_fast = tracking_cost(shape, data, fast.x, fast.u, fast.slack)
    c_ref = tracking_cost(shape, data, ref.x, ref.u, ref.slack)
    assert c_fast == pytest.approx(c_ref, rel=1e-7, abs=1e-8)
    # The hard constraints hold for the fast solution.
    assert np.all(np.abs(np.diff(np.r_[data.u_prev[0], fast.u[:, 0]])) <= 0.3 + 1e-6)
    assert np.all(fast.u <= 1 + 1e-6) and np.all(fast.u >= -1 - 1e-6)
    x_prev = data.x0
    for k in range(shape.horizon):
        x_next = data.A[k] @ x_prev + data.B[k] @ fast.u[k] + data.d[k]
        np.testing.assert_allclose(fast.x[k], x_next, atol=1e-6)
        x_prev = fast.x[k]


@pytest.mark.parametrize(
    "settings",
    [QPSettings(), QPSettings(max_iter=15, rescue=True), QPSettings(max_iter=15, rescue=False)],
    ids=["default", "rescued", "failing"],
)
def test_direct_osqp_calls_give_the_wrappers_numbers_bit_for_bit(settings):
    """A step talks to OSQP's extension object; through the wrapper the answers are the same.

    Also when OSQP runs out of iterations and Clarabel rescues the QP (whose answer then warm-starts
    OSQP), or nothing does (and the next solve starts from zero).
    """
    rng = np.random.default_rng(7)
    shape, _ = _random_problem(rng)
    direct, wrapped = TrackingQP(shape, settings), TrackingQP(shape, settings)
    assert direct._ext is not None  # the fast path is taken with the osqp this project pins
    wrapped._ext = None
    statuses = set()
    for step in range(6):  # warm starts carry over from step to step on both
        _, data = _random_problem(np.random.default_rng(100 + step))
        if step == 3:  # an open side, which OSQP takes as its own infinity
            data = dataclasses.replace(data, band_min=np.full(12, -np.inf))
        a, b = direct.solve(data), wrapped.solve(data)
        statuses.add(a.status)
        assert a.success == b.success and a.status == b.status
        assert a.iterations == b.iterations
        assert np.array_equal(a.objective, b.objective, equal_nan=True)
        for name in ("x", "u", "slack"):
            assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
    assert direct.rescues == wrapped.rescues
    if settings.max_iter == 15:  # the cases meant to fail did
        assert statuses - {"solved"}


def test_the_coupled_states_lead_the_model_state_in_the_mpc_order():
    """The coupled MPC selects its states with a slice: they must be the model's first, in order."""
    assert [X(i).name for i in COUPLED_STATES] == [MX(i).name for i in range(len(COUPLED_STATES))]
    assert np.array_equal(np.arange(NX)[COUPLED_SLICE], COUPLED_STATES)


def test_soft_band_keeps_the_qp_feasible_and_is_exact_when_possible():
    """A car already 2 m outside its band: the QP still solves, paying slack; inside, no slack."""
    n, m, N = 2, 1, 10
    # Double integrator on e_y: x = [e_y, e_y_dot], input = lateral acceleration.
    dt = 0.1
    A = np.tile(np.array([[1.0, dt], [0.0, 1.0]]), (N, 1, 1))
    B = np.tile(np.array([[0.5 * dt**2], [dt]]), (N, 1, 1))
    shape = QPShape.make(n, m, N, [1.0, 0.0], [0.0], band_index=0, slack_linear=1e3)
    qp = TrackingQP(shape, TIGHT)

    def solve(e0):
        return qp.solve(
            QPData(
                x0=np.array([e0, 0.0]), A=A, B=B, d=np.zeros((N, n)),
                x_ref=np.zeros((N, n)), u_prev=np.zeros(m),
                u_min=-np.ones((N, m)), u_max=np.ones((N, m)),
                band_min=np.full(N, -1.0), band_max=np.full(N, 1.0),
            )
        )  # fmt: skip

    outside = solve(3.0)
    assert outside.success
    assert outside.slack[0] > 1.5  # |u| <= 1 cannot bring it back within 0.1 s
    assert np.all(outside.u[:3] < -0.99)  # and it pushes back as hard as it can
    inside = solve(0.5)
    assert inside.success
    assert np.max(inside.slack) < 1e-6


def test_qp_rejects_malformed_data():
    shape, data = _random_problem(np.random.default_rng(0))
    bad = dataclasses.replace(data, A=data.A[:-1])
    with pytest.raises(ControlError, match="QPData.A"):
        TrackingQP(shape).solve(bad)
    with pytest.raises(ControlError, match="state_weights"):
        QPShape.make(2, 1, 5, state_weights=[1.0, 2.0, 3.0], rate_weights=[0.0])


def test_qp_reports_failure_instead_of_raising():
    shape, data = _random_problem(np.random.default_rng(1))
    settings = QPSettings(max_iter=1, check_termination=1, rescue=False)
    sol = TrackingQP(shape, settings).solve(data)
    assert isinstance(sol, QPSolution)
    assert not sol.success
    assert sol.status == "maximum iterations reached"
    assert np.all(np.isnan(sol.u))


@pytest.mark.parametrize("field", ["u_min", "u_max", "band_min", "band_max"])
def test_a_nan_or_crossed_bound_is_a_reported_failure(field):
    # A NaN bound passes a "lower > upper" test (NaN compares false); it must fail as clearly as
    # a crossed one, and the next good instance must solve as if nothing had happened.
    shape, data = _random_problem(np.random.default_rng(2))
    qp, fresh = TrackingQP(shape), TrackingQP(shape)
    bounds = np.array(getattr(data, field), dtype=float)
    bounds.flat[3] = np.nan
    sol = qp.solve(dataclasses.replace(data, **{field: bounds}))
    assert not sol.success and sol.status == "inconsistent bounds (NaN, or lower > upper)"
    assert qp.rescues == 0  # refused before OSQP, not handed to Clarabel
    if field.startswith("u_"):
        crossed = dataclasses.replace(data, u_min=data.u_max + 0.1)
        assert qp.solve(crossed).status == "inconsistent bounds (NaN, or lower > upper)"
    np.testing.assert_array_equal(qp.solve(data).u, fresh.solve(data).u)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_qp_osqp_cannot_finish_is_rescued_by_clarabel(seed):
    # OSQP starved of iterations fails; the interior-point rescue must give the QP's solution,
    # checked against the cvxpy reference (an independent formulation of the same problem).
    shape, data = _random_problem(np.random.default_rng(seed))
    qp = TrackingQP(shape, QPSettings(max_iter=1, check_termination=1))
    sol = qp.solve(data)
    assert sol.success and sol.status == "solved (clarabel)"
    assert qp.rescues == 1
    ref = CvxpyTrackingQP(shape).solve(data)
    np.testing.assert_allclose(sol.u, ref.u, atol=1e-5)
    np.testing.assert_allclose(sol.x, ref.x, atol=1e-5)


# --------------------------------------------------------------------------------------------------
# Discretization and linearization
# --------------------------------------------------------------------------------------------------


def test_zoh_discretization_is_exact_for_the_linearized_model(circle_setup):
    """ZOH of the continuous linearization at an equilibrium-free point: compare with a fine
    integration of the *linear* ODE (the ZOH is exact for it)."""
    plan, params = circle_setup
    mpc = CoupledMPC(plan, CarModel(params), settings=MPCSettings(horizon=2, discretization="zoh"))
    from racing_lib.control.mpc.linearize import continuous_linearization

    xi_bar = np.array([20.0, -0.3, 0.25, 0.02, 0.4, 10.0])
    u_bar = np.array([0.04, 0.5])
    A, B, d = mpc.linearize(
        np.tile(xi_bar, (2, 1)), np.tile(u_bar, (2, 1)), np.zeros(2), np.zeros(2)
    )
    Ac, Bc, c = (np.asarray(v) for v in continuous_linearization(params, mpc.options)(
        xi_bar, u_bar, 0.0, 0.0))  # fmt: skip
    xi = xi_bar + 0.1
    h = 0.1 / 2000
    for _ in range(2000):  # RK4 of the linear ODE, far more accurate than needed
        f = lambda z: Ac @ z + Bc @ u_bar + c.ravel()  # noqa: E731
        k1 = f(xi)
        k2 = f(xi + h / 2 * k1)
        k3 = f(xi + h / 2 * k2)
        k4 = f(xi + h * k3)
        xi = xi + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    np.testing.assert_allclose(A[0] @ (xi_bar + 0.1) + B[0] @ u_bar + d[0], xi, atol=1e-8)


def test_expm_batch_matches_scipy():
    rng = np.random.default_rng(3)
    for scale in (0.01, 1.0, 8.0):
        M = scale * rng.standard_normal((6, 9, 9)) / 3
        E = expm_batch(M)
        for k in range(M.shape[0]):
            np.testing.assert_allclose(E[k], expm(M[k]), rtol=1e-7, atol=1e-9 * scale)


def test_steering_lag_coefficients_are_the_exact_lag():
    tau, dt = 0.08, 0.1
    a, w = steering_lag_coefficients(tau, dt)
    # Step response of delta_dot = (1 - delta) / tau from 0: delta(dt) = 1 - exp(-dt / tau).
    assert 1.0 - a == pytest.approx(1.0 - np.exp(-dt / tau))
    # Mean of 1 - exp(-t / tau) over [0, dt] = 1 - tau / dt (1 - exp(-dt / tau)) = 1 - w.
    t = np.linspace(0.0, dt, 20001)
    assert 1.0 - w == pytest.approx(np.trapezoid(1.0 - np.exp(-t / tau), t) / dt, rel=1e-6)
    assert steering_lag_coefficients(0.0, dt) == (0.0, 0.0)
    # The augmented model feeds the mean angle to the vehicle.
    A = np.zeros((1, 1, 1))
    B = np.ones((1, 1, 2))
    A2, B2, d2 = augment_steering_lag(A, B, np.zeros((1, 1)), 0, tau, dt)
    assert A2[0, 0, 1] == pytest.approx(w) and B2[0, 0, 0] == pytest.approx(1 - w)
    assert A2[0, 1, 1] == pytest.approx(a) and B2[0, 1, 0] == pytest.approx(1 - a)
    assert B2[0, 0, 1] == 1.0 and B2[0, 1, 1] == 0.0 and np.all(d2 == 0)


@pytest.fixture(scope="module")
def circle_setup():
    """A circular plan (radius 80 m, 20 m/s) on a circular track: analytic and fast to build."""
    from racing_lib.model import ModelParams
    from racing_lib.planning.trajectory import Trajectory

    R, v, n = 80.0, 20.0, 200
    phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    x, y = R * np.cos(phi), R * np.sin(phi)
    params = ModelParams()
    kappa = np.full(n, 1.0 / R)
    plan = Trajectory.from_states(
        x, y, vx=np.full(n, v), vy=np.zeros(n), r=np.full(n, v / R), ax=np.full(n, 0.3),
        delta=np.full(n, np.arctan(params.wheelbase / R)), dt=np.full(n, 2 * np.pi * R / n / v),
    )  # fmt: skip
    assert np.allclose(plan.kappa, kappa, rtol=1e-3)
    return plan, params


@pytest.mark.parametrize("substeps", [1, 4])
def test_linearization_is_exact_to_first_order(circle_setup, substeps):
    """One step of the affine model vs. the model's nonlinear step: error O(|perturbation|^2)."""
    plan, params = circle_setup
    st = MPCSettings(horizon=4, substeps=substeps, jit=False)  # no compile time in tests
    mpc = CoupledMPC(plan, CarModel(params), settings=st)
    xi_bar = np.array([20.0, -0.3, 0.25, 0.02, 0.4, 10.0])
    u_bar = np.array([0.04, 0.5])
    kappa, theta = 1.0 / 80.0, 0.01
    N = st.horizon
    A, B, d = mpc.linearize(
        np.tile(xi_bar, (N, 1)), np.tile(u_bar, (N, 1)), np.full(N, kappa), np.full(N, theta)
    )
    # The nonlinear discrete step: the model's RK4, chained as the MPC chains it.
    n_sub = substeps
    step = discretize(params, mpc.options, 0.1 / n_sub, "rk4")

    def flow(xi, u):
        for _ in range(n_sub):
            xi = np.asarray(step(xi, u, kappa, theta)).ravel()
        return xi

    rng = np.random.default_rng(0)
    direction_x = rng.standard_normal(NX) * np.array([1.0, 0.3, 0.1, 0.02, 0.3, 1.0])
    direction_u = rng.standard_normal(NU) * np.array([0.01, 1.0])
    errors = []
    for eps in (0.4, 0.2, 0.1, 0.05):
        xi, u = xi_bar + eps * direction_x, u_bar + eps * direction_u
        exact = flow(xi, u)
        affine = A[0] @ xi + B[0] @ u + d[0]
        errors.append(np.linalg.norm(exact - affine))
    # At the linearization point itself the affine model is exact.
    np.testing.assert_allclose(A[0] @ xi_bar + B[0] @ u_bar + d[0], flow(xi_bar, u_bar), atol=1e-6)
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all(ratios > 3.0) and np.all(ratios < 5.0), (errors, ratios)
    # All stages share the point, so all models are equal (the map really is per stage).
    np.testing.assert_allclose(A[-1], A[0])


def test_heuristic_trajectory_and_reference(circle_setup):
    """Reference spaced by plan time; the heuristic falls linearly from the state to the plan."""
    from racing_lib.interfaces import Observation

    plan, params = circle_setup
    N = 10
    mpc = CoupledMPC(plan, CarModel(params), settings=MPCSettings(horizon=N, jit=False))
    s0 = 100.0
    xi_ref, u_ref, _ = mpc.reference(s0)
    # Constant 20 m/s: stage k is 2 k m further along.
    np.testing.assert_allclose(np.diff(xi_ref[:, X.S]), 20.0 * 0.1, rtol=1e-6)
    np.testing.assert_allclose(xi_ref[:, X.VX], 20.0)
    assert np.all(xi_ref[:, X.EY] == 0.0)
    # The plan table's columns are copied by slices: each lands in its own state and input.
    from racing_lib.control.mpc.base import PlanTable

    states = [PlanTable.VX, PlanTable.VY, PlanTable.R, PlanTable.EPSI]
    assert list(range(NX))[PlanTable.STATES] == states == [X.VX, X.VY, X.R, X.EPSI]
    assert list(range(10))[PlanTable.INPUTS] == [PlanTable.DELTA, PlanTable.AX]
    assert [U.DELTA, U.AX] == [0, 1]
    rows = mpc._plan.at_s(xi_ref[:, X.S])
    for col, name in ((PlanTable.VX, "VX"), (PlanTable.VY, "VY"), (PlanTable.R, "R"),
                      (PlanTable.EPSI, "EPSI")):  # fmt: skip
        np.testing.assert_array_equal(xi_ref[:, X[name]], rows[:, col])
    np.testing.assert_array_equal(u_ref[:, U.DELTA], rows[:, PlanTable.DELTA])
    np.testing.assert_array_equal(u_ref[:, U.AX], rows[:, PlanTable.AX])
    # The car 1 m left of the plan, heading along it.
    x, y, psi = plan.path.to_cartesian(s0, 1.0, 0.0)
    obs = Observation(0.0, float(x), float(y), float(psi), 20.0, 0.0, 0.25)
    mpc.reset(obs)
    xi0 = mpc.current_state(obs)
    assert xi0[X.EY] == pytest.approx(1.0, abs=1e-6)
    assert xi0[X.S] == pytest.approx(s0, abs=1e-4)
    assert xi0[X.EPSI] == pytest.approx(0.0, abs=1e-6)
    lam = mpc.blend_weights
    np.testing.assert_allclose(lam, 1.0 - np.arange(N + 1) / N)
    xi_hat = mpc.heuristic_trajectory(xi0, xi_ref)
    np.testing.assert_allclose(xi_hat[0], xi0)  # starts at the car
    np.testing.assert_allclose(xi_hat[-1], xi_ref[-1])  # ends on the plan
    assert xi_hat[N // 2, X.EY] == pytest.approx(0.5 * xi0[X.EY])  # halfway, half the offset
    off = CoupledMPC(
        plan, CarModel(params), settings=MPCSettings(horizon=N, smooth_transition=False, jit=False)
    )
    assert np.all(off.blend_weights == 0.0)
    np.testing.assert_allclose(off.heuristic_trajectory(xi0, xi_ref), xi_ref)


def test_the_plan_table_interpolates_periodically_and_at_the_seam(circle_setup):
    """Rows at the nodes are the nodes; s wraps; a round-off below 0 or at the length is row 0."""
    from racing_lib.control.mpc.base import PlanTable

    plan, _ = circle_setup
    n = len(plan.s)
    varied = np.linspace(0.0, 1.0, n)  # a column that changes from node to node
    table = PlanTable(plan, theta=varied, band_min=-varied, band_max=varied + 1.0)
    L = table.length
    rows = table.at_s(np.asarray(plan.s, dtype=float))
    np.testing.assert_array_equal(rows[:, PlanTable.THETA], varied)
    np.testing.assert_allclose(table.at_s(np.asarray(plan.s) + 3 * L), rows, atol=1e-9)
    # Halfway between the last node and the seam: halfway back to row 0.
    mid = 0.5 * (plan.s[-1] + L)
    assert table.at_s(np.array([mid]))[0, PlanTable.THETA] == pytest.approx(0.5, abs=1e-12)
    # -1e-17 mod L is L exactly in floating point: still row 0, never an index past the table.
    edge = table.at_s(np.array([-1e-17, L, -L]))
    np.testing.assert_allclose(edge[:, PlanTable.THETA], 0.0, atol=1e-12)
    np.testing.assert_allclose(edge[:, PlanTable.BMAX], 1.0, atol=1e-12)


# --------------------------------------------------------------------------------------------------
# Controllers in closed loop
# --------------------------------------------------------------------------------------------------


def _plan(track, params):
    """A drivable reference: the centerline at its speed profile with some grip in reserve.

    The time-optimal plan is planned at the identified model's limit, which the simulated car
    cannot quite reach (see the MPC chapter); the tests check the controller, not the plan.
    """
    from racing_lib.planning.trajectory import Trajectory

    # Planned with mu = 1.0, and labelled so: the model it carries keeps that share of grip
    # in reserve, and an MPC predicting with the full parameters agrees with it.
    reserve = CarModel(params, grip_margin=1.0 - 1.0 / params.mu)
    return Trajectory.from_centerline(track, params.replace(mu=1.0)).with_model(reserve)


@pytest.fixture(scope="module")
def setups():
    from racing_lib.model.identified import identified_params
    from racing_lib.tracks import load_track

    params = identified_params()
    out = {}
    for name in ("expressway", "shortcut"):
        track = load_track(name)
        out[name] = (track, _plan(track, params), params)
    return out


def _car(track, plan):
    from racing_lib.sim import SimulatedCar

    return SimulatedCar(track, start_s=track.length - 60.0, start_speed=float(plan.vx[-1]))


# The per-seed test drives three seeded laps per track in fast mode (the default of the test
# suite) and ten in full mode; the paper's main experiment below always drives ten, as the paper
# does: a property of ten laps, never the fate of one.
LAP_SEEDS = list(range(3)) if fast_mode() else list(range(10))
TEN_SEEDS = list(range(10))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["expressway", "shortcut"])
@pytest.mark.parametrize("seed", LAP_SEEDS)
def test_coupled_mpc_completes_laps_without_contact(setups, name, seed):
    from racing_lib.experiments.lap import run_lap

    track, plan, params = setups[name]
    mpc = CoupledMPC(plan, CarModel(params), track=track)
    assert isinstance(mpc, Controller)
    res = run_lap(_car(track, plan), mpc, plan, track=track, seed=seed)
    m = res.metrics
    assert m.completed
    assert m.wall_contacts == 0
    assert m.offtrack_time_s == 0.0
    assert m.ey_mae_m < 0.3
    # The car is slower than the plan on the straights (its engine cannot deliver the pedal
    # map's full-throttle acceleration at high speed), never faster.
    assert plan.planned_lap_time - 1.0 < m.lap_time_s < 1.08 * plan.planned_lap_time
    assert m.controller_stats["fallback_brake"] == 0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["expressway", "shortcut"])
def test_tuned_coupled_mpc_laps_the_time_optimal_plan_without_contact(name):
    """The paper's main experiment on both tracks: the plan at the model's limit, tuned weights."""
    from racing_lib.experiments.pipeline import race

    result = race(name, method="time-optimal", controller="coupled-mpc", trials=len(TEN_SEEDS))
    assert result.weights_source == "tuned for 'main'"
    metrics = [lap.metrics for lap in result.laps]
    # At most one lap in ten may go wrong; the others are clean and close to the plan.
    clean = [m for m in metrics if m.completed and m.wall_contacts == 0 and m.offtrack_time_s == 0]
    assert len(clean) >= len(metrics) - len(metrics) // 10
    limit = 1.03 if name == "expressway" else 1.05
    for m in clean:
        assert m.lap_time_s < limit * result.planned_lap_time, f"seed {m.seed}"
        assert m.controller_stats["qp_failures"] <= 3, f"seed {m.seed}"
    # Measured (full mode, ten seeds): see the closing numbers of chapter 05 and bench_circuits.
    assert 0.0 < result.lap_time_gap < (2.0 if name == "expressway" else 4.0)


def test_forced_qp_failures_fall_back_and_are_counted(setups, monkeypatch, caplog):
    """Every QP from step 5 fails: N-1 shifted inputs of the last plan, then safe braking."""
    track, plan, params = setups["shortcut"]
    N = 8
    mpc = CoupledMPC(plan, CarModel(params), track=track, settings=MPCSettings(horizon=N))
    car = _car(track, plan)
    obs = car.reset(seed=0)
    mpc.reset(obs)
    real_solve = mpc.qp.solve
    calls = {"n": 0}

    def flaky(data):
        calls["n"] += 1
        if calls["n"] > 5:
            return QPSolution(False, "primal infeasible", np.full((N, 6), np.nan),
                              np.full((N, 2), np.nan), np.full(N, np.nan))  # fmt: skip
        return real_solve(data)

    monkeypatch.setattr(mpc.qp, "solve", flaky)
    cmds = []
    with caplog.at_level("WARNING", logger="racing_lib.control.mpc"):
        for _ in range(5 + 20):
            cmd = mpc.step(obs)
            assert isinstance(cmd, Command)
            assert np.isfinite(cmd.steer) and np.isfinite(cmd.pedal)
            cmds.append(cmd)
            obs = car.step(cmd.steer, cmd.pedal)
    stats = mpc.stats()
    assert stats == {
        "qp_failures": 20.0,
        "fallback_shifted": N - 1.0,
        "fallback_brake": 13.0,
        "qp_rescues": 0.0,
    }
    assert all(c.pedal == MPCSettings().brake_pedal for c in cmds[5 + N - 1 :])
    assert any("primal infeasible" in r.getMessage() for r in caplog.records)
    assert mpc.failure_statuses() == {"primal infeasible": 20}
    # reset clears the counters for the next lap
    mpc.reset(obs)
    assert mpc.stats()["qp_failures"] == 0


def test_lap_goes_on_with_a_solver_that_fails_now_and_then(setups):
    """max_iter = 1 now and then: the lap still progresses and the failures are reported."""
    from racing_lib.experiments.lap import run_lap

    track, plan, params = setups["shortcut"]
    mpc = CoupledMPC(plan, CarModel(params), track=track)
    real_solve = mpc.qp.solve
    starved = TrackingQP(mpc.qp.shape, QPSettings(max_iter=1, rescue=False, check_termination=1))
    count = {"n": 0}

    def sometimes_starved(data):
        count["n"] += 1
        return starved.solve(data) if count["n"] % 7 == 0 else real_solve(data)

    mpc.qp.solve = sometimes_starved
    res = run_lap(_car(track, plan), mpc, plan, track=track, seed=0, max_time=25.0)
    stats = res.metrics.controller_stats
    assert stats["qp_failures"] >= 25 * 10 // 7 - 1
    assert stats["fallback_shifted"] == stats["qp_failures"]
    travelled = np.sum(np.hypot(np.diff(res.log.x), np.diff(res.log.y)))
    assert travelled > 400.0
    assert res.metrics.wall_contacts == 0


def test_decoupled_mpc_drives(setups):
    from racing_lib.experiments.lap import run_lap

    track, plan, params = setups["shortcut"]
    mpc = DecoupledMPC(plan, CarModel(params), track=track)
    assert isinstance(mpc, Controller)
    res = run_lap(_car(track, plan), mpc, plan, track=track, seed=0, max_time=20.0)
    travelled = np.sum(np.hypot(np.diff(res.log.x), np.diff(res.log.y)))
    assert travelled > 400.0
    assert np.mean(np.abs(res.log.ey)) < 0.5
    assert res.metrics.controller_stats["fallback_brake"] == 0


def test_band_comes_from_the_track_edges(setups):
    track, plan, params = setups["expressway"]
    st = MPCSettings(margin=0.4)
    mpc = CoupledMPC(plan, CarModel(params), track=track, settings=st)
    table = mpc._plan.table[:-1]
    s_c, e_c, _ = track.centerline.to_frenet(plan.x, plan.y)
    inset = 0.5 * st.car_width + st.margin
    # The centerline plan lies on the centerline: the band is the widths minus the inset.
    np.testing.assert_allclose(table[:, 9], track.width_left(s_c) - e_c - inset, atol=1e-6)
    np.testing.assert_allclose(table[:, 8], -(track.width_right(s_c) + e_c - inset), atol=1e-6)


def test_settings_are_checked():
    with pytest.raises(ControlError, match="horizon"):
        MPCSettings(horizon=1)
    with pytest.raises(ControlError, match="brake_pedal"):
        MPCSettings(brake_pedal=0.5)
    with pytest.raises(ControlError, match="discretization"):
        MPCSettings(discretization="magic")
    with pytest.raises(ControlError, match="substeps"):
        MPCSettings(substeps=0)
    assert MX.EY == 4 and U.DELTA == 0


def _random_stages(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """States (n, 6), inputs (n, 2), curvatures and pitches (n,) of n stages, seeded."""
    rng = np.random.default_rng(5)
    xi = np.column_stack(
        [rng.uniform(5, 50, n), rng.normal(0, 0.5, n), rng.normal(0, 0.3, n),
         rng.normal(0, 0.05, n), rng.normal(0, 1, n), rng.uniform(0, 1000, n)]
    )  # fmt: skip
    u = np.column_stack([rng.normal(0, 0.05, n), rng.normal(0, 3, n)])
    return xi, u, rng.normal(0, 0.02, n), rng.normal(0, 0.02, n)


def test_compiled_linearization_equals_the_interpreted_one(setups):
    track, plan, params = setups["shortcut"]
    N = 25
    fast = CoupledMPC(plan, CarModel(params), settings=MPCSettings(horizon=N, jit=True))
    slow = CoupledMPC(plan, CarModel(params), settings=MPCSettings(horizon=N, jit=False))
    xi, u, kappa, theta = _random_stages(N)
    compiled = fast.linearize(xi, u, kappa, theta)
    interpreted = slow.linearize(xi, u, kappa, theta)
    for a, b in zip(compiled, interpreted, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)


def test_one_build_is_shared_by_processes_and_the_cache_stays_small(tmp_path):
    """Every process (test run, kernel, tuning worker) reuses one build; nothing piles up."""
    import stat
    import subprocess
    import sys

    from racing_lib import jit

    code = (
        "import os\n"
        "from racing_lib.control.mpc.linearize import substep_linearization\n"
        "from racing_lib.jit import cache_dir\n"
        "from racing_lib.model import ModelOptions\n"
        "from racing_lib.model import identified_params\n"
        "substep_linearization(identified_params(), ModelOptions(), 0.1, 2, jit=True)\n"
        "print(cache_dir(), sorted(os.listdir(cache_dir())))\n"
    )
    work = tmp_path / "work"
    work.mkdir()
    # A private temporary folder: another run of the tests on this machine shares the real one.
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    runs = [
        subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            check=True,
            cwd=work,
            env=env,
        ).stdout.split(" ", 1)
        for _ in range(2)
    ]
    assert runs[0] == runs[1], runs  # same folder, same files: the second process built nothing
    path, listing = runs[0][0], eval(runs[0][1])  # noqa: S307 - our own printed list
    info = os.lstat(path)
    assert stat.S_ISDIR(info.st_mode) and info.st_mode & 0o077 == 0
    assert all(name.endswith(".so") for name in listing), listing  # no sources left behind
    assert len(listing) <= jit.MAX_BUILDS
    assert not list(work.iterdir())  # nothing written in the working directory


def test_the_build_cache_keeps_only_the_newest_builds(tmp_path):
    from racing_lib import jit

    def build(name: str, k: int) -> str:
        path = tmp_path / f"{name}_{k:016x}.so"  # a build: the name, a 16-digit hash
        path.write_bytes(b"")
        os.utime(path, (1000 + k, 1000 + k))
        return path.name

    olds = [build("old", k) for k in range(jit.MAX_BUILDS + 3)]
    other = build("old_other", 0)  # another name that starts like it, and older than all
    jit._prune(tmp_path, "old", keep=tmp_path / olds[0])
    left = sorted(p.name for p in tmp_path.iterdir())
    assert olds[0] in left  # the one in use stays
    assert olds[-1] in left and olds[1] not in left
    assert len([name for name in left if name in olds]) == jit.MAX_BUILDS + 1
    assert other in left  # not one of "old"'s builds


def test_a_damaged_build_falls_back_to_the_interpreter(tmp_path, monkeypatch, caplog):
    import casadi as ca

    from racing_lib import jit

    x = ca.SX.sym("x", 2)
    fn = ca.Function("racing_lib_test_fn", [x], [ca.sin(x) * 2.0])
    good, bad = tmp_path / "good", tmp_path / "bad"
    good.mkdir()
    bad.mkdir()
    monkeypatch.setattr(jit, "cache_dir", lambda: str(good))
    compiled = jit.compile_function(fn)
    assert compiled is not None
    np.testing.assert_allclose(np.asarray(compiled([0.3, 0.4])).ravel(), 2 * np.sin([0.3, 0.4]))
    # The same build's name in another folder, holding something that is no library (never
    # overwrite a loaded library in place: the process maps it).
    (build,) = good.glob("racing_lib_test_fn_*.so")
    (bad / build.name).write_bytes(b"not a shared library")
    monkeypatch.setattr(jit, "cache_dir", lambda: str(bad))
    with caplog.at_level("WARNING"):
        assert jit.compile_function(fn) is None  # refused to load: the caller interprets
    assert "failed" in caplog.text


@pytest.mark.skipif(os.name != "posix", reason="elsewhere no compiler is tried at all")
def test_without_a_compiler_the_mpc_interprets_with_one_warning_that_says_why(monkeypatch, caplog):
    from racing_lib.control.mpc.linearize import _substep_linearization, substep_linearization
    from racing_lib.model import ModelOptions, ModelParams

    monkeypatch.setenv("CC", "/no/such/dir/cc")
    caches = (substep_linearization, _substep_linearization)  # the binding, and the build
    for cache in caches:
        cache.cache_clear()  # built here, not taken from an earlier test
    try:
        with caplog.at_level("WARNING"):
            lin = substep_linearization(ModelParams(), ModelOptions(), 0.1, 2, jit=True)
    finally:
        for cache in caches:
            cache.cache_clear()  # nor left for a later one
    assert lin.class_name() == "SXFunction"
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1, warnings
    assert "/no/such/dir/cc" in warnings[0] and "MPCSettings(jit=False)" in warnings[0]


def test_the_packed_linearization_is_the_mapped_one():
    from racing_lib.control.mpc.linearize import (
        packed_map,
        substep_linearization,
        unpack_linearization,
    )
    from racing_lib.model import ModelOptions, ModelParams

    n = 7
    lin = substep_linearization(ModelParams(), ModelOptions(), 0.1, 2, jit=False)
    xi, u, kappa, theta = _random_stages(n)
    A, B, d = lin.map(n)(xi.T, u.T, kappa[None, :], theta[None, :])
    packed = packed_map(lin, n)(np.vstack([xi.T, u.T, kappa[None, :], theta[None, :]]))
    A_p, B_p, d_p = unpack_linearization(packed, n)
    np.testing.assert_array_equal(A_p, np.asarray(A).reshape(NX, n, NX).transpose(1, 0, 2))
    np.testing.assert_array_equal(B_p, np.asarray(B).reshape(NX, n, NU).transpose(1, 0, 2))
    np.testing.assert_array_equal(d_p, np.asarray(d).T)


def test_a_buffered_function_evaluates_in_place_and_refuses_sparse_outputs():
    import casadi as ca

    from racing_lib.jit import BufferedFunction

    x = ca.SX.sym("x", 2, 3)
    fn = BufferedFunction(ca.Function("f", [x], [ca.densify(2.0 * x.T)]))
    fn.inputs[0][:] = np.arange(6.0)  # column-major: x = [[0, 2, 4], [1, 3, 5]]
    (out,) = fn()
    np.testing.assert_array_equal(out, [0.0, 4.0, 8.0, 2.0, 6.0, 10.0])  # 2 x^T, column-major
    fn.inputs[0][:] = 1.0
    assert fn()[0] is out and np.all(out == 2.0)  # the same array, overwritten
    with pytest.raises(ValueError, match="densify"):
        BufferedFunction(ca.Function("g", [x], [ca.SX(ca.Sparsity.diag(2))]))


def test_the_controllers_linearization_matches_the_packed_call(circle_setup):
    # The controller fills the buffer row by row (stages); a wrong order would scramble A, B, d.
    from racing_lib.control.mpc.linearize import unpack_linearization

    plan, params = circle_setup
    n = 6
    ctrl = CoupledMPC(plan, CarModel(params), settings=MPCSettings(horizon=n, jit=False))
    assert ctrl.settings.discretization != "zoh"  # else A, B, d are transformed after the call
    xi, u, kappa, theta = _random_stages(n)
    A, B, d = ctrl.linearize(xi, u, kappa, theta)
    direct = ctrl._lin_map.fn(np.vstack([xi.T, u.T, kappa[None, :], theta[None, :]]))
    A_p, B_p, d_p = unpack_linearization(direct, n)
    np.testing.assert_array_equal(A, A_p)
    np.testing.assert_array_equal(B, B_p)
    np.testing.assert_array_equal(d, d_p)
    A2, _, _ = ctrl.linearize(xi + 0.1, u, kappa, theta)
    assert not np.array_equal(A, A2)
    np.testing.assert_array_equal(A, A_p)  # the first result is a copy, not the reused buffer


def test_the_brake_is_not_cut_by_a_yaw_wobble_the_line_does_not_need():
    n = 6
    xi_ref = np.zeros((n + 1, NX))
    xi_ref[:, X.VX] = 40.0
    xi_hat = xi_ref.copy()
    xi_hat[:, X.R] = 0.3  # a wobble under braking on a straight: 12 m/s^2 of v_x r
    reserved = CoupledMPC.reserved_lateral_acceleration(xi_hat, xi_ref)
    assert reserved.shape == (n,) and np.all(reserved == 0.0)
    # In a corner of the line (radius 200 m) the car needs v^2 / R; faster than the plan, more.
    xi_ref[:, X.R] = 40.0 / 200.0
    xi_hat[:, X.VX], xi_hat[:, X.R] = 44.0, 44.0 / 200.0
    assert np.allclose(CoupledMPC.reserved_lateral_acceleration(xi_hat, xi_ref), 44.0**2 / 200.0)
    # A car that turns less than the line (understeering) keeps what it uses.
    xi_hat[:, X.R] = 0.1
    assert np.allclose(CoupledMPC.reserved_lateral_acceleration(xi_hat, xi_ref), 4.4)


def test_with_a_learned_model_the_mpc_keeps_the_front_tyres_below_their_peak(circle_setup):
    from racing_lib.model import ModelCorrection
    from racing_lib.model.gp import fit_sparse_gp

    plan, params = circle_setup
    st = MPCSettings(horizon=8, jit=False)
    assert CoupledMPC(plan, CarModel(params), settings=st).front_slip_limit is None
    rng = np.random.default_rng(0)
    z = np.column_stack(
        [rng.uniform(10, 30, 60), rng.normal(0, 0.03, (60, 2)), rng.normal(0, 2, 60)]
    )
    gps = [fit_sparse_gp(z, 0.1 * z[:, 1 + k % 2], inducing=6) for k in range(3)]
    learned = params.replace(correction=ModelCorrection(gps, label="test"))
    mpc = CoupledMPC(plan, CarModel(learned), settings=st)
    limit = mpc.front_slip_limit
    assert 0.0 < limit < params.peak_slip_angle()[0]
    assert limit == params.slip_angle_at(LEARNED_SLIP_SHARE)[0]
    # a model with a slip margin of its own (the learning loop's) is held to that one
    closer = CoupledMPC(plan, CarModel(learned, slip_share=0.975), settings=st)
    assert closer.front_slip_limit == params.slip_angle_at(0.975)[0] > limit
    xi_hat = np.zeros((8, 6))
    xi_hat[:, X.VX], xi_hat[:, X.VY], xi_hat[:, X.R] = 20.0, -1.0, 0.25
    heading = (-1.0 + params.l_f * 0.25) / 20.0  # (v_y + l_f r) / v_x: alpha_f = delta - heading
    mpc._u_prev[:] = [heading, 0.0]  # the last command inside the bounds: nothing to widen
    lower, upper = mpc.steering_within_slip(xi_hat)
    np.testing.assert_allclose(lower, heading - limit)
    np.testing.assert_allclose(upper, heading + limit)
    # A last command far outside: each stage keeps what the steering rate limit can reach
    mpc._u_prev[0] = heading + limit + 0.5
    lower, upper = mpc.steering_within_slip(xi_hat)
    rate = mpc.qp_shape.rate_limits[U.DELTA]
    reach = mpc._u_prev[0] - rate * np.arange(1, 9)
    np.testing.assert_allclose(
        upper, np.minimum(np.maximum(heading + limit, reach), mpc.model.steer_max)
    )
    assert np.all(lower <= upper)
