"""Model predictive tracking controllers: the coupled MPC of the paper and the decoupled baseline.

Taught in notebook 05. Both follow a planned :class:`~racing_lib.planning.trajectory.Trajectory`
in Frenet coordinates relative to the *plan's own line* (``trajectory.path``), so the reference
lateral offset is zero and the reference heading error is the plan's side-slip (see
:meth:`CoupledMPC.reference`). Both linearize the one model of :mod:`racing_lib.model` (never a
copy of its equations) and solve one small QP per control period with the OSQP fast path of
:mod:`racing_lib.control.mpc_qp`.

:class:`CoupledMPC` (paper Section "Tracking Controller")
    One QP over the coupled longitudinal and lateral dynamics, states
    ``[v_x, v_y, r, e_psi, e_y]`` and inputs ``[delta, a_x]``, linearized along the *heuristic
    trajectory* ``xi_hat_k = xi_ref_k + lambda_k (xi_0 - xi_ref_0)`` with ``lambda_k`` falling
    linearly from 1 to 0 over the horizon (``smooth_transition=False``: all ``lambda_k = 0``, the
    paper's ablation). The ``a_x`` bounds come from the pedal map at the heuristic states, and the
    solved ``a_x`` becomes a pedal command through the map's inverse (paper Appendix C).

:class:`DecoupledMPC` (the paper's controller ablation)
    A longitudinal MPC (state ``v_x``, input ``a_x``) and a lateral MPC (states
    ``[v_y, r, e_psi, e_y]``, input ``delta``, speed assumed to follow the reference), each
    linearized about the reference alone; the other subsystem's variables are frozen at their
    reference values.

Why the arc length ``s`` is not a QP state: it carries no cost and no constraint, and it enters
the other equations only through the curvature ``kappa(s)``, which the linearization evaluates
at the heuristic ``s_hat_k`` as a fixed parameter. Its row of the linear model therefore never
feeds back into the other five states; dropping it removes one sixth of the QP without changing
its solution.

Why the reference is spaced by time: stage ``k`` is the plan at time ``t_plan(s_0) + k dt``
(interpolated along the plan's own time stamps), which is where a car that follows the plan
exactly is after ``k`` control periods. Spacing by ``v_ref(s_0) dt`` would be the same on a
straight but would put the stages in the wrong places where the plan brakes or accelerates.

Robustness: a QP that does not report a solution never stops the lap. The controller applies the
next input of the previous solution (shifted), and when none is left a safe braking command; each
event is counted (:meth:`stats`) and logged.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from racing_lib.control.mpc_qp import QPData, QPSettings, QPShape, QPSolution, TrackingQP
from racing_lib.errors import ControlError
from racing_lib.interfaces import Command
from racing_lib.jit import compile_function
from racing_lib.model import NU, NX, U, X, discrete_linearization

log = logging.getLogger(__name__)


class MX(IntEnum):
    """Indices of the coupled MPC's state: the model's state without ``s``, plus the steering
    actuator's output (see :func:`augment_steering_lag`)."""

    VX = 0  #: longitudinal velocity, m/s
    VY = 1  #: lateral velocity, m/s
    R = 2  #: yaw rate, rad/s
    EPSI = 3  #: heading error to the plan's line, rad
    EY = 4  #: lateral offset from the plan's line, m
    DELTA = 5  #: actual steering angle behind the actuator lag, rad (estimated, not weighted)


#: Model-state indices of the coupled MPC's states, in :class:`MX` order.
_COUPLED_STATES = np.array([X.VX, X.VY, X.R, X.EPSI, X.EY])
#: Model-state indices of the lateral MPC's states (v_y, r, e_psi, e_y).
_LATERAL_STATES = np.array([X.VY, X.R, X.EPSI, X.EY])


