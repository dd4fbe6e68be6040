"""Stage one of the two-stage planner: the iterated curvature-optimal QP (taught in notebook 03).

The paper (Section "Minimum Curvature Trajectory Optimization") approximates the lap time by the
curvature of the line, kappa ~ r / v_x, and minimizes it subject to the vehicle dynamics linearized
around the previous solution, with the speed v_x replaced by a fixed estimate v_hat so that the
objective is quadratic. Each iteration:

1. linearize the spatial-domain model of :mod:`racing_lib.model` (its exact Jacobians,
   :func:`racing_lib.model.jacobians` with ``domain="spatial"``) at steady cornering on the current
   line at the speed v_hat;
2. solve the QP below (cvxpy; Clarabel by default, OSQP on request);
3. rebuild the line from the new lateral offsets e_y, compute its curvature and its quasi-steady
   speed profile (:func:`racing_lib.planning.speed.speed_profile`): that gives the next v_hat;

until the line stops moving (max |Delta e_y| < ``tol``: 'converged') or its lap time stops
improving (``patience`` iterations: 'settled'). It starts from the centerline and returns the
fastest line found.

The QP, on N nodes of the centerline (periodic, a flying lap)::

    min  sum_k  (L r_k / v_hat_k)^2 + w_1 (v_y,k / v_hat_k)^2 + w_2 (delta_k - delta_{k-1})^2
                + w_prox (e_y,k - e_y,k^prev)^2
    s.t. xi_{k+1} - xi_k = ds_k / 2 (f_k + f_{k+1}),  f_k = A_k xi_k + B_k delta_k + c_k
         e_y,min,k <= e_y,k <= e_y,max,k      (track width minus half the car and a margin)
         |delta_k| <= delta_max

with the lateral state xi = (v_y, r, e_psi, e_y). What made it converge where the paper's weights
taken literally in SI units did not (measured on racetrack-database circuits while this planner
was built):

* **Dimensionless terms.** The curvature r / v_hat (1/m) is multiplied by the wheelbase L, which
  turns it into the kinematic steering angle of the line (rad); the lateral velocity enters as the
  side-slip angle v_y / v_hat (rad); the steering change is in rad. All terms are squared angles,
  so the weights are dimensionless and comparable, and the paper's w_1 = 0.015 and w_2 = 0.01 work
  as they are (defaults). In SI units the v_y^2 term (m^2/s^2) is about 1e4 times larger than
  (r / v)^2 (1/m^2) for the same motion and swamps it. Measured (3 m grid): w_1 = 0.015 gave
  98.6 s on the expressway and 72.0 s on Norisring, w_1 = 0.3 gave 99.8 s and 72.1 s.
* **v_x prescribed at a fraction of the speed profile.** v_x is not a decision variable: it is
  fixed to v_hat = ``speed_fraction`` (0.9) times the speed profile of the current line. Near
  100 % the tyres sit at the peak of their force curve in every corner, where the linearized
  lateral dynamics lose their cornering stiffness: with 1.0 the first QP on the expressway failed
  in Clarabel and Norisring ended 0.7 s slower. The final line is driven at its full profile.
* **Linearization at steady cornering** (:func:`steady_cornering`), not at the kinematic guess
  (v_y = 0, delta = L kappa): the kinematic guess puts hairpins past the tyre peak, where the
  linearized dynamics are unstable (an eigenvalue of +35 per metre on Norisring) and the QP
  infeasible.
* **Trapezoidal discretization** of the linearized dynamics: an explicit RK4 step of 3-5 m is
  unstable at hairpin speeds (the lateral dynamics decay over about 1 m there); the trapezoidal
  rule is A-stable and matches the NLP's collocation.
* **Damping**: v_hat is under-relaxed (``relaxation``) and, after ``full_steps``, the line moves
  only ``line_step`` of the way to each new QP solution; without it the line swung by 1-2 m
  between iterations on Brands Hatch and the expressway.

The fixed-point iteration is not a descent method on the lap time: on the expressway the
speed-profile lap time drops from 108.7 s (centerline) to 100.1 s in two QPs and then creeps back
up by about 1 s over 20 more iterations as the line wanders in a long constant-radius corner;
hence the 'settled' rule and returning the fastest line.

The constraint matrices change with every linearization, so the problem is rebuilt for each
iteration from sparse matrices in one vectorized constraint (cvxpy compiles it in tens of ms);
cvxpy Parameters would need dense per-node matrices.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from enum import IntEnum
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from racing_lib.errors import PlanningError
from racing_lib.geometry import Track
from racing_lib.model import X, jacobians, spatial_dynamics
from racing_lib.model.car_model import CarModel
from racing_lib.model.params import ModelOptions, PedalMap
from racing_lib.planning.curvature_settings import CurvatureResult, CurvatureSettings
from racing_lib.planning.grid import TrackGrid
from racing_lib.planning.speed import AccelLimits, SpeedProfile, segment_times, speed_profile
from racing_lib.planning.trajectory import Trajectory, model_inputs

if TYPE_CHECKING:
    import casadi as ca

    from racing_lib.model.params import ModelParams


def steady_cornering(
    v: np.ndarray, kappa: np.ndarray, params: ModelParams, max_use: float = 0.98
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lateral velocity, yaw rate and steering of steady cornering at speed v on curvature kappa.

    Each axle carries its static share of the lateral acceleration v^2 kappa; the slip angle that
    gives it is found by inverting the simplified Pacejka curve (tyre force proportional to load),
    then v_y and delta follow from the slip-angle definitions of the model. Used as the
    linearization point of the QP and as the initial guess of the NLP; not a model of its own.

    Parameters
    ----------
    v : ndarray
        Speed, m/s.
    kappa : ndarray
        Curvature of the line, 1/m.
    params : ModelParams
        Mass geometry and Pacejka factors.
    max_use : float
        Friction use is capped at this fraction of the tyre peak (beyond it there is no solution).

    Returns
    -------
    v_y (m/s), r (rad/s), delta (rad) : ndarray
    """
    v = np.asarray(v, float)
    kappa = np.asarray(kappa, float)
    r = v * kappa
    a_y = v * v * kappa
    g = float(getattr(params, "g", 9.81))

    def slip(B: float, C: float, D: float) -> np.ndarray:
        use = np.clip(a_y / (g * params.mu * D), -max_use, max_use)
        return np.tan(np.arcsin(use) / C) / B

    alpha_f = slip(params.B_f, params.C_f, params.D_f)
    alpha_r = slip(params.B_r, params.C_r, params.D_r)
    v_safe = np.maximum(v, 1.0)
    v_y = params.l_r * r - v_safe * alpha_r  # from alpha_r = -(v_y - l_r r) / v_x
    delta = alpha_f + (v_y + params.l_f * r) / v_safe  # from alpha_f = delta - (v_y + l_f r) / v_x
    return v_y, r, delta


