"""Stage two of the two-stage planner: the minimum-lap-time NLP (taught in notebook 04).

The lap time is written as an integral over the centerline's arc length (paper, Eq. TimeObj2),
``T = int (1 - kappa e_y) / (v_x cos e_psi - v_y sin e_psi) ds``, and minimized over the states
xi = (v_x, v_y, r, e_psi, e_y) and inputs u = (delta, a_x) at N nodes of the centerline, subject to
the spatial-domain model of :mod:`racing_lib.model` (:func:`racing_lib.model.spatial_dynamics`),
for a flying lap (the state at the end of the lap equals the state at its start).

Formulation choices, each measured on real circuits before it was adopted:

* **Trapezoidal collocation**: ``xi_{k+1} - xi_k = ds_k / 2 (f(xi_k, u_k) + f(xi_{k+1}, u_{k+1}))``
  with inputs linear between nodes. It is A-stable (explicit steps of 3-5 m are not, at hairpin
  speeds) and cheap to build. With it the paper's "cold start fails" does not reproduce: on a 3 m
  grid a cold start (centerline, 10 m/s) converges as well as the warm start from the curvature
  QP, to the same lap time.
* **A starting barrier for a warm start**: the warm start sits on many active constraints (track
  edges, tyre limits), where IPOPT's defaults made its adaptive barrier collapse and the iterates
  creep (40-168 iterations on real circuits); a small ``mu_init`` with bound multipliers
  ``mu / slack`` (:data:`STARTING_BARRIER`) brought it to 23-36, level with the cold start.
* **Tyres below their peak**: |alpha_f|, |alpha_r| <= the slip angle where the Pacejka force
  reaches 95 % of its peak (``slip_force_share``,
  :meth:`racing_lib.model.ModelParams.slip_angle_at`). Past the peak the optimum is degenerate
  and IPOPT needs several times more iterations; up to the peak itself, plans drifted into
  corners under braking, which the car cannot do.
* **Everything scaled to order one**: each variable is divided by a typical magnitude and each
  dynamics defect by the scale of its state; the objective by a reference lap time.
* **Exact Hessian**, assembled from the symbolic Hessian of one interval (CasADi SX).
* **Combined slip**: the tyres' longitudinal acceleration ``a_x - F_yf sin(delta) / m`` and the
  lateral acceleration a_y share the friction ellipse ``(a_long / a_brake)^2 + (a_y / a_peak)^2
  <= 1`` (``friction_ellipse``; ``a_peak`` is the
  tyres' peak, :meth:`racing_lib.model.ModelParams.peak_acceleration`, ``a_brake`` the pedal
  map's full brake, both identified: the g-g diagram); the model's lateral tyre forces do not know
  about braking, the simulated car's tyres do. The rear tyres also carry the drive force inside
  their own friction circle (``drive_axle_circle``).
* **State-dependent a_x limits** (paper, Appendix C): a_x between the pedal map's value at full
  brake and at full throttle. Our pedal map is affine in the state apart from its power limit, so
  by default (``pedal_limits="exact"``) they are imposed exactly as constraints ``-a_brake <=
  a_x - (m_0 + m_xi . xi) <= m_thr`` (``a_brake``: full brake, the tyres' limit) and, with a
  power limit, ``(a_x - m_0 - m_xi . xi) v_x <= p_thr``; one solve suffices. ``"iterate"``
  is the paper's scheme, for maps that are not affine: bounds evaluated on the last solution,
  re-solved until they settle (at most ``max_outer`` solves). On Norisring (574 nodes) "exact"
  took 25 IPOPT iterations; "iterate" took 3-4 solves of 40-75 iterations each, because every
  re-solve restarts IPOPT's barrier.

The NLP is assembled from the functions of one interval, differentiated and compiled once per
parameter set (:mod:`racing_lib.planning.time_optimal_nlp`), so building it for a new track takes
a fraction of a second; built problems are also kept in a small cache.
"""