@dataclass(frozen=True)
class MPCSettings:
    """Settings of the MPC tracking controllers (both the coupled and the decoupled one).

    Weights multiply squared errors in the units given, so ``w_ey = 10`` costs as much for 1 m of
    lateral error as ``w_vx = 10`` for 1 m/s of speed error.

    Attributes
    ----------
    horizon : int
        N_p, the number of stages, each ``dt`` long.
    dt : float
        Stage length, s; must equal the plant's control period (0.1 s for the simulated car).
    w_vx : float
        Weight of (v_x - v_x,ref)^2, 1/(m/s)^2.
    w_vy : float
        Weight of (v_y - v_y,ref)^2, 1/(m/s)^2.
    w_r : float
        Weight of (r - r_ref)^2, 1/(rad/s)^2.
    w_epsi : float
        Weight of (e_psi - e_psi,ref)^2, 1/rad^2.
    w_ey : float
        Weight of e_y^2, 1/m^2.
    w_ddelta : float
        Weight of the steering change per period (delta_k - delta_{k-1})^2, 1/rad^2.
    w_dax : float
        Weight of the a_x change per period, 1/(m/s^2)^2 (small: it only damps pedal chatter;
        the paper has none).
    terminal_factor : float
        The last stage's state weights are multiplied by this (1 = the paper's uniform weights).
    slack_linear, slack_quadratic : float
        Penalty rho_1 eps + rho_2 eps^2 of the soft e_y band, per m and per m^2. Large enough that
        the band holds whenever it can, small enough not to dwarf the tracking weights: with 1e3
        and 1e4 the QP became ill-conditioned when the band was active (OSQP needed thousands of
        iterations) and the car reacted violently at the edge of the band; 100 and 1000 gave
        fewer wall contacts on time-optimal plans that run along the edges.
    margin : float
        Distance kept between the car's side and the track edge, m (on top of half the width).
    car_width : float
        Car body width, m (the paper's Demio: 2.008 m).
    steer_max : float
        Steering angle limit, rad.
    steer_rate_max : float
        Steering slew-rate limit, rad/s, a hard constraint on the change per stage (the simulated
        car's actuator: 1.2 rad/s). Commanding faster changes than the actuator can follow makes
        the closed loop oscillate. ``inf`` removes it.
    steer_tau : float
        Time constant of the steering actuator's first-order lag, s (the simulated car's is
        0.08 s; ``racing_lib.sysid`` identifies it). The QP carries the actual steering angle
        as an extra state so that it knows a command acts only partly within the first period
        (see :func:`augment_steering_lag`). 0 removes the lag model. At 45 m/s an unmodelled
        0.08 s lag was enough to make the closed loop oscillate and spin the car.
    smooth_transition : bool
        Linearize along the heuristic trajectory (True, the paper's method) or along the reference
        itself (False: all lambda_k = 0, the ablation). Used by :class:`CoupledMPC` only.
    throttle_scale, brake_scale : float
        Factors on the pedal map's full-throttle and full-brake accelerations (``m_thr``,
        ``m_brk``) inside the MPC, for both the a_x bounds and the pedal inverse (1 = the map as
        given). Below 1 when the map promises more than the car delivers: measured on the
        simulated car, full brake at 40-50 m/s gave about 10.4 m/s^2 where the identified map
        says 12.2, and a controller that believes the map brakes too late.
    friction_ellipse : bool
        Bound a_x also by the friction left over from cornering, the planner's g-g ellipse:
        ``|a_x| <= a_brake sqrt(1 - (a_y / a_peak)^2)`` with ``a_y = v_x r`` of the heuristic
        trajectory, ``a_peak = friction_scale mu D g`` (``D`` the smaller Pacejka peak factor)
        and ``a_brake`` the pedal map's full brake (scaled alike, at most ``a_peak``). The
        model's tires do not know that braking costs lateral grip; the car's do, and a
        controller that brakes fully into a hairpin (as the plan may ask when the car arrives
        too fast) understeers into the wall.
        This is the planner's friction ellipse, made a state-dependent input bound like the
        paper's pedal limits.
    friction_scale : float
        Fraction of the model's peak friction the ellipse allows (dimensionless).
    ax_min_floor : float
        Lower bound on a_x in any case, m/s^2 (-inf: the pedal map alone decides). The linear
        pedal map keeps promising more deceleration at full brake than the tires give: on the
        simulated car full brake gave about -11 m/s^2 at 30-50 m/s where the identified map
        says -12 to -12.3. Unlike ``brake_scale`` this leaves partial braking as mapped.
    brake_pedal : float
        Pedal of the safe braking fallback, in [-1, 0).
    fallback_gain_ey : float
        Steering of the braking fallback per m of e_y, rad/m (steers back toward the line).
    fallback_gain_epsi : float
        Steering of the braking fallback per rad of e_psi, rad/rad.
    discretization : str
        How the model is made discrete over ``dt``. ``"rk4"`` (default): ``substeps`` RK4 steps of
        model.py's :func:`~racing_lib.model.discretize` chained, and the exact Jacobians of that
        nonlinear discrete map (so the affine model is exact to first order). ``"zoh"``: the exact
        discretization of the continuous-time linearization with the input held (a matrix
        exponential of model.py's Jacobians); stable at any speed, but only an O(dt^2)
        approximation of the nonlinear step away from equilibria.
    substeps : int
        RK4 steps per period for ``"rk4"``. One RK4 step of 0.1 s is unstable for the tire modes
        below about 8 m/s (|lambda dt| > 2.8), which turns a slow car's QP into nonsense; 2 steps
        keep it stable down to about 4 m/s, 4 steps to about 2 m/s.
    jit : bool
        Compile the linearization with the system C compiler (about a second, once per parameter
        set: the build is cached on disk, :mod:`racing_lib.jit`): about 0.15 ms instead of 1 ms
        per step. Falls back to the
        interpreter, with a warning, when no compiler works.
    qp : QPSettings
        Settings of the OSQP fast path.
    """

    horizon: int = 25
    dt: float = 0.1
    w_vx: float = 1.0
    w_vy: float = 1.0
    w_r: float = 10.0
    w_epsi: float = 50.0
    w_ey: float = 5.0
    w_ddelta: float = 100.0
    w_dax: float = 0.01
    terminal_factor: float = 1.0
    slack_linear: float = 100.0
    slack_quadratic: float = 1000.0
    margin: float = 0.3
    car_width: float = 2.008
    steer_max: float = 0.5
    steer_rate_max: float = 1.2
    steer_tau: float = 0.08
    smooth_transition: bool = True
    throttle_scale: float = 1.0
    brake_scale: float = 1.0
    friction_ellipse: bool = True
    friction_scale: float = 1.0
    ax_min_floor: float = -np.inf
    brake_pedal: float = -0.3
    fallback_gain_ey: float = 0.05
    fallback_gain_epsi: float = 0.5
    discretization: str = "rk4"
    substeps: int = 2
    jit: bool = True
    qp: QPSettings = field(default_factory=QPSettings)

    def __post_init__(self) -> None:
        if int(self.horizon) != self.horizon or self.horizon < 2:
            raise ControlError(f"MPCSettings.horizon must be an integer >= 2, got {self.horizon}.")
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ControlError(f"MPCSettings.dt must be > 0 s, got {self.dt}.")
        for name in ("w_vx", "w_vy", "w_r", "w_epsi", "w_ey", "w_ddelta", "w_dax", "margin"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ControlError(f"MPCSettings.{name} must be finite and >= 0, got {value}.")
        if not -1.0 <= self.brake_pedal < 0.0:
            raise ControlError(
                f"MPCSettings.brake_pedal must be in [-1, 0) (a brake), got {self.brake_pedal}."
            )
        if not self.steer_max > 0:
            raise ControlError(f"MPCSettings.steer_max must be > 0 rad, got {self.steer_max}.")
        if self.discretization not in ("zoh", "rk4"):
            raise ControlError(
                f"MPCSettings.discretization must be 'rk4' or 'zoh', got {self.discretization!r}."
            )
        if int(self.substeps) != self.substeps or self.substeps < 1:
            raise ControlError(
                f"MPCSettings.substeps must be an integer >= 1, got {self.substeps}."
            )
        for name in ("throttle_scale", "brake_scale"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ControlError(f"MPCSettings.{name} must be > 0, got {value}.")
        if not (math.isfinite(self.steer_tau) and self.steer_tau >= 0):
            raise ControlError(f"MPCSettings.steer_tau must be >= 0 s, got {self.steer_tau}.")
        if not self.steer_rate_max > 0:
            raise ControlError(
                f"MPCSettings.steer_rate_max must be > 0 rad/s (inf for none), "
                f"got {self.steer_rate_max}."
            )

    def state_weights(self) -> np.ndarray:
        """Per-stage weights of the coupled states, shape (N, 6) (the last stage scaled).

        The actual steering angle (:attr:`MX.DELTA`) has weight 0: it is a state of the
        actuator, not a tracking target.
        """
        w = np.array([self.w_vx, self.w_vy, self.w_r, self.w_epsi, self.w_ey, 0.0], dtype=float)
        out = np.tile(w, (self.horizon, 1))
        out[-1] *= self.terminal_factor
        return out


def _wrap(angle: float) -> float:
    """Angle wrapped to [-pi, pi), rad."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class _PlanTable:
    """The plan's node values, extended by one node at s = length, for fast vectorized lookups.

    Holds, per node: v_x, v_y, r, e_psi_ref (= -atan(v_y / v_x), the plan's heading relative to
    its own line), delta, a_x, kappa, theta (road pitch), and the e_y band. Lookups are linear
    interpolation in s (periodic) and the time <-> s relation of the plan.
    """

    # Column indices of the table.
    VX, VY, R, EPSI, DELTA, AX, KAPPA, THETA, BMIN, BMAX = range(10)

    def __init__(self, plan: Any, theta: np.ndarray, band_min: np.ndarray, band_max: np.ndarray):
        self.length = float(plan.path.length)
        self.lap_time = float(plan.planned_lap_time)
        s = np.asarray(plan.s, dtype=float)
        vx = np.asarray(plan.vx, dtype=float)
        vy = np.asarray(plan.vy, dtype=float)
        cols = np.column_stack(
            [
                vx,
                vy,
                np.asarray(plan.r, dtype=float),
                # Along its own line the planned car has e_y_dot = v_x sin(e_psi) + v_y cos(e_psi)
                # = 0, so its heading relative to the line is -atan(v_y / v_x), not zero.
                -np.arctan2(vy, np.maximum(vx, 1.0)),
                np.asarray(plan.delta, dtype=float),
                np.asarray(plan.ax, dtype=float),
                np.asarray(plan.kappa, dtype=float),
                theta,
                band_min,
                band_max,
            ]
        )
        self.s = np.append(s, self.length)
        self.table = np.vstack([cols, cols[:1]])
        t = np.asarray(plan.t, dtype=float)
        self.t = np.append(t, self.lap_time)

    def at_s(self, s: np.ndarray) -> np.ndarray:
        """Interpolated rows at arc lengths ``s`` (m, any real; wrapped), shape (len(s), 10)."""
        sq = np.mod(s, self.length)
        i = np.clip(np.searchsorted(self.s, sq, side="right") - 1, 0, self.s.size - 2)
        w = (sq - self.s[i]) / (self.s[i + 1] - self.s[i])
        return self.table[i] * (1.0 - w)[:, None] + self.table[i + 1] * w[:, None]

    def time_at(self, s: float) -> float:
        """Plan time at arc length ``s`` within the lap, s."""
        return float(np.interp(s % self.length, self.s, self.t))

    def s_at_times(self, t: np.ndarray) -> np.ndarray:
        """Unwrapped arc length (m) the plan reaches at times ``t`` (s, may exceed a lap)."""
        laps = np.floor(t / self.lap_time)
        tq = t - laps * self.lap_time
        return np.interp(tq, self.t, self.s) + laps * self.length


@functools.lru_cache(maxsize=16)
def _substep_linearization(
    params: Any, options: Any, dt: float, substeps: int, jit: bool = False
) -> Any:
    """CasADi Function ``(xi_bar, u_bar, kappa, theta) -> (A_d, B_d, d_d)`` of ``substeps`` chained
    RK4 steps of model.py's :func:`~racing_lib.model.discretize` (step ``dt / substeps``).

    Same contract as :func:`racing_lib.model.discrete_linearization`, whose single RK4 step of
    0.1 s is unstable at low speed. With ``jit`` the Function is compiled to machine code by the
    system C compiler (about 1-4 s, once per parameter set: :mod:`racing_lib.jit` caches the
    build on disk by the hash of its code), which makes it about eight times faster than CasADi's
    interpreter; without a compiler it falls back to the interpreter with a warning.
    """
    import casadi as ca

    from racing_lib.model import discretize

    F = discretize(params, options, dt / substeps, "rk4", "time")
    xi, u = ca.SX.sym("xi", NX), ca.SX.sym("u", NU)
    kappa, theta = ca.SX.sym("kappa"), ca.SX.sym("theta")
    x = xi
    for _ in range(substeps):
        x = F(x, u, kappa, theta)
    A = ca.jacobian(x, xi)
    B = ca.jacobian(x, u)
    d = x - ca.mtimes(A, xi) - ca.mtimes(B, u)
    fn = ca.Function("racing_lib_mpc_lin", [xi, u, kappa, theta], [A, B, d])
    if jit:
        compiled = compile_function(fn)
        if compiled is not None:
            return compiled
        log.warning(
            "compiling the MPC linearization failed; using CasADi's interpreter (slower). "
            "Install a C compiler (cc) or pass MPCSettings(jit=False)."
        )
    return fn


def _continuous_linearization(params: Any, options: Any) -> Any:
    """CasADi Function ``(xi, u, kappa, theta) -> (A_c, B_c, c)`` of model.py's time-domain model.

    ``xi_dot ~= A_c xi + B_c u + c`` near the point, with ``c = f - A_c xi - B_c u``.
    """
    import casadi as ca

    from racing_lib.model import jacobians, time_dynamics

    f = time_dynamics(params, options)
    jac = jacobians(params, options, "time")
    xi, u = ca.SX.sym("xi", NX), ca.SX.sym("u", NU)
    kappa, theta = ca.SX.sym("kappa"), ca.SX.sym("theta")
    A_c, B_c = jac(xi, u, kappa, theta)
    c = f(xi, u, kappa, theta) - ca.mtimes(A_c, xi) - ca.mtimes(B_c, u)
    return ca.Function("lin_continuous", [xi, u, kappa, theta], [A_c, B_c, c])


def expm_batch(M: np.ndarray, order: int = 8, max_norm: float = 0.5) -> np.ndarray:
    """Matrix exponentials of a batch of small matrices, shape (N, n, n).

    Scaling and squaring with a Taylor polynomial: divide by 2^j so that the largest infinity norm
    in the batch is at most ``max_norm``, sum the series to ``order`` (truncation error below
    ``max_norm^(order+1) / (order+1)!``, about 5e-9 relative at the defaults), then square j times.
    Written out because it is a fixed, short sequence of batched matrix products: for the MPC's
    25 matrices of 9 x 9 it takes a fraction of a millisecond every time, where
    ``scipy.linalg.expm`` took from 0.3 to 200 ms on the same machine.
    """
    n = M.shape[-1]
    norm = float(np.abs(M).sum(axis=-1).max()) if M.size else 0.0
    j = max(0, math.ceil(math.log2(norm / max_norm))) if norm > max_norm else 0
    X = M / (2.0**j)
    eye = np.eye(n)
    E = np.broadcast_to(eye, M.shape).copy()
    for k in range(order, 0, -1):  # Horner: I + X (I + X/2 (I + X/3 (...)))
        E = eye + (X @ E) / k
    for _ in range(j):
        E = E @ E
    return E


def _zoh(A_c: np.ndarray, B_c: np.ndarray, c: np.ndarray, dt: float) -> tuple:
    """Exact discretization over ``dt`` of ``xi_dot = A_c xi + B_c u + c`` with ``u`` held.

    ``expm(dt [[A_c, B_c, c], [0, 0, 0]]) = [[A_d, B_d, d_d], [0, I, 0]]``, batched over stages.
    """
    N, n, m = B_c.shape
    M = np.zeros((N, n + m + 1, n + m + 1))
    M[:, :n, :n] = A_c * dt
    M[:, :n, n : n + m] = B_c * dt
    M[:, :n, n + m] = c * dt
    Phi = expm_batch(M)
    return Phi[:, :n, :n], Phi[:, :n, n : n + m], Phi[:, :n, n + m]


def steering_lag_coefficients(tau: float, dt: float) -> tuple[float, float]:
    """``(a, w)`` of the first-order steering lag ``delta_dot = (delta_cmd - delta) / tau``.

    Over one period with the command held: ``delta_{k+1} = a delta_k + (1 - a) delta_cmd`` with
    ``a = exp(-dt / tau)``, and the *mean* angle over the period is
    ``w delta_k + (1 - w) delta_cmd`` with ``w = tau / dt (1 - a)``. ``tau = 0``: ``(0, 0)``.
    """
    if tau <= 0.0:
        return 0.0, 0.0
    a = math.exp(-dt / tau)
    return a, tau / dt * (1.0 - a)


def augment_steering_lag(
    A: np.ndarray, B: np.ndarray, d: np.ndarray, steer_col: int, tau: float, dt: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Append the actual steering angle as the last state of a batch of discrete models.

    The vehicle model sees the steering *angle*; the controller sets the *command*, which the
    actuator follows with a first-order lag. The vehicle's input over a period is approximated by
    the period's mean angle ``w delta_k + (1 - w) delta_cmd,k`` (coefficients from
    :func:`steering_lag_coefficients`), and the angle itself becomes a state:
    ``delta_{k+1} = a delta_k + (1 - a) delta_cmd,k``.

    Parameters
    ----------
    A : ndarray, shape (N, n, n)
    B : ndarray, shape (N, n, m)
    d : ndarray, shape (N, n)
        The models ``x_{k+1} = A x_k + B u_k + d`` with the steering angle in column
        ``steer_col`` of ``B``.
    steer_col : int
        Which input is the steering.
    tau, dt : float
        Lag time constant and period, s.

    Returns
    -------
    A_aug (N, n+1, n+1), B_aug (N, n+1, m), d_aug (N, n+1)
    """
    N, n, m = B.shape
    a, w = steering_lag_coefficients(tau, dt)
    A_aug = np.zeros((N, n + 1, n + 1))
    A_aug[:, :n, :n] = A
    A_aug[:, :n, n] = w * B[:, :, steer_col]
    A_aug[:, n, n] = a
    B_aug = np.zeros((N, n + 1, m))
    B_aug[:, :n, :] = B
    B_aug[:, :n, steer_col] *= 1.0 - w
    B_aug[:, n, steer_col] = 1.0 - a
    d_aug = np.zeros((N, n + 1))
    d_aug[:, :n] = d
    return A_aug, B_aug, d_aug


def _edge_band(plan: Any, track: Any, car_width: float, margin: float) -> tuple:
    """Grade and e_y band per plan node, from the track edges.

    For each plan node the centerline projection gives ``(s_c, e_c)``; the plan point is ``e_c``
    left of the centerline, so the edges are ``w_left(s_c) - e_c`` to its left and
    ``w_right(s_c) + e_c`` to its right. Measured along the plan's normal rather than the
    centerline's, the distance is ``1 / cos`` of the angle between the lines longer, so this is
    slightly conservative. The car's
    centre must stay half its width plus ``margin`` inside. Where the plan itself comes closer to an
    edge than that, the band is widened to include the plan (e_y = 0): the reference must lie
    inside its own band, else the QP would fight the plan everywhere near that edge.

    Returns
    -------
    theta, band_min, band_max : ndarray, shape (n_nodes,)
        Road pitch at the node (rad) and the band on e_y relative to the plan (m).
    """
    x = np.asarray(plan.x, dtype=float)
    y = np.asarray(plan.y, dtype=float)
    # Along the plan, so that every node stays on its own stretch where the track crosses itself.
    s_c, e_c = track.centerline.to_frenet_along(x, y)
    inset = 0.5 * car_width + margin
    band_max = np.asarray(track.width_left(s_c), dtype=float) - e_c - inset
    band_min = -(np.asarray(track.width_right(s_c), dtype=float) + e_c - inset)
    band_max = np.maximum(band_max, 0.0)
    band_min = np.minimum(band_min, 0.0)
    theta = np.asarray(track.grade(s_c), dtype=float)
    return theta, band_min, band_max


class _MPCBase:
    """Shared machinery: plan lookup, state estimate, fallbacks, counters and timings."""

    def __init__(
        self,
        plan: Any,
        params: Any = None,
        options: Any = None,
        pedal_map: Any = None,
        track: Any = None,
        settings: MPCSettings | None = None,
        band: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        from racing_lib.geometry import FrenetTracker
        from racing_lib.model import ModelOptions, ModelParams

        self.settings = settings or MPCSettings()
        self.params = params if params is not None else ModelParams()
        self.options = options if options is not None else ModelOptions()
        pedal_map = pedal_map if pedal_map is not None else self.params.pedal
        st = self.settings
        if st.throttle_scale != 1.0 or st.brake_scale != 1.0:
            pedal_map = dataclasses.replace(
                pedal_map,
                m_thr=pedal_map.m_thr * st.throttle_scale,
                m_brk=pedal_map.m_brk * st.brake_scale,
                p_thr=None if pedal_map.p_thr is None else pedal_map.p_thr * st.throttle_scale,
            )
        self.pedal_map = pedal_map
        if not isinstance(self.params, ModelParams):
            raise ControlError(
                f"params must be a racing_lib.model.ModelParams, got {type(self.params).__name__}."
            )
        for name in ("s", "vx", "vy", "r", "delta", "ax", "kappa", "t", "path"):
            if not hasattr(plan, name):
                raise ControlError(
                    f"the MPC needs a planned Trajectory (missing {name!r}); build one with "
                    "racing_lib.planning (e.g. Trajectory.from_centerline(track))."
                )
        self.plan = plan
        self.path = plan.path
        n_nodes = len(plan.s)
        if track is not None:
            theta, bmin, bmax = _edge_band(
                plan, track, self.settings.car_width, self.settings.margin
            )
        else:
            theta = np.zeros(n_nodes)
            bmin, bmax = np.full(n_nodes, -np.inf), np.full(n_nodes, np.inf)
        if band is not None:
            bmin = np.broadcast_to(np.asarray(band[0], dtype=float), (n_nodes,)).copy()
            bmax = np.broadcast_to(np.asarray(band[1], dtype=float), (n_nodes,)).copy()
        self._plan = _PlanTable(plan, theta, bmin, bmax)
        self._tracker = FrenetTracker(self.path)
        N = self.settings.horizon
        # lambda_k, k = 0..N: 1 -> 0 linearly (paper Eq. for the heuristic trajectory).
        self._lam = 1.0 - np.arange(N + 1) / N
        # One batched CasADi call linearizes all N stages.
        if self.settings.discretization == "zoh":
            self._lin_map = _continuous_linearization(self.params, self.options).map(N)
        elif self.settings.substeps == 1 and not self.settings.jit:
            lin = discrete_linearization(self.params, self.options, float(self.settings.dt), "rk4")
            self._lin_map = lin.map(N)
        else:
            lin = _substep_linearization(
                self.params,
                self.options,
                float(self.settings.dt),
                int(self.settings.substeps),
                bool(self.settings.jit),
            )
            self._lin_map = lin.map(N)
        self._counters = {"qp_failures": 0, "fallback_shifted": 0, "fallback_brake": 0}
        self._rescues_at_reset = 0
        self._qp_list: list[TrackingQP] = []  # the QPs solved each period (set by subclasses)
        self._statuses: dict[str, int] = {}
        # Wall time (s) of the parts of the last step: project (nearest point), reference,
        # linearize, build (bounds and QP data), qp (solve), pedal (command), total.
        self.last_timing: dict[str, float] = {}
        self.last_solution: QPSolution | None = None
        self.last_qp_data: QPData | None = None
        self._u_prev = np.zeros(NU)

    # --- protocol --------------------------------------------------------------------------------
    def reset(self, obs: Any) -> None:
        """Start a lap from ``obs``: global search on the plan; clear the counters and memory."""
        self._tracker.reset()
        self._tracker.project(obs.x, obs.y)
        for key in self._counters:
            self._counters[key] = 0
        self._rescues_at_reset = sum(qp.rescues for qp in self._qp_list)
        self._statuses.clear()
        self._shift_buffer: list[np.ndarray] = []
        self.last_solution = None
        s0 = self._tracker.s or 0.0
        ref = self._plan.at_s(np.array([s0]))[0]
        self._u_prev = np.array([self._clip_steer(ref[_PlanTable.DELTA]), ref[_PlanTable.AX]])
        # The actuator's angle is not observed: estimate it by running the lag model on our own
        # commands, starting from the command the plan would have given.
        self._delta_est = float(self._u_prev[U.DELTA])

    def stats(self) -> dict[str, float]:
        """Counters of the lap: ``qp_failures``, ``fallback_shifted``, ``fallback_brake`` and
        ``qp_rescues`` (QPs that OSQP failed and Clarabel was asked to solve; those it solved too
        are not failures)."""
        out = {k: float(v) for k, v in self._counters.items()}
        out["qp_rescues"] = float(sum(qp.rescues for qp in self._qp_list) - self._rescues_at_reset)
        return out

    # --- pieces ----------------------------------------------------------------------------------
    def current_state(self, obs: Any) -> np.ndarray:
        """The model state ``xi_0`` (6,) of the car relative to the plan's line."""
        s, e_y = self._tracker.project(obs.x, obs.y)
        heading = float(self.path.heading(s))
        xi = np.empty(NX)
        xi[X.VX] = obs.vx
        xi[X.VY] = obs.vy
        xi[X.R] = obs.r
        xi[X.EPSI] = _wrap(obs.psi - heading)
        xi[X.EY] = e_y
        xi[X.S] = s
        return xi

    def reference(self, s0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference states, inputs and plan rows for stages k = 0..N, spaced by plan time.

        Returns
        -------
        xi_ref : ndarray, shape (N+1, 6)
            ``[v_x, v_y, r, e_psi, 0, s]`` of the plan at ``t_plan(s0) + k dt``; ``s`` unwrapped
            (it may pass the lap length).
        u_ref : ndarray, shape (N+1, 2)
            The plan's ``[delta, a_x]`` there.
        rows : ndarray, shape (N+1, 10)
            All interpolated plan columns (curvature, pitch, band) there.
        """
        st = self.settings
        t0 = self._plan.time_at(s0)
        times = t0 + st.dt * np.arange(st.horizon + 1)
        s_k = self._plan.s_at_times(times)
        # Stage 0 is the projection itself (interpolating back from time would add round-off).
        s_k = s_k - s_k[0] + s0
        rows = self._plan.at_s(s_k)
        xi_ref = np.zeros((st.horizon + 1, NX))
        xi_ref[:, X.VX] = rows[:, _PlanTable.VX]
        xi_ref[:, X.VY] = rows[:, _PlanTable.VY]
        xi_ref[:, X.R] = rows[:, _PlanTable.R]
        xi_ref[:, X.EPSI] = rows[:, _PlanTable.EPSI]
        xi_ref[:, X.S] = s_k
        u_ref = np.column_stack([rows[:, _PlanTable.DELTA], rows[:, _PlanTable.AX]])
        return xi_ref, u_ref, rows

    def linearize(
        self, xi_bar: np.ndarray, u_bar: np.ndarray, kappa: np.ndarray, theta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Discrete affine models of the N stages in one CasADi call.

        Parameters
        ----------
        xi_bar : ndarray, shape (N, 6)
            Linearization states.
        u_bar : ndarray, shape (N, 2)
            Linearization inputs.
        kappa, theta : ndarray, shape (N,)
            Curvature of the plan's line (1/m) and road pitch (rad) per stage.

        Returns
        -------
        A : (N, 6, 6), B : (N, 6, 2), d : (N, 6)
            ``xi_{k+1} ~= A_k xi_k + B_k u_k + d_k``.
        """
        N = self.settings.horizon
        A, B, d = self._lin_map(xi_bar.T, u_bar.T, kappa[None, :], theta[None, :])
        A = np.asarray(A).reshape(NX, N, NX).transpose(1, 0, 2)
        B = np.asarray(B).reshape(NX, N, NU).transpose(1, 0, 2)
        d = np.asarray(d).T
        if self.settings.discretization == "zoh":
            A, B, d = _zoh(A, B, d, self.settings.dt)
        return A, B, d

    def ax_limits(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``(a_min, a_max)`` on a_x (m/s^2) at states ``xi`` (N, 6).

        The pedal map's full-brake and full-throttle values, the optional floor, and the friction
        left over by the lateral acceleration ``v_x r`` (see :class:`MPCSettings`). The interval
        always contains a_x = 0 when the pedal map allows it, and is never empty.
        """
        st = self.settings
        a_min, a_max = self.pedal_map.limits(xi)
        a_min = np.maximum(a_min, st.ax_min_floor)
        if st.friction_ellipse:
            p = self.params
            a_tot = st.friction_scale * p.peak_acceleration()
            a_long = min(a_tot, st.friction_scale * self.pedal_map.full_brake())
            a_y = xi[:, X.VX] * xi[:, X.R]
            # The g-g ellipse (as in the planner); keep a tenth of a_x's axis even when the
            # lateral demand exceeds the limit.
            room = a_long * np.sqrt(np.maximum(1.0 - (a_y / a_tot) ** 2, 0.01))
            a_min = np.maximum(a_min, -room)
            a_max = np.minimum(a_max, room)
        return np.minimum(a_min, a_max), a_max

    def _apply(self, steer: float, a_x: float, xi0: np.ndarray) -> Command:
        """Record the command (for the rate penalty and the lag estimate) and make it a Command."""
        a, _ = steering_lag_coefficients(self.settings.steer_tau, self.settings.dt)
        self._delta_est = a * self._delta_est + (1.0 - a) * steer
        self._u_prev = np.array([steer, a_x])
        return Command(steer=steer, pedal=float(self.pedal_map.pedal(float(a_x), xi0)))

    def _clip_steer(self, steer: float) -> float:
        lim = self.settings.steer_max
        return min(max(float(steer), -lim), lim)

    def _fallback(self, xi0: np.ndarray, u_ref0: np.ndarray, status: str) -> Command:
        """Shifted previous solution, else safe braking; counts and logs the event."""
        self._counters["qp_failures"] += 1
        self._statuses[status] = self._statuses.get(status, 0) + 1
        # Log the first events of a lap, then every 100th, so a long outage cannot flood the log.
        n_fail = self._counters["qp_failures"]
        level = logging.WARNING if n_fail <= 5 or n_fail % 100 == 0 else logging.DEBUG
        if self._shift_buffer:
            u = self._shift_buffer.pop(0)
            self._counters["fallback_shifted"] += 1
            log.log(
                level,
                "MPC QP failed (%s, failure %d of this lap) at s = %.1f m: applying the shifted "
                "previous solution",
                status,
                n_fail,
                xi0[X.S],
            )
            return self._apply(self._clip_steer(u[U.DELTA]), float(u[U.AX]), xi0)
        self._counters["fallback_brake"] += 1
        log.log(
            level,
            "MPC QP failed (%s, failure %d of this lap) at s = %.1f m and no previous solution "
            "is left: safe braking",
            status,
            n_fail,
            xi0[X.S],
        )
        st = self.settings
        steer = self._clip_steer(
            u_ref0[U.DELTA] - st.fallback_gain_ey * xi0[X.EY] - st.fallback_gain_epsi * xi0[X.EPSI]
        )
        a, _ = steering_lag_coefficients(st.steer_tau, st.dt)
        self._delta_est = a * self._delta_est + (1.0 - a) * steer
        self._u_prev = np.array([steer, 0.0])
        return Command(steer=steer, pedal=float(st.brake_pedal))

    def failure_statuses(self) -> dict[str, int]:
        """How often each solver status caused a fallback in this lap."""
        return dict(self._statuses)

    def _conclude(self, u_plan: np.ndarray | None, status: str, xi0: np.ndarray,
                  u_ref0: np.ndarray) -> Command:  # fmt: skip
        """Apply the first input of a solved plan (keeping the rest for fallbacks), or fall back.

        ``u_plan`` is the optimal input sequence, shape (N, 2), or None when the QP failed.
        """
        if u_plan is None:
            return self._fallback(xi0, u_ref0, status)
        self._shift_buffer = [u_plan[k] for k in range(1, len(u_plan))]
        u0 = u_plan[0]
        return self._apply(self._clip_steer(u0[U.DELTA]), float(u0[U.AX]), xi0)

    def _record_timing(self, t0: float, t1: float, t2: float, t3: float, t3b: float,
                       t4: float) -> None:  # fmt: skip
        """Store the time of each part of the step just taken (s), for the benchmarks."""
        t5 = time.perf_counter()
        self.last_timing = {
            "project": t1 - t0,
            "reference": t2 - t1,
            "linearize": t3 - t2,
            "build": t3b - t3,
            "qp": t4 - t3b,
            "pedal": t5 - t4,
            "total": t5 - t0,
        }


class CoupledMPC(_MPCBase):
    """The paper's coupled MPC: one QP for steering and longitudinal acceleration.

    Parameters
    ----------
    plan : Trajectory
        The planned trajectory; ``plan.path`` is the Frenet reference line.
    params : ModelParams, optional
        Parameters of the control model (default ``ModelParams()``).
    options : ModelOptions, optional
        Effects in the control model (default: drag and longitudinal load transfer).
    pedal_map : PedalMap, optional
        Map between pedal and ``a_x`` (default ``params.pedal``): gives the ``a_x`` bounds and
        turns the solved ``a_x`` into a pedal command.
    track : Track, optional
        Gives the e_y band (track edges relative to the plan, minus half the car width and the
        margin) and the road pitch. Without it the band is open and the road flat.
    settings : MPCSettings, optional
        Horizon, weights, margins, fallbacks, QP settings.
    band : (band_min, band_max), optional
        Override of the e_y band per plan node (or scalars), m.

    Examples
    --------
    >>> from racing_lib.planning.trajectory import Trajectory
    >>> from racing_lib.sim import SimulatedCar
    >>> from racing_lib.model import identified_params
    >>> from racing_lib.geometry import load_track
    >>> track = load_track("shortcut")
    >>> params = identified_params()
    >>> plan = Trajectory.from_centerline(track, params=params.replace(mu=1.0))
    >>> mpc = CoupledMPC(plan, params=params, track=track)
    >>> car = SimulatedCar(track, start_speed=float(plan.vx[0]))
    >>> obs = car.reset(seed=0)
    >>> mpc.reset(obs)
    >>> cmd = mpc.step(obs)
    >>> bool(-1.0 <= cmd.pedal <= 1.0 and abs(cmd.steer) <= mpc.settings.steer_max)
    True
    >>> mpc.stats()
    {'qp_failures': 0.0, 'fallback_shifted': 0.0, 'fallback_brake': 0.0, 'qp_rescues': 0.0}

    A whole lap: ``racing_lib.experiment.run_lap(car, mpc, plan, track=track, seed=0)``.
    """

    def __init__(self, plan: Any, params: Any = None, options: Any = None, pedal_map: Any = None,
                 track: Any = None, settings: MPCSettings | None = None,
                 band: tuple[np.ndarray, np.ndarray] | None = None) -> None:  # fmt: skip
        super().__init__(plan, params, options, pedal_map, track, settings, band)
        st = self.settings
        shape = QPShape.make(
            n_state=len(MX),
            n_input=NU,
            horizon=st.horizon,
            state_weights=st.state_weights(),
            rate_weights=[st.w_ddelta, st.w_dax],
            rate_limits=[st.steer_rate_max * st.dt, np.inf],
            band_index=MX.EY,
            slack_linear=st.slack_linear,
            slack_quadratic=st.slack_quadratic,
        )
        self.qp = TrackingQP(shape, st.qp)
        self._qp_list = [self.qp]
        self._lam_used = self._lam if st.smooth_transition else np.zeros_like(self._lam)
        self._shift_buffer = []

    @property
    def blend_weights(self) -> np.ndarray:
        """``lambda_k``, k = 0..N, of the heuristic trajectory: 1 falling linearly to 0 (all 0
        without the smooth transition), shape (N+1,)."""
        return self._lam_used.copy()

    def heuristic_trajectory(self, xi0: np.ndarray, xi_ref: np.ndarray) -> np.ndarray:
        """The states the model is linearized at: ``xi_hat_k = xi_ref_k + lambda_k (xi0 -
        xi_ref_0)`` (the paper's heuristic trajectory).

        Parameters
        ----------
        xi0 : ndarray (6,)
            The car's state (order of :class:`racing_lib.model.X`).
        xi_ref : ndarray (N+1, 6)
            The plan at stages 0..N (:meth:`reference`).

        Returns
        -------
        ndarray (N+1, 6)
            From the measured state at stage 0 to the plan at stage N.
        """
        return xi_ref + self._lam_used[:, None] * (xi0 - xi_ref[0])[None, :]

    def step(self, obs: Any) -> Command:
        """One control period: project, build the QP along the heuristic trajectory, solve."""
        st = self.settings
        N = st.horizon
        t0 = time.perf_counter()
        xi0 = self.current_state(obs)
        t1 = time.perf_counter()
        xi_ref, u_ref, rows = self.reference(xi0[X.S])
        xi_hat = self.heuristic_trajectory(xi0, xi_ref)
        # The same transition for the inputs, from the last command to the plan's: linearizing
        # at the plan's steering while the front tires are working at a very different angle
        # gets the sign of the tire-force slope wrong when the car is near the grip limit.
        u_hat = u_ref + self._lam_used[:, None] * (self._u_prev - u_ref[0])[None, :]
        kappa = rows[:N, _PlanTable.KAPPA]
        theta = rows[:N, _PlanTable.THETA]
        # State-dependent a_x limits at the heuristic states, stages 0..N-1.
        a_min, a_max = self.ax_limits(xi_hat[:N])
        u_min = np.column_stack([np.full(N, -st.steer_max), a_min])
        u_max = np.column_stack([np.full(N, st.steer_max), a_max])
        # Linearize only at inputs the QP may choose: after a hard brake (or a fallback) the last
        # a_x can lie far outside this step's bounds, and the tyre slopes there made the
        # prediction unstable enough for OSQP to report the QP infeasible.
        u_lin = np.clip(u_hat[:N], u_min, u_max)
        t2 = time.perf_counter()
        A, B, d = self.linearize(xi_hat[:N], u_lin, kappa, theta)
        t3 = time.perf_counter()
        idx = _COUPLED_STATES
        A_q, B_q, d_q = augment_steering_lag(
            A[:, idx[:, None], idx[None, :]], B[:, idx, :], d[:, idx], U.DELTA, st.steer_tau, st.dt
        )
        x_ref = np.zeros((N, len(MX)))
        x_ref[:, : len(idx)] = xi_ref[1:, idx]
        data = QPData(
            x0=np.append(xi0[idx], self._delta_est),
            A=A_q,
            B=B_q,
            d=d_q,
            x_ref=x_ref,
            u_prev=self._u_prev,
            u_min=u_min,
            u_max=u_max,
            band_min=rows[1:, _PlanTable.BMIN],
            band_max=rows[1:, _PlanTable.BMAX],
        )
        t3b = time.perf_counter()
        sol = self.qp.solve(data)
        t4 = time.perf_counter()
        self.last_qp_data = data
        self.last_solution = sol
        cmd = self._conclude(sol.u if sol.success else None, sol.status, xi0, u_ref[0])
        self._record_timing(t0, t1, t2, t3, t3b, t4)
        return cmd


class DecoupledMPC(_MPCBase):
    """The baseline of the paper's controller ablation: separate longitudinal and lateral MPCs.

    The longitudinal MPC chooses ``a_x`` to track the reference ``v_x`` with the ``v_x`` row of the
    model linearized about the reference (steering, lateral states at their reference values); the
    lateral MPC chooses ``delta`` to track ``[v_y, r, e_psi, e_y]`` assuming ``v_x`` and ``a_x``
    follow the reference. Both are linearized about the reference trajectory only (no heuristic
    transition). Parameters as for :class:`CoupledMPC`.
    """

    def __init__(self, plan: Any, params: Any = None, options: Any = None, pedal_map: Any = None,
                 track: Any = None, settings: MPCSettings | None = None,
                 band: tuple[np.ndarray, np.ndarray] | None = None) -> None:  # fmt: skip
        super().__init__(plan, params, options, pedal_map, track, settings, band)
        st = self.settings
        w = st.state_weights()
        self.qp_lon = TrackingQP(
            QPShape.make(1, 1, st.horizon, state_weights=w[:, [MX.VX]], rate_weights=[st.w_dax]),
            st.qp,
        )
        self.qp_lat = TrackingQP(
            QPShape.make(
                5,
                1,
                st.horizon,
                state_weights=w[:, [MX.VY, MX.R, MX.EPSI, MX.EY, MX.DELTA]],
                rate_weights=[st.w_ddelta],
                rate_limits=[st.steer_rate_max * st.dt],
                band_index=3,
                slack_linear=st.slack_linear,
                slack_quadratic=st.slack_quadratic,
            ),
            st.qp,
        )
        self._qp_list = [self.qp_lon, self.qp_lat]
        self._shift_buffer = []

    def step(self, obs: Any) -> Command:
        """One control period: two QPs linearized about the reference, then apply both inputs."""
        st = self.settings
        N = st.horizon
        t0 = time.perf_counter()
        xi0 = self.current_state(obs)
        t1 = time.perf_counter()
        xi_ref, u_ref, rows = self.reference(xi0[X.S])
        kappa = rows[:N, _PlanTable.KAPPA]
        theta = rows[:N, _PlanTable.THETA]
        t2 = time.perf_counter()
        A, B, d = self.linearize(xi_ref[:N], u_ref[:N], kappa, theta)
        t3 = time.perf_counter()
        a_min, a_max = self.ax_limits(xi_ref[:N])
        xr, ur = xi_ref[:N], u_ref[:N]
        # Longitudinal: v_x only; everything else frozen at the reference (moved into d).
        vx = int(X.VX)
        others = np.array([i for i in range(NX) if i != vx])
        d_lon = (
            d[:, vx]
            + np.einsum("kj,kj->k", A[:, vx, others], xr[:, others])
            + B[:, vx, U.DELTA] * ur[:, U.DELTA]
        )
        lon = QPData(
            x0=xi0[[vx]],
            A=A[:, [vx]][:, :, [vx]],
            B=B[:, [vx]][:, :, [U.AX]],
            d=d_lon[:, None],
            x_ref=xi_ref[1:, [vx]],
            u_prev=self._u_prev[[U.AX]],
            u_min=a_min[:, None],
            u_max=a_max[:, None],
        )
        # Lateral: v_y, r, e_psi, e_y with v_x and a_x at the reference; s dropped as before.
        lat_idx = _LATERAL_STATES
        frozen = np.array([X.VX, X.S])
        d_lat = (
            d[:, lat_idx]
            + np.einsum("kij,kj->ki", A[:, lat_idx[:, None], frozen[None, :]], xr[:, frozen])
            + B[:, lat_idx, U.AX] * ur[:, [U.AX]]
        )
        A_lat, B_lat, d_lat = augment_steering_lag(
            A[:, lat_idx[:, None], lat_idx[None, :]],
            B[:, lat_idx][:, :, [U.DELTA]],
            d_lat,
            0,
            st.steer_tau,
            st.dt,
        )
        x_ref_lat = np.zeros((N, len(lat_idx) + 1))
        x_ref_lat[:, : len(lat_idx)] = xi_ref[1:, lat_idx]
        lat = QPData(
            x0=np.append(xi0[lat_idx], self._delta_est),
            A=A_lat,
            B=B_lat,
            d=d_lat,
            x_ref=x_ref_lat,
            u_prev=self._u_prev[[U.DELTA]],
            u_min=np.full((N, 1), -st.steer_max),
            u_max=np.full((N, 1), st.steer_max),
            band_min=rows[1:, _PlanTable.BMIN],
            band_max=rows[1:, _PlanTable.BMAX],
        )
        t3b = time.perf_counter()
        sol_lon = self.qp_lon.solve(lon)
        sol_lat = self.qp_lat.solve(lat)
        t4 = time.perf_counter()
        self.last_solution = sol_lat
        ok = sol_lon.success and sol_lat.success
        u = np.column_stack([sol_lat.u[:, 0], sol_lon.u[:, 0]]) if ok else None
        status = sol_lat.status if not sol_lat.success else sol_lon.status
        cmd = self._conclude(u, status, xi0, u_ref[0])
        self._record_timing(t0, t1, t2, t3, t3b, t4)
        return cmd