# Lateral state of the QP and the model-state index of each component.
_LAT = ("VY", "R", "EPSI", "EY")


class QPVar(IntEnum):
    """Columns of one node of the curvature QP: the lateral state (as ``_LAT``), then steering."""

    VY = 0  #: lateral velocity, m/s
    R = 1  #: yaw rate, rad/s
    EPSI = 2  #: heading error to the centerline, rad
    EY = 3  #: lateral offset from the centerline (left positive), m
    DELTA = 4  #: steering angle, rad


def _lateral_qp(
    A: np.ndarray,
    B: np.ndarray,
    f0: np.ndarray,
    grid: TrackGrid,
    v_hat: np.ndarray,
    wheelbase: float,
    st: CurvatureSettings,
    e_y_prev: np.ndarray | None = None,
) -> tuple[str, np.ndarray | None, float]:
    """Solve one QP.

    ``A`` (N,4,4), ``B`` (N,4) are the continuous spatial Jacobians of the lateral state at the
    nodes and ``f0`` (N,4) the affine remainder, dxi/ds ~= A_k xi + B_k delta + f0_k. The dynamics
    are imposed with the trapezoidal rule, xi_{k+1} - xi_k = ds_k / 2 (f_k + f_{k+1}), which is
    A-stable: an explicit RK4 step of 3-5 m is unstable at hairpin speeds, where the lateral
    dynamics in the spatial domain decay over about 1 m.
    """
    import cvxpy as cp

    n = grid.n
    width = len(QPVar)  # columns per node: the lateral state, then delta
    nz = width * n
    ix = np.arange(n)[:, None] * width + np.arange(QPVar.DELTA)[None, :]  # state columns, node k
    idl = np.arange(n) * width + QPVar.DELTA  # delta column of node k
    nxt = (np.arange(n) + 1) % n
    h = 0.5 * grid.ds[:, None, None]
    eye = np.eye(4)[None, :, :]
    blk_k = -(eye + h * A)  # coefficient of xi_k in interval k
    blk_k1 = eye - h * A[nxt]  # coefficient of xi_{k+1}
    rows = np.arange(4 * n).reshape(n, 4)
    r_a = np.repeat(rows[:, :, None], 4, axis=2).ravel()
    data = [
        blk_k.ravel(),
        blk_k1.ravel(),
        -(h[:, :, 0] * B).ravel(),
        -(h[:, :, 0] * B[nxt]).ravel(),
    ]
    ri = [r_a, r_a, rows.ravel(), rows.ravel()]
    ci = [
        np.repeat(ix[:, None, :], 4, axis=1).ravel(),
        np.repeat(ix[nxt][:, None, :], 4, axis=1).ravel(),
        np.repeat(idl, 4),
        np.repeat(idl[nxt], 4),
    ]
    M = sp.csr_matrix(
        (np.concatenate(data), (np.concatenate(ri), np.concatenate(ci))), shape=(4 * n, nz)
    )
    c = h[:, :, 0] * (f0 + f0[nxt])
    # Objective rows: L r / v_hat, sqrt(w1) v_y / v_hat, sqrt(w2) (delta_k - delta_{k-1}).
    q_rows = np.concatenate(
        [np.arange(n), n + np.arange(n), 2 * n + np.arange(n), 2 * n + np.arange(n)]
    )
    q_cols = np.concatenate([ix[:, QPVar.R], ix[:, QPVar.VY], idl, idl[np.arange(n) - 1]])
    q_vals = np.concatenate(
        [
            wheelbase / v_hat,
            math.sqrt(st.w_vy) / v_hat,
            np.full(n, math.sqrt(st.w_ddelta)),
            np.full(n, -math.sqrt(st.w_ddelta)),
        ]
    )
    Q = sp.csr_matrix((q_vals, (q_rows, q_cols)), shape=(3 * n, nz))
    # Proximal term sqrt(w_prox) (e_y - e_y_prev): on straights the curvature does not care where
    # the line lies, and without it the line drifts there from one iteration to the next.
    P = sp.csr_matrix(
        (np.full(n, math.sqrt(st.w_prox)), (np.arange(n), ix[:, QPVar.EY])), shape=(n, nz)
    )
    e_prev = np.zeros(n) if e_y_prev is None else e_y_prev
    lb = np.full(nz, -np.inf)
    ub = np.full(nz, np.inf)
    lb[ix[:, QPVar.EY]], ub[ix[:, QPVar.EY]] = grid.ey_min, grid.ey_max
    lb[idl], ub[idl] = -st.delta_max, st.delta_max
    # Only e_y and delta are bounded: giving the free states bounds of +-1e6 as well doubled the
    # inequality rows and cost Clarabel a quarter more iterations (22 against 16 per QP) for the
    # same line.
    bounded = np.flatnonzero(np.isfinite(lb))
    z = cp.Variable(nz)
    prob = cp.Problem(
        cp.Minimize(cp.sum_squares(Q @ z) + cp.sum_squares(P @ z - math.sqrt(st.w_prox) * e_prev)),
        [M @ z == c.ravel(), z[bounded] >= lb[bounded], z[bounded] <= ub[bounded]],
    )
    t0 = time.perf_counter()
    try:
        if st.solver.upper() == "OSQP":
            prob.solve(
                solver=cp.OSQP,
                eps_abs=st.osqp_eps,
                eps_rel=st.osqp_eps,
                max_iter=20000,
                polish=True,
                warm_start=False,
            )
        else:
            prob.solve(solver=st.solver.upper())
    except cp.error.SolverError as exc:
        return f"solver error: {exc}", None, time.perf_counter() - t0
    status = str(prob.status)
    if status not in ("optimal", "optimal_inaccurate") or z.value is None:
        return status, None, time.perf_counter() - t0
    return status, np.asarray(z.value).reshape(n, 5), time.perf_counter() - t0