from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from racing_lib.errors import PlanningError
from racing_lib.geometry import Track
from racing_lib.model import NX, X
from racing_lib.model.car_model import CarModel
from racing_lib.model.params import ModelOptions
from racing_lib.planning.curvature import solve_curvature, steady_cornering
from racing_lib.planning.curvature_settings import CurvatureResult, CurvatureSettings
from racing_lib.planning.grid import TrackGrid
from racing_lib.planning.ipopt import ipopt_solver, option_advice
from racing_lib.planning.speed import DEFAULT_V_TOP, speed_profile
from racing_lib.planning.time_optimal_nlp import (
    NLP_SCALE,
    NLP_VARS,
    NXS,
    SPEED_SCALE,
    StructuredNLP,
    interval_functions,
)
from racing_lib.planning.time_optimal_settings import (
    TimeOptimalResult,
    TimeOptimalSettings,
)
from racing_lib.planning.trajectory import Trajectory, model_inputs

__all__ = [
    "DEFAULT_START",
    "STARTS",
    "TimeOptimalResult",
    "TimeOptimalSettings",
    "clear_cache",
    "lap_time_with_model",
    "solve_time_optimal",
]

if TYPE_CHECKING:
    # casadi is imported where a problem is built: importing the planners stays cheap

    from racing_lib.model.params import ModelParams

_VARS = NLP_VARS
_SCALE = NLP_SCALE
_NXS = NXS


#: IPOPT options of the NLP's first iterate: a small barrier parameter and bound multipliers
#: ``mu / slack``. With IPOPT's defaults (mu_init 0.1, multipliers 1) the adaptive barrier fell
#: to 1e-7 within a few iterations of the warm start, which sits on many active constraints, and
#: then crept along in short steps: 40-168 iterations on ten real circuits and the two built-in
#: tracks (plan's defaults). With these options: warm 23-36, cold 22-45, to the same lap times
#: within 0.005 % (benchmarks/bench_plan_speed.py). mu_init 1e-6 saved a few more iterations
#: (medians warm / cold 26 / 28 against 29.5 / 29.5) but made the best-lap NLP, which starts from
#: this plan, end on an OpenBLAS-kernel-dependent solution (lap 20.389 s under Sandybridge against
#: 20.380 s), so 1e-4 stays: with it both kernels give the same plans.
STARTING_BARRIER: tuple[tuple[str, str | float], ...] = (
    ("mu_init", 1e-4),
    ("bound_mult_init_method", "mu-based"),
)

#: Where the NLP starts unless told otherwise: ``'cold'`` (the centerline at 10 m/s). With the
#: starting barrier above the warm start from the curvature QP takes as many IPOPT iterations as
#: the cold start (median ratio 1.0 on ten real circuits and the two built-in tracks) to the same
#: lap (within 0.005 %), so the seconds the QP costs first are not bought back: the cold start was
#: the faster plan on all twelve (benchmarks/bench_plan_speed.py). ``start='warm'`` is the paper's
#: two-stage planner, and the start to try when the NLP is made harder (finer grid, other model).
DEFAULT_START = "cold"
#: The starts :func:`solve_time_optimal` and :func:`racing_lib.planning.plan` know.
STARTS = ("cold", "warm")


def _shape_settings(st: TimeOptimalSettings) -> TimeOptimalSettings:
    """The settings reduced to the fields that shape one interval's functions.

    The others are reset to their defaults, so that settings that differ only in solver options,
    grid or bounds share one cached set of interval functions.
    """
    shaping = ("w_ddelta", "w_dax", "slip_limit", "slip_force_share", "friction_ellipse")
    shaping += ("drive_axle_circle", "uncertainty_margin", "pedal_limits")
    shaping += ("lateral_stability", "steer_rate")
    kept = {name: getattr(st, name) for name in shaping}
    # Only the structured graph calls the compiled functions: the others are differentiated by
    # CasADi, which needs the interval functions symbolic.
    return TimeOptimalSettings(**kept, jit=st.jit and st.graph == "structured")


