"""The minimum-lap-time NLP's settings and the result it returns."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from racing_lib.errors import PlanningError
from racing_lib.planning.grid import DEFAULT_CAR_WIDTH, TrackGrid
from racing_lib.planning.trajectory import Trajectory

__all__ = ["IpoptSettings", "TimeOptimalResult", "TimeOptimalSettings"]


class IpoptSettings(Protocol):
    """What a planner's settings tell IPOPT: :class:`TimeOptimalSettings`, ``BestLapSettings``."""

    @property
    def print_level(self) -> int:
        """IPOPT's print level (0: silent)."""

    @property
    def max_iter(self) -> int:
        """Most IPOPT iterations."""

    @property
    def tol(self) -> float:
        """IPOPT's convergence tolerance."""

    @property
    def ipopt_options(self) -> tuple[tuple[str, str | float], ...]:
        """Further IPOPT options, (name, value) pairs; they override the planner's."""


@dataclass(frozen=True)
class TimeOptimalSettings:
    """Settings of the minimum-lap-time NLP.

    Attributes
    ----------
    spacing : float
        Node spacing along the centerline, m.
    w_ddelta : float
        Weight of the steering-rate regularization ``sum_k ((delta_{k+1} - delta_k) / ds_k)^2 ds_k``
        (rad^2/m), in seconds per rad^2/m.
    w_dax : float
        Weight of the same regularization of ``a_x`` (``sum_k (a_{x,k+1} - a_{x,k})^2 / ds_k``,
        (m/s^2)^2/m), in seconds per (m/s^2)^2/m. Trapezoidal collocation fixes only the mean of
        two neighbouring nodes' derivatives, so where the speed rides a bound (the top speed) the
        optimum left ``a_x`` free to alternate node by node (0.09 and 0.78 m/s^2 on the
        expressway's straight, +-1.5 m/s^2 for a car without drag): a pedal that the tracking
        controller then flicked every control period. Any positive weight removes that freedom;
        this one costs a braking point a few milliseconds.
    max_iter : int
        IPOPT iteration limit per solve.
    tol : float
        IPOPT convergence tolerance (on the scaled problem).
    car_width : float
        Body width, m.
    margin : float or None
        Clearance to the track edge, m (None: WALL_MARGIN with walls, OPEN_MARGIN open, both 0.8).
    delta_max : float
        Steering angle bound, rad.
    v_min : float
        Lower bound on v_x, m/s (keeps the lap-time integrand finite).
    e_psi_max : float
        Bound on the heading error to the centerline, rad.
    slip_limit : bool
        Bound the slip angles on the rising side of the tyre curves (below the Pacejka peak).
    slip_force_share : float
        The bound is the slip angle where the tyre force reaches this share of its peak
        (:meth:`racing_lib.model.ModelParams.slip_angle_at`; 1 = the peak itself). The identified
        curves are broad (C about 1.2): at the peak the rear slips 7.7 degrees, and plans used
        it to rotate the car into corners while braking at the limit, a drift the car's tyres,
        which lose lateral grip when they brake, cannot hold (Oschersleben: 32 s off the track).
        95 % of the peak force comes at about half that slip.
    friction_ellipse : bool
        Couple a_x and a_y through the friction ellipse.
    drive_axle_circle : bool
        Keep the drive force and the rear lateral force inside the rear tyres' friction circle
        (the car is rear-wheel driven): without it the plan accelerates out of corners harder
        than the car's traction control allows.
    uncertainty_margin : float
        With a learned model correction (:class:`racing_lib.model.ModelCorrection`): how many
        posterior standard deviations of the learned accelerations (longitudinal and lateral,
        each on its axis of the ellipse) the plan keeps inside the friction ellipse, node by
        node. Where the laps it learned from went, the correction
        is sure and the plan may go close to the limit; where they did not, it keeps away. No
        effect on a model without a correction.
    lateral_stability : float or None
        Keep the plan where the model's lateral dynamics are stable, and where braking has
        not brought one of their eigenvalues to within ``lateral_stability`` (1/s) of zero: at
        every node the determinant and trace of their linearization say stable, and the
        determinant shifted by the margin keeps both eigenvalues on one side of
        ``-lateral_stability`` (:func:`racing_lib.model.lateral_eigenvalue_test`). A car that
        oversteers under braking diverges by itself in the plan's braking zones, faster than a
        rate-limited steering can catch it, and the time-optimal plan goes there, since in the
        model it costs nothing. None (default): no such rows, as in the paper;
        :func:`racing_lib.planning.plan` takes the model's
        (:attr:`racing_lib.model.CarModel.lateral_stability`) with its steering rate. Set here,
        set ``steer_rate`` too: without it the optimum weaves (see there).
    steer_rate : float or None
        The steering actuator's rate limit, rad/s: between two nodes the steering angle changes
        by at most this times the time the car takes from one to the other. None (default): no
        such row (the steering-rate weight ``w_ddelta`` regularizes alone, as in the paper);
        :func:`racing_lib.planning.plan` takes the model's ``steer_rate_max`` for a model with
        a lateral stability margin, whose plans otherwise weave (see ``lateral_stability``).
    pedal_limits : {"iterate", "exact"}
        How the state-dependent a_x limits are imposed (see the module docstring).
    max_outer : int
        Maximum number of solves with updated a_x limits ("iterate").
    outer_tol : float
        The a_x limits have settled when they move less than this, m/s^2.
    v_top : float or None
        Top speed, m/s: the bound on the car's speed ``sqrt(v_x^2 + v_y^2)``. None: the model's
        top speed under :func:`racing_lib.planning.plan` (``CarModel.v_top``), 190 km/h when the
        solver is called directly. Given here, it replaces the model's.
    print_level : int
        IPOPT's print level (0 silent).
    graph : {"structured", "sx", "mx"}
        How the NLP and its derivatives are built. ``"structured"`` (default): one interval's
        functions are differentiated symbolically and mapped over the grid
        (:mod:`racing_lib.planning.time_optimal_nlp`); built in a fraction of a second.
        ``"sx"``: the whole lap as one SX graph that CasADi differentiates (6-9 s to build for
        the expressway's 1,464 nodes, the same iterations); ``"mx"``: an MX graph over the
        mapped node function (fast to build, several times slower per iteration). Both are kept
        to check the structured derivatives.
    jit : bool
        Compile the derivatives of one interval (Jacobian, gradient, Hessian of the Lagrangian)
        with the system C compiler: about a second, once per parameter set, options and settings
        (the build is cached on disk, :mod:`racing_lib.jit`). IPOPT evaluates them at every
        iteration, and compiled they cost a fraction of what CasADi's interpreter takes: a solve
        takes about half the time, to the same plan bit for bit. Falls back to the interpreter,
        with one warning, when no compiler works (or on Windows). Used by
        ``graph="structured"`` only.
    mu_min : float
        Smallest friction coefficient accepted (ice is about 0.1); below it the parameters are
        taken for a mistake and :class:`PlanningError` is raised before solving.
    ipopt_options : tuple of (name, value)
        Extra IPOPT options, e.g. ``(("mu_init", 1e-3),)`` (a tuple so the settings stay hashable).
    """

    spacing: float = 3.0
    w_ddelta: float = 1.0
    w_dax: float = 1e-4
    max_iter: int = 1000
    tol: float = 1e-6
    car_width: float = DEFAULT_CAR_WIDTH
    margin: float | None = None
    delta_max: float = 0.5
    v_min: float = 3.0
    e_psi_max: float = 1.0
    slip_limit: bool = True
    slip_force_share: float = 0.95
    friction_ellipse: bool = True
    drive_axle_circle: bool = True
    uncertainty_margin: float = 2.0
    lateral_stability: float | None = None
    steer_rate: float | None = None
    pedal_limits: str = "exact"
    max_outer: int = 4
    outer_tol: float = 0.05
    v_top: float | None = None
    print_level: int = 0
    ipopt_options: tuple[tuple[str, str | float], ...] = ()
    mu_min: float = 0.1
    graph: str = "structured"
    jit: bool = True

    def __post_init__(self) -> None:
        _check_bound("lateral_stability", self.lateral_stability, "1/s", zero_ok=True)
        _check_bound("steer_rate", self.steer_rate, "rad/s", zero_ok=False)