def solve_curvature(
    track: Track,
    params: ModelParams,
    options: ModelOptions | None = None,
    settings: CurvatureSettings | None = None,
    *,
    grid: TrackGrid | None = None,
    raise_on_failure: bool = True,
) -> CurvatureResult:
    """Iterate the curvature-optimal QP from the centerline until the line settles.

    Parameters
    ----------
    track : Track
        The track (its centerline is the Frenet reference).
    params : ModelParams
        Planning model parameters, as they are (no grip margin is applied here; see
        :func:`racing_lib.planning.plan`).
    options : ModelOptions, optional
        Model effects (default ``ModelOptions()``): used in the linearized dynamics and the drag in
        the speed profile.
    settings : CurvatureSettings, optional
        Weights, grid and stopping rule.
    grid : TrackGrid, optional
        A grid made beforehand (otherwise built from ``settings``).
    raise_on_failure : bool
        Raise :class:`PlanningError` when a QP fails (default); otherwise return ``success=False``.

    Returns
    -------
    CurvatureResult

    Raises
    ------
    PlanningError
        The QP solver (via cvxpy) reports a QP infeasible or fails; the track is narrower than
        the car.

    Examples
    --------
    >>> from racing_lib.tracks import load_track
    >>> from racing_lib.model import identified_params
    >>> res = solve_curvature(load_track("expressway"), identified_params())
    >>> res.success, round(res.trajectory.lap_time)
    (True, 106)
    """
    st = settings or CurvatureSettings()
    params, pedal, options = model_inputs(params, None, options, "solve_curvature")
    t_start = time.perf_counter()
    if grid is None:
        grid = TrackGrid.from_track(track, st.spacing, st.car_width, st.margin)
    n = grid.n
    wheelbase = float(params.l_f + params.l_r)
    jac = jacobians(params, options, "spatial").map(n)
    f_s = spatial_dynamics(params, options).map(n)

    # Start: the centerline at its speed profile.
    run = _LineIteration(
        e_y=np.zeros(n), e_psi=np.zeros(n), kappa=grid.kappa, s=grid.s, length=grid.length
    )
    run.prof = _line_profile(run, grid, params, pedal, options, st)
    run.lap_times.append(run.prof.lap_time)
    for it in range(1, st.max_iterations + 1):
        run.it = it
        v_hat = _next_v_hat(run, st)
        A, B, f0 = _linearized_lateral(jac, f_s, grid, params, run, v_hat, st)
        status, new, t_qp = _lateral_qp(A, B, f0, grid, v_hat, wheelbase, st, run.e_y)
        run.status = status
        run.qp_time += t_qp
        if new is None:
            if raise_on_failure:
                raise PlanningError(_qp_failure_message(it, status, st, track))
            break
        if _move_line(run, new, grid, params, pedal, options, st):
            break
    else:
        run.status = "max_iterations"
    return _curvature_result(run, grid, track, CarModel(params, options), st, t_start)