class _Problem:
    """The built NLP for one grid, parameter set, options and settings."""

    def __init__(
        self, grid: TrackGrid, params: ModelParams, options: ModelOptions, st: TimeOptimalSettings
    ) -> None:
        t0 = time.perf_counter()
        self.n = grid.n
        self.grid = grid
        self.params = params
        self.settings = st
        fns = interval_functions(params, options, _shape_settings(st))
        self.t_ref = float(grid.length / 20.0)
        nlp = StructuredNLP(fns, grid.kappa, grid.theta, grid.s, grid.ds, self.t_ref, st.graph)
        self.solver = ipopt_solver(
            "time_optimal", nlp.nlp, st, nlp.derivatives, defaults=STARTING_BARRIER
        )
        self.lbg, self.ubg = nlp.lbg, nlp.ubg
        self.speed_rows = nlp.speed_rows
        self.lap_fn = nlp.lap_fn
        self.build_time = time.perf_counter() - t0

    def speed_bounds(self, v_top: float) -> np.ndarray:
        """The constraints' upper bounds with the car's speed capped at ``v_top`` (m/s)."""
        ubg = self.ubg.copy()
        ubg[self.speed_rows] = (v_top / SPEED_SCALE) ** 2
        return ubg

    def bounds(
        self, ax_lo: np.ndarray, ax_hi: np.ndarray, v_top: float
    ) -> tuple[np.ndarray, np.ndarray]:
        st = self.settings
        n = self.n
        lo = np.empty((len(_VARS), n))
        hi = np.empty((len(_VARS), n))
        rows = {name: i for i, name in enumerate(_VARS)}
        big = 1e3
        lo[rows["VX"]], hi[rows["VX"]] = st.v_min, v_top
        lo[rows["VY"]], hi[rows["VY"]] = -big, big
        lo[rows["R"]], hi[rows["R"]] = -big, big
        lo[rows["EPSI"]], hi[rows["EPSI"]] = -st.e_psi_max, st.e_psi_max
        lo[rows["EY"]], hi[rows["EY"]] = self.grid.ey_min, self.grid.ey_max
        lo[rows["DELTA"]], hi[rows["DELTA"]] = -st.delta_max, st.delta_max
        lo[rows["AX"]], hi[rows["AX"]] = ax_lo, ax_hi
        s = _SCALE[:, None]
        return (lo / s).ravel(order="F"), (hi / s).ravel(order="F")


# Built problems, keyed by what determines them; a few entries only (each holds a compiled NLP).
_CACHE: OrderedDict[tuple[Any, ...], _Problem] = OrderedDict()
_CACHE_SIZE = 4


def _problem(
    grid: TrackGrid,
    track: Track,
    params: ModelParams,
    options: ModelOptions,
    st: TimeOptimalSettings,
) -> tuple[_Problem, float]:
    key = (
        track.checksum() if hasattr(track, "checksum") else id(track),
        grid.n,
        float(grid.ey_min.sum()),
        float(grid.ey_max.sum()),
        params,
        options,
        dataclasses.replace(st, max_outer=0, outer_tol=0.0, v_top=None),
    )
    prob = _CACHE.get(key)
    if prob is not None:
        _CACHE.move_to_end(key)
        return prob, 0.0
    prob = _Problem(grid, params, options, st)
    _CACHE[key] = prob
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return prob, prob.build_time


def clear_cache() -> None:
    """Forget the built NLPs (they are rebuilt on the next solve)."""
    _CACHE.clear()


