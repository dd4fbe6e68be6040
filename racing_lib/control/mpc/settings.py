"""The MPC's settings (weights, horizon, limits) and the index of its state vector."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from racing_lib.control.mpc.qp_problem import (
    QPSettings,
)
from racing_lib.errors import ControlError
from racing_lib.model import X
from racing_lib.vehicle.params import VehicleParams

#: The car whose data sheet gives the defaults of the car's dimensions and actuator.
_CAR = VehicleParams()

__all__ = ["COUPLED_SLICE", "COUPLED_STATES", "LATERAL_STATES", "MX", "MPCSettings"]


class MX(IntEnum):
    """Indices of the coupled MPC's state.

    The model's state without ``s``, plus the steering actuator's output (see
    :func:`~racing_lib.control.mpc.linearize.augment_steering_lag`).
    """

    VX = 0  #: longitudinal velocity, m/s
    VY = 1  #: lateral velocity, m/s
    R = 2  #: yaw rate, rad/s
    EPSI = 3  #: heading error to the plan's line, rad
    EY = 4  #: lateral offset from the plan's line, m
    DELTA = 5  #: actual steering angle behind the actuator lag, rad (estimated, not weighted)


#: The coupled MPC's states within the model's state: the first five, in :class:`MX` order (a
#: slice, so that selecting them takes views rather than copies).
COUPLED_SLICE = slice(X.VX, X.EY + 1)
#: Model-state indices of the coupled MPC's states, in :class:`MX` order.
COUPLED_STATES = np.arange(len(X))[COUPLED_SLICE]
#: Model-state indices of the lateral MPC's states (v_y, r, e_psi, e_y).
LATERAL_STATES = np.array([X.VY, X.R, X.EPSI, X.EY])


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
    smooth_transition : bool
        Linearize along the heuristic trajectory (True, the paper's method) or along the reference
        itself (False: all lambda_k = 0, the ablation). Used by
        :class:`~racing_lib.control.mpc.coupled.CoupledMPC` only.
    throttle_scale, brake_scale : float
        Factors on the pedal map's full-throttle and full-brake accelerations (``m_thr``,
        ``m_brk``) inside the MPC, for both the a_x bounds and the pedal inverse (1 = the map as
        given). Below 1 when the map promises more than the car delivers: measured on the
        simulated car, full brake at 40-50 m/s gave about 10.4 m/s^2 where the identified map
        says 12.2, and a controller that believes the map brakes too late.
    friction_ellipse : bool
        Bound a_x also by the friction left over from cornering, the planner's g-g ellipse:
        ``|a_x| <= a_brake sqrt(1 - (a_y / a_peak)^2)`` with ``a_y`` the lateral acceleration
        reserved for cornering: ``v_x r`` of the states the QP is built at (for the coupled
        MPC, the smaller of that and what the plan's line needs at that speed:
        :meth:`~racing_lib.control.mpc.coupled.CoupledMPC.reserved_lateral_acceleration`),
        ``a_peak = friction_scale mu D g`` (``D`` the smaller Pacejka peak factor)
        and ``a_brake`` the pedal map's full brake (scaled alike, at most ``a_peak``). The
        model's tyres do not know that braking costs lateral grip; the car's do, and a
        controller that brakes fully into a hairpin (as the plan may ask when the car arrives
        too fast) understeers into the wall.
        This is the planner's friction ellipse, made a state-dependent input bound like the
        paper's pedal limits.
    friction_scale : float
        Fraction of the model's peak friction the ellipse allows (dimensionless).
    ax_min_floor : float
        Lower bound on a_x in any case, m/s^2 (-inf: the pedal map alone decides). The linear
        pedal map keeps promising more deceleration at full brake than the tyres give: on the
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
        the model's :func:`~racing_lib.model.discretize` chained, and the exact Jacobians of that
        nonlinear discrete map (so the affine model is exact to first order). ``"zoh"``: the exact
        discretization of the continuous-time linearization with the input held (a matrix
        exponential of the model's Jacobians); stable at any speed, but only an O(dt^2)
        approximation of the nonlinear step away from equilibria.
    substeps : int
        RK4 steps per period for ``"rk4"``. One RK4 step of 0.1 s is unstable for the tyre modes
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
    # The car's body: by default the simulated car's data sheet. Its steering actuator (lag,
    # angle and rate limits) is part of the model the MPC predicts with (racing_lib.model.CarModel).
    car_width: float = _CAR.width
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

    def state_weights(self) -> np.ndarray:
        """Per-stage weights of the coupled states, shape (N, 6) (the last stage scaled).

        The actual steering angle (:attr:`MX.DELTA`) has weight 0: it is a state of the
        actuator, not a tracking target.
        """
        w = np.array([self.w_vx, self.w_vy, self.w_r, self.w_epsi, self.w_ey, 0.0], dtype=float)
        out = np.tile(w, (self.horizon, 1))
        out[-1] *= self.terminal_factor
        return out