def _check_bound(name: str, value: object, unit: str, zero_ok: bool) -> None:
    """Refuse a bound that is not None or a finite number >= 0 (> 0 unless ``zero_ok``)."""
    if value is None:
        return
    number = isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)
    if not number or not math.isfinite(value) or value < 0.0 or (value == 0.0 and not zero_ok):
        rule = ">= 0" if zero_ok else "> 0"
        raise PlanningError(
            f"TimeOptimalSettings.{name} must be a finite number {rule} {unit}, or None for no "
            f"bound; got {value!r}."
        )


@dataclass
class TimeOptimalResult:
    """Result of :func:`solve_time_optimal`.

    Attributes
    ----------
    success : bool
        IPOPT converged (``Solve_Succeeded`` or ``Solved_To_Acceptable_Level``) in the last solve
        and the a_x limits settled.
    status : str
        IPOPT's ``return_status`` of the last solve.
    iterations : int
        IPOPT iterations, summed over the outer solves.
    solve_time : float
        Wall time of the solves, s.
    evaluation_time : float
        The part of ``solve_time`` spent evaluating the NLP's functions and derivatives, s; the
        rest is IPOPT's own work, mostly factorizing its linear systems (MUMPS).
    build_time : float
        Wall time to build the CasADi problem (0 when it came from the cache), s.
    outer_iterations : int
        Number of solves with updated a_x limits.
    trajectory : Trajectory or None
        The plan (None only when no solve produced finite numbers).
    lap_time : float
        Planned lap time, s.
    start : str
        ``'warm'`` (from the curvature plan), ``'cold'`` (centerline at 10 m/s) or ``'given'``.
    iterations_per_solve : list of int
        IPOPT iterations of each outer solve.
    grid : TrackGrid
        The planning grid.
    solution : dict
        Arrays on the grid: v_x, v_y, r, e_psi, e_y, delta, a_x, dt (the interval times).
    """

    success: bool
    status: str
    iterations: int
    solve_time: float
    build_time: float
    outer_iterations: int
    trajectory: Trajectory | None
    lap_time: float
    start: str
    iterations_per_solve: list[int] = field(default_factory=list)
    grid: TrackGrid | None = None
    solution: dict[str, np.ndarray] = field(default_factory=dict)
    evaluation_time: float = 0.0