def _initial_guess(
    grid: TrackGrid, params: ModelParams, start: str | CurvatureResult, cold_speed: float
) -> tuple[np.ndarray, str]:
    """Initial values (7, N) in physical units, and the kind of start."""
    n = grid.n
    z = np.zeros((len(_VARS), n))
    rows = {name: i for i, name in enumerate(_VARS)}
    if isinstance(start, CurvatureResult):
        src = start
        same = src.grid is not None and src.grid.n == n
        sq = grid.s
        period = grid.length

        def get(a: np.ndarray) -> np.ndarray:
            if same:
                return np.asarray(a, float)
            return np.interp(sq, src.grid.s, a, period=period)

        z[rows["VX"]] = get(src.v_x)
        z[rows["EY"]] = get(src.e_y)
        z[rows["EPSI"]] = get(src.e_psi)
        z[rows["DELTA"]] = get(src.delta)
        z[rows["AX"]] = get(src.a_x)
        z[rows["VY"]] = get(src.v_y)
        # The QP's yaw rate belongs to its reduced speed v_hat: use the line's at full speed.
        z[rows["R"]] = get(src.trajectory.r)
        kind = "warm"
    elif start == "cold":
        v = np.full(n, cold_speed)
        vy, r, delta = steady_cornering(v, grid.kappa, params)
        z[rows["VX"]] = v
        z[rows["VY"]] = vy
        z[rows["R"]] = r
        z[rows["DELTA"]] = delta
        kind = "cold"
    else:
        raise PlanningError(f"unknown start {start!r}: pass 'warm', 'cold' or a CurvatureResult.")
    z[rows["VX"]] = np.maximum(z[rows["VX"]], 1.0)
    return z, kind


def _failure_advice(kind: str, st: TimeOptimalSettings, status: str) -> str:
    """What to try after a failed NLP: only knobs that exist, with their command-line flags."""
    if status == "Invalid_Option":
        # Nothing was solved: another start or grid would fail the same way.
        return option_advice(st)
    tips = []
    if kind == "warm":
        tips.append("the cold start (start='cold'; on the command line --start cold)")
    else:
        tips.append(
            "the warm start from the curvature plan (start='warm'; on the command line "
            "--start warm)"
        )
    tips.append(
        f"more iterations (TimeOptimalSettings.max_iter, now {st.max_iter}; on the command "
        f"line --max-iter {2 * st.max_iter})"
    )
    tips.append(
        f"another node spacing (plan(..., spacing=...), now {st.spacing:g} m; on the command "
        "line --spacing 2 or --spacing 4)"
    )
    tips.append("a check of the friction coefficient mu of the parameter set")
    return "; ".join(tips)