@dataclass
class _LineIteration:
    """The state the curvature iteration carries from one QP to the next.

    Attributes
    ----------
    e_y, e_psi : ndarray (N,)
        The current line: lateral offset (m) and heading error (rad) on the grid.
    kappa, s : ndarray (N,)
        The current line's curvature (1/m) and arc length (m) at the nodes.
    length : float
        The current line's length, m.
    prof : SpeedProfile or None
        The current line's speed profile.
    sol : ndarray (N, 5) or None
        The last (damped) QP solution, columns as :class:`QPVar`.
    v_hat_prev : ndarray (N,) or None
        The last speed estimate v_hat, m/s.
    history, lap_times, qp_time, it, status, success
        As in :class:`CurvatureResult` (``it``: the iterations done).
    best, since_best
        (lap time in s, (sol, e_y, e_psi, kappa, s, length, prof)) of the fastest line so far,
        and the iterations since the lap time last improved by more than ``lap_tol``.
    """

    e_y: np.ndarray
    e_psi: np.ndarray
    kappa: np.ndarray
    s: np.ndarray
    length: float
    prof: SpeedProfile | None = None
    sol: np.ndarray | None = None
    v_hat_prev: np.ndarray | None = None
    history: list[float] = field(default_factory=list)
    lap_times: list[float] = field(default_factory=list)
    qp_time: float = 0.0
    it: int = 0
    status: str = "not_run"
    success: bool = False
    best: tuple[float, tuple] | None = None
    since_best: int = 0


