"""The best possible lap: minimum lap time with the simulated car's own equations (chapter 07).

The paper compares its controller against the best lap of a human expert. Our stand-in is
the time-optimal lap of the simulated car itself: the same NLP as
:mod:`racing_lib.planning.time_optimal` (trapezoidal collocation over the centerline grid,
periodic flying lap, IPOPT with the exact Hessian, everything scaled to order one), but with the
plant's vector field
(:func:`racing_lib.vehicle.dynamics.car_vector_field`) and its true parameters
(:class:`racing_lib.vehicle.VehicleParams`) instead of the identified planning model.

Per node of the grid (:class:`racing_lib.planning.grid.TrackGrid`):

* states: v_x, v_y, r, the actual road-wheel angle delta (the steering actuator's first-order lag
  is a state), e_psi, e_y; d/ds = (d/dt) / s_dot with the Frenet kinematics
  (:func:`racing_lib.model.frenet_kinematics`, the one definition);
* inputs: the steering command, the drive force F_d in [0, envelope(v_x)] (the best gear at every
  speed, :func:`racing_lib.vehicle.drive_force_envelope`) and the brake force F_b in
  [0, brake_force_max];
* algebraic variables: the two load-transfer accelerations (a_x, a_y), constrained to equal the
  ground-force accelerations the vector field returns (the simulator closes this loop with the
  previous substep's values; at a solution both agree).

Nominal friction on all four wheels (no per-trial randomness), no walls (the e_y bounds keep the car
off them), an ideal gearbox (no torque cut while shifting): so the lap is a slightly optimistic
bound on what the simulated car can do.

What made it converge (a 460 m oval, 4 m grid): the vector field's clamps (tyre force limits,
traction control, steering rate) are kinks, and with them exact IPOPT cycled without converging
(300-1000 iterations). Now (1) the commands are kept inside the limits of the more loaded wheel
of each axle and inside the steering rate limit (``force_margin``, ``rate_margin``); (2) the
remaining clamps, which bind on the lighter inner wheel in corners (both wheels of an axle get the
same command), are rounded off over 1 % of their arguments (``smoothing``): 142 iterations. Keeping
the inner wheels inside their limits as well converged faster (51 iterations) but to a slower,
wrong answer (5 % below the car's cornering speed on a circle). (3) The slip angles are bounded
near the tyre peak, as in the planning NLP. (4) Drive and brake exclude each other (one pedal) by
a relaxed complementarity constraint (``pedal_overlap``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from enum import IntEnum
from types import SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np

from racing_lib.errors import PlanningError
from racing_lib.geometry import Track
from racing_lib.model import frenet_kinematics, identified_params
from racing_lib.planning.grid import DEFAULT_CAR_WIDTH, TrackGrid
from racing_lib.planning.ipopt import ipopt_solver, trapezoid_lap_time
from racing_lib.planning.time_optimal import (
    TimeOptimalResult,
    TimeOptimalSettings,
    lap_time_with_model,
    solve_time_optimal,
)
from racing_lib.planning.trajectory import Trajectory
from racing_lib.vehicle import (
    CASADI_OPS,
    MathOps,
    Numeric,
    VehicleParams,
    drive_force_envelope,
    wheel_loads,
)
from racing_lib.vehicle.dynamics import SimState, car_vector_field, tyre_limits
from racing_lib.vehicle.forces import slip_angles

if TYPE_CHECKING:
    # casadi is imported where a problem is built: importing the planners stays cheap
    import casadi as ca

__all__ = [
    "BestLapResult",
    "BestLapSettings",
    "V",
    "solve_best_lap",
]


class V(IntEnum):
    """Rows of the per-node variables of the best-lap NLP (states first)."""

    VX = 0  #: longitudinal velocity, m/s
    VY = 1  #: lateral velocity, m/s
    R = 2  #: yaw rate, rad/s
    DELTA = 3  #: actual road-wheel steering angle, rad
    EPSI = 4  #: heading error to the centerline, rad
    EY = 5  #: lateral offset from the centerline (left positive), m
    DCMD = 6  #: steering command, rad
    FD = 7  #: drive force at the rear wheels, N
    FB = 8  #: brake force (total, before the split), N
    AXT = 9  #: longitudinal load-transfer acceleration, m/s^2
    AYT = 10  #: lateral load-transfer acceleration, m/s^2


_NS = 6  # states (rows 0..5)
_NV = len(V)
# Typical magnitudes for scaling every variable to order one.
_SCALE = np.array([30.0, 1.0, 0.5, 0.1, 0.2, 5.0, 0.1, 5000.0, 10000.0, 5.0, 10.0])


def _wheel_limits(
    p: VehicleParams, fz: Numeric, front: bool, alpha: Numeric, ops: MathOps
) -> tuple[Numeric, Numeric]:
    """Brake (ABS) and drive (traction control) limits of one wheel, N.

    The sim's tyre law (:func:`racing_lib.vehicle.dynamics.tyre_limits`) with its floors' kinks
    rounded off (width 0.01), since a kink in a constraint at the optimum makes IPOPT cycle.
    """
    b, c, d = (p.B_f, p.C_f, p.D_f) if front else (p.B_r, p.C_r, p.D_r)
    w_half = 0.5 * p.m * p.g / (p.l_f + p.l_r)
    fz_static = w_half * (p.l_r if front else p.l_f)

    def soft_max(a: Numeric, floor2: float) -> Numeric:
        eps = 1e-2
        return 0.5 * (a + floor2 + ops.sqrt((a - floor2) ** 2 + eps * eps))

    _, _, f_drive_max, f_brake_max = tyre_limits(
        p, fz, fz_static, p.mu, b, c, d, alpha, ops, floor_max=soft_max
    )
    return f_brake_max, f_drive_max


def _smooth_ops(rel: float) -> MathOps:
    """CasADi backend whose min/max are rounded off over ``rel`` of the arguments' size.

    The vector field's clamps (a tyre at its limit on the lighter wheel of an axle) are kinks;
    Newton steps jump across them and IPOPT cycles. The rounded max overestimates by at most
    ``rel / sqrt(2)`` of the arguments where they are equal, and nothing away from there.
    """
    import casadi as ca

    if rel <= 0.0:
        return CASADI_OPS

    def smax(a: Numeric, b: Numeric) -> Numeric:
        d = a - b
        return 0.5 * (a + b + ca.sqrt(d * d + rel * rel * (a * a + b * b) + 1e-12))

    def smin(a: Numeric, b: Numeric) -> Numeric:
        return -smax(-a, -b)

    names = ("sin", "cos", "tan", "atan", "sqrt", "tanh", "fabs")
    return SimpleNamespace(
        name="casadi-smooth", fmin=smin, fmax=smax, **{n: getattr(CASADI_OPS, n) for n in names}
    )


def _peak_slip(b: float, c: float) -> float:
    """Slip angle of the peak of sin(C atan(B alpha)), rad."""
    return math.tan(math.pi / (2.0 * c)) / b


@dataclass(frozen=True)
class BestLapSettings:
    """Settings of the best-lap NLP.

    Attributes
    ----------
    spacing : float
        Node spacing along the centerline, m.
    w_dcmd : float
        Weight of the steering-command rate regularization ``sum ((dcmd_{k+1} - dcmd_k)/ds)^2 ds``,
        s per rad^2/m (keeps the command smooth where the lap time does not care).
    max_iter : int
        IPOPT iteration limit.
    tol : float
        IPOPT tolerance (scaled problem).
    car_width : float
        Body width for the e_y bounds, m.
    margin : float or None
        Clearance to the track edge, m (None: as the planner, WALL_MARGIN with walls and
        OPEN_MARGIN open, both 0.8).
    v_min : float
        Lower bound on v_x, m/s.
    v_top : float
        Upper bound on v_x, m/s (the drive envelope vanishes at the rev limiter anyway).
    e_psi_max : float
        Bound on the heading error, rad.
    slip_limit : float or None
        Bound on |alpha_f|, |alpha_r| as a multiple of each axle's Pacejka peak slip at the static
        load (the loaded outer wheels peak later, hence a default above 1); None: no bound.
    force_margin : float
        Wheel force commands are kept below this share of the tyre's limits (peak force, traction
        control), so that the vector field's force clamps, which are kinks, stay inactive, -.
    rate_margin : float
        Same for the steering actuator's rate limit, -.
    smoothing : float
        Relative width over which the vector field's min/max (tyre clamps) are rounded off in the
        NLP (`_smooth_ops`), -; 0 keeps them exact (IPOPT then cycles on laps with corners).
    pedal_overlap : float or None
        The simulated car has one pedal, so drive and brake force exclude each other; imposed as
        ``(F_d / 5000 N) (F_b / 10000 N) <= pedal_overlap`` (a relaxed complementarity; 0 would
        leave IPOPT without an interior). None: no constraint (the optimizer may then brake and
        drive at once to shift the force balance between the axles).
    print_level : int
        IPOPT print level.
    graph : {"sx", "mx"}
        CasADi graph of the mapped problem ("sx": slow build, fast iterations).
    ipopt_options : tuple of (name, value)
        Extra IPOPT options.
    """

    spacing: float = 3.0
    w_dcmd: float = 1.0
    max_iter: int = 1000
    tol: float = 1e-6
    car_width: float = DEFAULT_CAR_WIDTH
    margin: float | None = None
    v_min: float = 3.0
    v_top: float = 80.0
    e_psi_max: float = 1.0
    slip_limit: float | None = 1.2
    force_margin: float = 0.99
    pedal_overlap: float | None = 1e-3
    smoothing: float = 0.01
    rate_margin: float = 0.98
    print_level: int = 0
    graph: str = "sx"
    ipopt_options: tuple[tuple[str, str | float], ...] = ()


@dataclass
class BestLapResult:
    """Result of :func:`solve_best_lap`.

    Attributes
    ----------
    success : bool
        IPOPT converged (``Solve_Succeeded`` or ``Solved_To_Acceptable_Level``).
    status : str
        IPOPT's return status.
    iterations : int
        IPOPT iterations.
    solve_time, build_time : float
        Wall times of the solve and of building the CasADi problem, s.
    lap_time : float
        Lap time of the solution, s.
    trajectory : Trajectory or None
        The lap (method ``'best-lap'``); ``delta`` is the actual steering angle, ``ax`` the
        ground-force acceleration (drive, brake, rolling resistance, tyre forces along the body).
    start : str
        ``'warm'`` (planning-model time-optimal lap), ``'cold'`` or ``'given'``.
    grid : TrackGrid
        The grid.
    solution : dict
        Arrays on the grid, one per :class:`V` row (lower-case names), plus ``dt`` and ``s_dot``.
    warm_start_time : float
        Wall time spent computing the warm start, s.
    """

    success: bool
    status: str
    iterations: int
    solve_time: float
    build_time: float
    lap_time: float
    trajectory: Trajectory | None
    start: str = "warm"
    grid: TrackGrid | None = None
    solution: dict[str, np.ndarray] = field(default_factory=dict)
    warm_start_time: float = 0.0


def _node_function(
    p: VehicleParams, st: BestLapSettings
) -> tuple[ca.Function, list[float], list[float]]:
    """CasADi function of one node: (w scaled, kappa, theta) -> (dstate/ds, path g, 1/s_dot)."""
    import casadi as ca

    ops = CASADI_OPS
    w = ca.SX.sym("w", _NV)
    kap, th = ca.SX.sym("kappa"), ca.SX.sym("theta")
    z = [w[i] * float(_SCALE[i]) for i in range(_NV)]
    vx, vy, r, delta = z[V.VX], z[V.VY], z[V.R], z[V.DELTA]
    e_psi, e_y = z[V.EPSI], z[V.EY]
    zero = ca.SX(0.0)
    state = [zero, zero, zero, vx, vy, r, delta]  # position and yaw do not enter the rates used
    mu = (p.mu,) * 4
    d_state, a_ground = car_vector_field(
        state,
        z[V.DCMD],
        z[V.FD],
        z[V.FB],
        th,
        mu,
        (z[V.AXT], z[V.AYT]),
        p,
        _smooth_ops(st.smoothing),
    )
    s_dot, e_psi_dot, e_y_dot = frenet_kinematics(vx, vy, r, e_psi, e_y, kap, ops)
    rates = ca.vertcat(
        *(d_state[i] for i in (SimState.VX, SimState.VY, SimState.R, SimState.DELTA)),
        e_psi_dot,
        e_y_dot,
    )
    f = rates / s_dot

    # Slip angles as in the vector field (its speed clamp is inactive above v_min).
    alpha_f, alpha_r = slip_angles(vx, vy, r, delta, p.l_f, p.l_r, CASADI_OPS, small_angle=False)
    rate = 1.0 / (st.rate_margin * p.steer_tau * p.steer_rate_max)
    path = [
        (z[V.AXT] - a_ground[0]) / _SCALE[V.AXT],
        (z[V.AYT] - a_ground[1]) / _SCALE[V.AYT],
        (z[V.FD] - drive_force_envelope(p, vx, ops)) / _SCALE[V.FD],
        # Keeps the actuator's rate clamp (a kink of the vector field) inactive.
        (z[V.DCMD] - delta) * rate,
    ]
    lb = [0.0, 0.0, -np.inf, -1.0]
    ub = [0.0, 0.0, 0.0, 1.0]
    # Keep the wheel force commands inside the tyre clamps of the more loaded wheel of each axle
    # (kinks there make IPOPT cycle): brake per front wheel <= f_peak, rear drive <= the
    # traction-control limit. Both wheels of an axle get the same command, so the clamp of the
    # lighter (inner) wheel is a legitimate operating point and stays in the dynamics.
    loads = wheel_loads(p, z[V.AXT], z[V.AYT], th, ops)
    lims = [
        _wheel_limits(p, fz, i < 2, alpha_f if i < 2 else alpha_r, ops)
        for i, fz in enumerate(loads)
    ]
    fb_f = 0.5 * p.brake_front_share * z[V.FB]
    fx_r = 0.5 * z[V.FD] - 0.5 * (1.0 - p.brake_front_share) * z[V.FB]
    lim = st.force_margin
    path += [
        (fb_f - lim * ops.fmax(lims[0][0], lims[1][0])) / _SCALE[V.FB],
        (fx_r - lim * ops.fmax(lims[2][1], lims[3][1])) / _SCALE[V.FD],
        (fx_r + lim * ops.fmax(lims[2][0], lims[3][0])) / _SCALE[V.FD],
    ]
    lb += [-np.inf, -np.inf, 0.0]
    ub += [0.0, 0.0, np.inf]
    if st.pedal_overlap is not None:
        # One pedal: throttle and brake are exclusive (relaxed complementarity, scaled units).
        path.append(w[V.FD] * w[V.FB])
        lb.append(-np.inf)
        ub.append(st.pedal_overlap)
    if st.slip_limit is not None:
        path += [
            alpha_f / (st.slip_limit * _peak_slip(p.B_f, p.C_f)),
            alpha_r / (st.slip_limit * _peak_slip(p.B_r, p.C_r)),
        ]
        lb += [-1.0, -1.0]
        ub += [1.0, 1.0]
    fn = ca.Function("best_lap_node", [w, kap, th], [f, ca.vertcat(*path), 1.0 / s_dot])
    return fn, lb, ub


class _Problem:
    """The built best-lap NLP for one grid, car and settings."""

    def __init__(self, grid: TrackGrid, p: VehicleParams, st: BestLapSettings) -> None:
        import casadi as ca

        t0 = time.perf_counter()
        if st.graph not in ("sx", "mx"):
            raise PlanningError(f"unknown graph {st.graph!r}; use 'sx' or 'mx'.")
        n = grid.n
        node_fn, lb_path, ub_path = _node_function(p, st)
        W = (ca.SX if st.graph == "sx" else ca.MX).sym("w", _NV, n)
        F, P, inv_sdot = node_fn.map(n)(W, ca.DM(grid.kappa).T, ca.DM(grid.theta).T)
        nxt = list(range(1, n)) + [0]
        h = ca.DM(grid.ds).T
        xs = W[0:_NS, :]
        inv_scale = ca.DM(1.0 / _SCALE[:_NS])
        # Trapezoidal collocation, periodic, each defect in units of its state's scale.
        defect = (
            xs[:, nxt]
            - xs
            - 0.5 * ca.repmat(h, _NS, 1) * (F + F[:, nxt]) * ca.repmat(inv_scale, 1, n)
        )
        lap = trapezoid_lap_time(inv_sdot, grid)
        cmd = W[int(V.DCMD), :] * _SCALE[V.DCMD]
        reg = ca.sum2((cmd[:, nxt] - cmd) ** 2 / h)
        t_ref = float(grid.length / 20.0)
        nlp = {
            "x": ca.vec(W),
            "f": (lap + st.w_dcmd * reg) / t_ref,
            "g": ca.vertcat(ca.vec(defect), ca.vec(P)),
        }
        self.solver = ipopt_solver("best_lap", nlp, st)
        self.lbg = np.concatenate([np.zeros(_NS * n), np.tile(lb_path, n)])
        self.ubg = np.concatenate([np.zeros(_NS * n), np.tile(ub_path, n)])
        self.node_fn = node_fn
        self.build_time = time.perf_counter() - t0


def _bounds(
    grid: TrackGrid, p: VehicleParams, st: BestLapSettings
) -> tuple[np.ndarray, np.ndarray]:
    n = grid.n
    lo = np.full((_NV, n), -1e3)
    hi = np.full((_NV, n), 1e3)
    lo[V.VX], hi[V.VX] = st.v_min, st.v_top
    lo[V.DELTA], hi[V.DELTA] = -p.steer_max, p.steer_max
    lo[V.DCMD], hi[V.DCMD] = -p.steer_max, p.steer_max
    lo[V.EPSI], hi[V.EPSI] = -st.e_psi_max, st.e_psi_max
    lo[V.EY], hi[V.EY] = grid.ey_min, grid.ey_max
    lo[V.FD], hi[V.FD] = 0.0, 1e5
    lo[V.FB], hi[V.FB] = 0.0, p.brake_force_max
    s = _SCALE[:, None]
    return (lo / s).ravel(order="F"), (hi / s).ravel(order="F")


def _guess_from_plan(grid: TrackGrid, p: VehicleParams, res: TimeOptimalResult) -> np.ndarray:
    """Initial values (11, N) from a planning-model time-optimal solution, interpolated."""
    sol = res.solution
    src = res.grid
    if src is None or not sol:
        raise PlanningError("the warm-start plan has no solution arrays; use start='cold'.")

    def get(name: str) -> np.ndarray:
        return np.interp(grid.s, src.s, np.asarray(sol[name], float), period=grid.length)

    z = np.zeros((_NV, grid.n))
    z[V.VX], z[V.VY], z[V.R] = get("vx"), get("vy"), get("r")
    z[V.EPSI], z[V.EY] = get("epsi"), get("ey")
    z[V.DELTA] = z[V.DCMD] = get("delta")
    a_x = get("ax")
    # The plan's a_x is the tyre acceleration: drive force beyond it covers drag and rolling.
    resist = p.C_xw * z[V.VX] ** 2 + p.c_rr * p.m * p.g
    z[V.FD] = np.maximum(p.m * a_x + resist, 0.0)
    z[V.FB] = np.clip(-p.m * a_x, 0.0, p.brake_force_max)
    z[V.AXT] = a_x
    z[V.AYT] = z[V.VX] * z[V.R]
    return z


def _cold_guess(grid: TrackGrid, p: VehicleParams, speed: float) -> np.ndarray:
    """Centerline at constant ``speed``, kinematic steering, drive force against the resistance."""
    z = np.zeros((_NV, grid.n))
    z[V.VX] = speed
    z[V.R] = speed * grid.kappa
    z[V.DELTA] = z[V.DCMD] = np.clip(p.wheelbase * grid.kappa, -p.steer_max, p.steer_max)
    z[V.FD] = p.C_xw * speed**2 + p.c_rr * p.m * p.g
    z[V.AYT] = speed**2 * grid.kappa
    return z


def solve_best_lap(
    track: Track,
    vehicle: VehicleParams | None = None,
    settings: BestLapSettings | None = None,
    start: str | TimeOptimalResult | None = None,
    *,
    cold_speed: float = 10.0,
    raise_on_failure: bool = True,
) -> BestLapResult:
    """Minimum-lap-time flying lap of the simulated car with its own equations.

    Parameters
    ----------
    track : Track
        The track (its centerline is the Frenet reference).
    vehicle : VehicleParams, optional
        The car's true parameters (default ``VehicleParams()``).
    settings : BestLapSettings, optional
        Grid and solver settings.
    start : None, 'warm', 'cold' or TimeOptimalResult
        None / ``'warm'``: solve the planning-model time-optimal NLP on the same grid and start
        from it; ``'cold'``: the centerline at ``cold_speed``; or a time-optimal result to start
        from (interpolated onto the grid).
    cold_speed : float
        Speed of the cold start, m/s.
    raise_on_failure : bool
        Raise :class:`PlanningError` when IPOPT fails (default); otherwise return the result with
        ``success=False``.

    Returns
    -------
    BestLapResult

    Raises
    ------
    PlanningError
        IPOPT did not converge (the message gives its status and what to try), or a bad start.
    """
    p = vehicle if vehicle is not None else VehicleParams()
    st = settings or BestLapSettings()
    grid = TrackGrid.from_track(track, st.spacing, st.car_width, st.margin)

    t_warm = time.perf_counter()
    kind = "given"
    if start is None or (isinstance(start, str) and start == "warm"):
        kind = "warm"
        to_settings = TimeOptimalSettings(
            spacing=st.spacing, car_width=st.car_width, margin=st.margin
        )
        # The NLP starts from the plan of the shipped identified model: a good guess of the
        # line, which the car's own equations then refine.
        start = solve_time_optimal(track, identified_params(), settings=to_settings)
    if isinstance(start, TimeOptimalResult):
        z0 = _guess_from_plan(grid, p, start)
    elif isinstance(start, str) and start == "cold":
        kind = "cold"
        z0 = _cold_guess(grid, p, cold_speed)
    else:
        raise PlanningError(
            f"unknown start {start!r}: pass None/'warm', 'cold' or a TimeOptimalResult."
        )
    warm_time = time.perf_counter() - t_warm

    prob = _Problem(grid, p, st)
    lbx, ubx = _bounds(grid, p, st)
    x0 = np.clip((z0 / _SCALE[:, None]).ravel(order="F"), lbx, ubx)
    t0 = time.perf_counter()
    sol = prob.solver(x0=x0, lbx=lbx, ubx=ubx, lbg=prob.lbg, ubg=prob.ubg)
    solve_time = time.perf_counter() - t0
    stats = prob.solver.stats()
    status = str(stats.get("return_status", "unknown"))
    iters = int(stats.get("iter_count", -1))
    x_opt = np.asarray(sol["x"], float).ravel()
    success = status in ("Solve_Succeeded", "Solved_To_Acceptable_Level") and bool(
        np.all(np.isfinite(x_opt))
    )
    if not success and raise_on_failure:
        raise PlanningError(
            f"best-lap NLP on track {getattr(track, 'name', '?')!r}: IPOPT returned '{status}' "
            f"after {iters} iterations ({kind} start). Try: the warm start (start='warm'), a "
            "larger BestLapSettings.max_iter, a looser slip_limit, or a different grid spacing."
        )
    z = x_opt.reshape(_NV, grid.n, order="F") * _SCALE[:, None]
    lap_time = float("nan")
    traj = None
    solution: dict[str, np.ndarray] = {}
    if np.all(np.isfinite(z)):
        vx, vy, e_psi, e_y = z[V.VX], z[V.VY], z[V.EPSI], z[V.EY]
        lap_time = lap_time_with_model(grid, vx, vy, e_psi, e_y)
        s_dot, _, _ = frenet_kinematics(vx, vy, z[V.R], e_psi, e_y, grid.kappa, np)
        dt = 0.5 * grid.ds * (1.0 / s_dot + 1.0 / np.roll(s_dot, -1))
        solution = {v.name.lower(): z[v].copy() for v in V}
        solution["dt"], solution["s_dot"] = dt, s_dot
        if np.all(s_dot > 0):
            x, y, _ = grid.line_xy(e_y, e_psi)
            try:
                traj = Trajectory.from_states(
                    x,
                    y,
                    vx=vx,
                    vy=vy,
                    r=z[V.R],
                    ax=z[V.AXT],
                    delta=z[V.DELTA],
                    dt=dt,
                    track=track,
                    method="best-lap",
                    info={
                        "ipopt_status": status,
                        "ipopt_iterations": iters,
                        "vehicle": dataclasses.asdict(p),
                    },
                )
            except PlanningError:
                if success:
                    raise
    return BestLapResult(
        success=success,
        status=status,
        iterations=iters,
        solve_time=solve_time,
        build_time=prob.build_time,
        lap_time=lap_time,
        trajectory=traj,
        start=kind,
        grid=grid,
        solution=solution,
        warm_start_time=warm_time,
    )