def solve_time_optimal(
    track: Track,
    params: ModelParams,
    options: ModelOptions | None = None,
    settings: TimeOptimalSettings | None = None,
    *,
    start: str | CurvatureResult = DEFAULT_START,
    curvature_settings: CurvatureSettings | None = None,
    cold_speed: float = 10.0,
    raise_on_failure: bool = True,
) -> TimeOptimalResult:
    """Plan a minimum-lap-time flying lap.

    Parameters
    ----------
    track : Track
        The track; its centerline is the Frenet reference of the NLP.
    params : ModelParams
        Planning model parameters, as they are (no grip margin is applied here; see
        :func:`racing_lib.planning.plan`).
    options : ModelOptions, optional
        Model effects (default ``ModelOptions()``); any ablation plans through this same code.
    settings : TimeOptimalSettings, optional
        Grid, weights and solver settings.
    start : {'cold', 'warm'} or CurvatureResult
        ``'cold'`` (default, :data:`DEFAULT_START`): start from the centerline at ``cold_speed``;
        ``'warm'``: solve the curvature QP first (same grid and options) and start from it (the
        paper's two-stage planner); or pass a curvature result to start from.
    curvature_settings : CurvatureSettings, optional
        Settings for the warm-start QP (its spacing is set to the NLP's).
    cold_speed : float
        Speed of the cold start, m/s.
    raise_on_failure : bool
        Raise :class:`PlanningError` if IPOPT fails (default). With False a failed solve is returned
        with ``success=False`` and IPOPT's status (used for the warm-vs-cold experiment).

    Returns
    -------
    TimeOptimalResult

    Raises
    ------
    PlanningError
        IPOPT failed (message with its return status and what to try), the track is narrower than
        the car, or the friction is too low for the planner's minimum speed.

    Examples
    --------
    >>> from racing_lib.tracks import load_track
    >>> from racing_lib.model import identified_params
    >>> res = solve_time_optimal(load_track("expressway"), identified_params())
    >>> res.status, round(res.lap_time)
    ('Solve_Succeeded', 104)
    """
    st = settings or TimeOptimalSettings()
    params, _, options = model_inputs(params, None, options, "solve_time_optimal")
    v_top = float(st.v_top) if st.v_top is not None else DEFAULT_V_TOP
    grid = TrackGrid.from_track(track, st.spacing, st.car_width, st.margin)
    _check_friction(track, grid, params, options, st, v_top)
    if isinstance(start, str) and start == "warm":
        cs = curvature_settings or CurvatureSettings()
        cs = dataclasses.replace(
            cs, spacing=st.spacing, car_width=st.car_width, margin=st.margin, v_top=st.v_top
        )
        start = solve_curvature(track, params, options, cs, grid=grid)
    z0, kind = _initial_guess(grid, params, start, cold_speed)

    prob, build_time = _problem(grid, track, params, options, st)
    solves = _solve_with_ax_limits(prob, grid, params, st, z0, v_top)
    if not solves.success and raise_on_failure:
        raise PlanningError(
            f"time-optimal NLP on track {getattr(track, 'name', '?')!r}: IPOPT returned "
            f"'{solves.status}' after {sum(solves.iters)} iterations ({kind} start). Try: "
            f"{_failure_advice(kind, st, solves.status)}."
        )
    traj, lap_time, solution = _read_solution(prob, grid, solves, track, options)
    return TimeOptimalResult(
        success=solves.success,
        status=solves.status,
        iterations=int(sum(solves.iters)),
        solve_time=solves.solve_time,
        build_time=build_time,
        outer_iterations=solves.outer,
        trajectory=traj,
        lap_time=lap_time,
        start=kind,
        iterations_per_solve=solves.iters,
        grid=grid,
        solution=solution,
        evaluation_time=solves.evaluation_time,
    )


def _check_friction(
    track: Track,
    grid: TrackGrid,
    params: ModelParams,
    options: ModelOptions,
    st: TimeOptimalSettings,
    v_top: float,
) -> None:
    """Cheap feasibility checks before any solver runs: enough friction to reach ``st.v_min``.

    Parameters
    ----------
    track : Track
        The track (its name goes into the message).
    grid : TrackGrid
        The planning grid.
    params : ModelParams
        Planning parameters (``mu``, dimensionless).
    options : ModelOptions
        Model effects, for the speed profile.
    st : TimeOptimalSettings
        ``mu_min`` (dimensionless) and ``v_min`` (m/s).
    v_top : float
        Top speed, m/s.

    Raises
    ------
    PlanningError
        If mu is below ``st.mu_min`` or the speed profile falls below ``st.v_min`` somewhere.
    """
    if not params.mu >= st.mu_min:
        raise PlanningError(
            f"friction too low: mu = {params.mu} is below {st.mu_min} (even ice is about 0.1, dry "
            "asphalt 1.0-1.3), so the planner would crawl round the track or fail. Check the "
            "friction coefficient of the parameter set; to plan anyway, lower "
            "TimeOptimalSettings.mu_min."
        )
    prof = speed_profile(
        grid.s, grid.kappa, params, None, grid.theta, v_top, options, length=grid.length
    )
    if float(np.min(prof.v)) < st.v_min:
        k = int(np.argmin(prof.v))
        raise PlanningError(
            f"friction too low for track {getattr(track, 'name', '?')!r}: with mu = {params.mu} "
            "the "
            f"fastest speed through the corner at s = {grid.s[k]:.0f} m is {prof.v[k]:.2f} m/s, "
            f"below the planner's minimum speed v_min = {st.v_min} m/s. Check the friction "
            "coefficient (dry asphalt: about 1.0-1.3) or lower v_min."
        )