def _line_profile(
    run: _LineIteration,
    grid: TrackGrid,
    params: ModelParams,
    pedal: PedalMap | AccelLimits,
    options: ModelOptions,
    st: CurvatureSettings,
) -> SpeedProfile:
    """The speed profile (:func:`speed_profile`) of the iteration's current line."""
    return speed_profile(
        run.s, run.kappa, params, pedal, grid.theta, st.v_top, options, length=run.length
    )


def _next_v_hat(run: _LineIteration, st: CurvatureSettings) -> np.ndarray:
    """The next speed estimate v_hat (m/s): a fraction of the line's profile, under-relaxed."""
    v_new = st.speed_fraction * run.prof.v
    # Under-relax the speed estimate: the line and its speed profile feed each other, and
    # taking the new profile whole makes the line swing by a few decimetres forever.
    prev = run.v_hat_prev
    v_hat = v_new if prev is None else prev + st.relaxation * (v_new - prev)
    run.v_hat_prev = v_hat
    return v_hat


def _linearized_lateral(
    jac: ca.Function,
    f_s: ca.Function,
    grid: TrackGrid,
    params: ModelParams,
    run: _LineIteration,
    v_hat: np.ndarray,
    st: CurvatureSettings,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lateral dynamics linearized at steady cornering on the current line at v_hat (m/s).

    ``jac`` and ``f_s`` are the spatial model's Jacobians and right-hand side mapped over the N
    nodes; ``run`` holds the current line (e_y in m, e_psi in rad) and its speed profile. Returns
    A (N, 4, 4), B (N, 4) and f0 (N, 4) with d xi / ds ~= A xi + B delta + f0 (per m) for the
    lateral state xi (as ``_LAT``).
    """
    n = grid.n
    lat = [int(getattr(X, name)) for name in _LAT]
    # Linearize at steady cornering on the current line at v_hat: with the tyres on the
    # stable side of their peak the linearized lateral dynamics are stable.
    v_y, r_bar, delta_bar = steady_cornering(v_hat, run.kappa, params)
    # Longitudinal input that makes v_x follow v_hat between nodes (v dv/ds).
    a_bar = st.speed_fraction**2 * run.prof.a_x
    xi_bar = np.zeros((6, n))
    xi_bar[X.VX] = v_hat
    xi_bar[X.VY] = v_y
    xi_bar[X.R] = r_bar
    xi_bar[X.EPSI] = run.e_psi
    xi_bar[X.EY] = run.e_y
    xi_bar[X.S] = grid.s
    u_bar = np.vstack([delta_bar, a_bar])
    args = (xi_bar, u_bar, grid.kappa[None, :], grid.theta[None, :])
    A_all, B_all = jac(*args)
    A_all = np.asarray(A_all).reshape(6, n, 6).transpose(1, 0, 2)
    B_all = np.asarray(B_all).reshape(6, n, 2).transpose(1, 0, 2)
    f_bar = np.asarray(f_s(*args)).T
    A = A_all[:, lat][:, :, lat]
    B = B_all[:, lat, 0]
    # v_x and a_x stay at their bar values, so only the lateral deviations enter:
    # f ~= f_bar + A (xi - xi_bar) + B (delta - delta_bar).
    xi_lat = xi_bar[lat].T
    f0 = f_bar[:, lat] - np.einsum("kij,kj->ki", A, xi_lat) - B * delta_bar[:, None]
    return A, B, f0


def _qp_failure_message(it: int, status: str, st: CurvatureSettings, track: Track) -> str:
    """What went wrong in QP iteration ``it`` (solver status ``status``) and what to try."""
    return (
        f"curvature QP iteration {it}: {st.solver} (via cvxpy) returned status "
        f"'{status}' on track {getattr(track, 'name', '?')!r}. Try: check that the track "
        "is wide enough for the car; another node spacing (plan(..., spacing=...); on "
        "the command line --spacing 4); or, in CurvatureSettings, a larger delta_max or "
        "a lower speed_fraction."
    )


def _move_line(
    run: _LineIteration,
    new: np.ndarray,
    grid: TrackGrid,
    params: ModelParams,
    pedal: PedalMap | AccelLimits,
    options: ModelOptions,
    st: CurvatureSettings,
) -> bool:
    """Move the line towards the QP solution ``new`` (N, 5), profile it, keep the fastest.

    Returns True when the iteration stops: 'converged' (the line moved less than ``st.tol``, m)
    or 'settled' (no lap-time gain for ``st.patience`` iterations); ``run`` records which.
    """
    change = float(np.max(np.abs(new[:, QPVar.EY] - run.e_y)))
    run.history.append(change)
    if run.sol is not None and run.it > st.full_steps:
        # Damped fixed-point step: the line and its speed estimate feed each other, and on some
        # tracks the undamped iteration swings between two lines by a metre or two.
        new = run.sol + st.line_step * (new - run.sol)
    run.sol = new
    run.e_psi, run.e_y = new[:, QPVar.EPSI], new[:, QPVar.EY]
    run.kappa, run.s, run.length = grid.line_curvature(run.e_y)
    prof = run.prof = _line_profile(run, grid, params, pedal, options, st)
    run.lap_times.append(prof.lap_time)
    best = run.best
    if best is None or prof.lap_time < best[0] - st.lap_tol:
        run.since_best = 0
    else:
        run.since_best += 1
    if best is None or prof.lap_time < best[0]:
        line = (run.sol, run.e_y, run.e_psi, run.kappa, run.s, run.length, prof)
        run.best = (prof.lap_time, line)
    if change < st.tol:
        run.status, run.success = "converged", True
        return True
    if run.since_best >= st.patience:
        # The fixed-point iteration is not a descent method on the lap time: once the line
        # stops getting faster it wanders between nearly equivalent lines (e.g. in long
        # constant-radius corners, where many lines have the same curvature).
        run.status, run.success = "settled", True
        return True
    return False


def _curvature_result(
    run: _LineIteration,
    grid: TrackGrid,
    track: Track,
    model: CarModel,
    st: CurvatureSettings,
    t_start: float,
) -> CurvatureResult:
    """The fastest line of the iteration, driven at its full speed profile, as the result.

    Raises
    ------
    PlanningError
        If no QP was solved.
    """
    if run.sol is None or run.best is None:
        raise PlanningError(
            f"curvature QP: {st.solver} (via cvxpy) found no solution in the first iteration "
            f"(status '{run.status}'); check the track widths and the steering limit."
        )
    # Keep the fastest line found (by its speed-profile lap time).
    sol, e_y, e_psi, kappa_line, s_line, len_line, prof = run.best[1]
    traj = _trajectory_from_line(grid, e_y, e_psi, sol, prof, kappa_line, len_line, track, model)
    return CurvatureResult(
        success=run.success,
        status=run.status,
        iterations=run.it,
        solve_time=time.perf_counter() - t_start,
        qp_time=run.qp_time,
        trajectory=traj,
        history=run.history,
        lap_times=run.lap_times,
        e_y=e_y,
        e_psi=e_psi,
        v_y=sol[:, QPVar.VY],
        r=sol[:, QPVar.R],
        delta=sol[:, QPVar.DELTA],
        v_x=prof.v,
        a_x=prof.a_x,
        grid=grid,
    )


def _trajectory_from_line(
    grid: TrackGrid,
    e_y: np.ndarray,
    e_psi: np.ndarray,
    sol: np.ndarray,
    prof: SpeedProfile,
    kappa_line: np.ndarray,
    line_length: float,
    track: Track,
    model: CarModel,
) -> Trajectory:
    """The curvature plan as a Trajectory: the QP's line driven at its full speed profile.

    The yaw rate is the line's at that speed, v kappa_line; v_y and delta are the QP's.
    """
    x, y, _ = grid.line_xy(e_y, e_psi)
    v = prof.v
    ds_line = np.diff(np.append(prof.s, line_length))
    dt = segment_times(ds_line, v, np.roll(v, -1))
    return Trajectory.from_states(
        x,
        y,
        vx=v,
        vy=sol[:, QPVar.VY],
        r=v * kappa_line,
        ax=prof.a_x,
        delta=sol[:, QPVar.DELTA],
        dt=dt,
        track=track,
        method="curvature",
        model=model,
    )