@dataclasses.dataclass
class _Solves:
    """What the IPOPT solves of :func:`_solve_with_ax_limits` ended with.

    Attributes
    ----------
    z : ndarray (7, N)
        The last solution in model units (rows as ``NLP_VARS``); the start if none was read.
    status : str
        IPOPT's last return status (with a note if the a_x limits did not settle).
    success : bool
        True if the last solve succeeded (and the a_x limits settled).
    iters : list of int
        IPOPT iterations of each solve.
    solve_time, evaluation_time : float
        Wall time in IPOPT and in its function evaluations, s.
    outer : int
        Number of solves (outer iterations on the a_x limits).
    """

    z: np.ndarray
    status: str = "not_run"
    success: bool = False
    iters: list[int] = dataclasses.field(default_factory=list)
    solve_time: float = 0.0
    evaluation_time: float = 0.0
    outer: int = 0


def _ax_limits_function(
    grid: TrackGrid, params: ModelParams, st: TimeOptimalSettings
) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """The bounds on a_x (m/s^2) at each node of an NLP solution z (7, N), in model units.

    ``st.pedal_limits == "exact"``: the tyres' peak acceleration only; otherwise the pedal map at
    the solution's states as well, capped by the tyres' peak (and the upper bound kept 1e-3 m/s^2
    above the lower one).
    """
    pedal = params.pedal
    grip = params.peak_acceleration()

    def ax_limits(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if st.pedal_limits == "exact":
            return np.full(grid.n, -grip), np.full(grid.n, grip)
        xi = _model_states(z, grid)
        lo, hi = pedal.limits(xi)
        lo = np.maximum(np.asarray(lo, float), -grip)
        hi = np.minimum(np.asarray(hi, float), grip)
        return lo, np.maximum(hi, lo + 1e-3)

    return ax_limits


def _solve_with_ax_limits(
    prob: _Problem,
    grid: TrackGrid,
    params: ModelParams,
    st: TimeOptimalSettings,
    z0: np.ndarray,
    v_top: float,
) -> _Solves:
    """Solve the NLP, re-solving while the a_x limits at the solution move (``st.max_outer``).

    Parameters
    ----------
    prob : _Problem
        The built NLP.
    grid : TrackGrid
        The planning grid.
    params : ModelParams
        Planning parameters (pedal map, tyre peak).
    st : TimeOptimalSettings
        ``max_outer``, ``outer_tol`` (m/s^2) and ``pedal_limits``.
    z0 : ndarray (7, N)
        The initial guess in model units.
    v_top : float
        Top speed, m/s.

    Returns
    -------
    _Solves
    """
    ax_limits = _ax_limits_function(grid, params, st)
    x0 = (z0 / _SCALE[:, None]).ravel(order="F")
    lo_prev, hi_prev = ax_limits(z0)
    out = _Solves(z=z0)
    settled = False
    for outer in range(1, max(1, st.max_outer) + 1):
        out.outer = outer
        lbx, ubx = prob.bounds(lo_prev, hi_prev, v_top)
        x0 = np.clip(x0, lbx, ubx)
        t0 = time.perf_counter()
        sol = prob.solver(x0=x0, lbx=lbx, ubx=ubx, lbg=prob.lbg, ubg=prob.speed_bounds(v_top))
        out.solve_time += time.perf_counter() - t0
        stats = prob.solver.stats()
        out.evaluation_time += sum(v for k, v in stats.items() if k.startswith("t_wall_nlp_"))
        out.status = str(stats.get("return_status", "unknown"))
        out.iters.append(int(stats.get("iter_count", -1)))
        out.success = out.status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
        x_opt = np.asarray(sol["x"], float).ravel()
        if not np.all(np.isfinite(x_opt)):
            out.success = False
            break
        out.z = x_opt.reshape(len(_VARS), grid.n, order="F") * _SCALE[:, None]
        if not out.success:
            break
        x0 = x_opt
        lo_new, hi_new = ax_limits(out.z)
        change = max(np.max(np.abs(lo_new - lo_prev)), np.max(np.abs(hi_new - hi_prev)))
        lo_prev, hi_prev = lo_new, hi_new
        if change < st.outer_tol:
            settled = True
            break
    if out.success and not settled and st.pedal_limits == "iterate":
        # The last solve used limits from the solve before it; accept if the plan respects them.
        a = out.z[_VARS.index("AX")]
        slack = 0.2  # m/s^2
        settled = bool(np.all(a >= lo_prev - slack) and np.all(a <= hi_prev + slack))
        out.success = settled
        if not settled:
            out.status = f"{out.status} (a_x limits not settled after {out.outer} solves)"
    return out


def _read_solution(
    prob: _Problem, grid: TrackGrid, solves: _Solves, track: Track, options: ModelOptions
) -> tuple[Trajectory | None, float, dict[str, np.ndarray]]:
    """The plan, its lap time (s) and the named NLP values of the last solution.

    A solution with a non-finite value gives (None, NaN, {}); one whose s_dot is not positive
    everywhere gives no trajectory. A trajectory that cannot be built is an error only for a
    successful solve.
    """
    traj = None
    lap_time = float("nan")
    solution: dict[str, np.ndarray] = {}
    z = solves.z
    if np.all(np.isfinite(z)):
        lap, s_dot = prob.lap_fn((z / _SCALE[:, None]).ravel(order="F"))
        s_dot = np.asarray(s_dot, float).ravel()
        dt = 0.5 * grid.ds * (1.0 / s_dot + 1.0 / np.roll(s_dot, -1))
        lap_time = float(np.sum(dt))
        solution = {name.lower(): z[i].copy() for i, name in enumerate(_VARS)}
        solution["dt"] = dt
        solution["s_dot"] = s_dot
        if np.all(s_dot > 0):
            try:
                model = CarModel(prob.params, options)
                traj = _trajectory(grid, z, dt, track, model, solves.status, solves.iters)
            except PlanningError:
                if solves.success:
                    raise
    return traj, lap_time, solution


def _trajectory(
    grid: TrackGrid,
    z: np.ndarray,
    dt: np.ndarray,
    track: Track,
    model: CarModel,
    status: str,
    iters: list[int],
) -> Trajectory:
    rows = {name: i for i, name in enumerate(_VARS)}
    x, y, _ = grid.line_xy(z[rows["EY"]], z[rows["EPSI"]])
    return Trajectory.from_states(
        x,
        y,
        vx=z[rows["VX"]],
        vy=z[rows["VY"]],
        r=z[rows["R"]],
        ax=z[rows["AX"]],
        delta=z[rows["DELTA"]],
        dt=dt,
        track=track,
        method="time-optimal",
        model=model,
        info={"ipopt_status": status, "ipopt_iterations": iters},
    )


def _model_states(z: np.ndarray, grid: TrackGrid) -> np.ndarray:
    """Model states (N, 6), rows in :class:`racing_lib.model.X` order, from NLP values (7, N)."""
    xi = np.zeros((grid.n, NX))
    for i, name in enumerate(_VARS[:_NXS]):
        xi[:, int(X[name])] = z[i]
    xi[:, int(X.S)] = grid.s
    return xi


def lap_time_with_model(
    grid: TrackGrid, v_x: np.ndarray, v_y: np.ndarray, e_psi: np.ndarray, e_y: np.ndarray
) -> float:
    """Lap time (s) of states on the grid with the NLP's formula (trapezoid in 1 / s_dot)."""
    s_dot = (v_x * np.cos(e_psi) - v_y * np.sin(e_psi)) / (1.0 - grid.kappa * e_y)
    return float(np.sum(0.5 * grid.ds * (1.0 / s_dot + 1.0 / np.roll(s_dot, -1))))
