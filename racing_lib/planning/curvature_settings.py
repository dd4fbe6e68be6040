"""The curvature-optimal QP's settings and result (the planner is :mod:`.curvature`).

Kept apart from the iteration, as :mod:`.time_optimal_settings` is for the NLP, so that the
planner's module holds the algorithm.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from racing_lib.planning.grid import DEFAULT_CAR_WIDTH, TrackGrid
from racing_lib.planning.trajectory import Trajectory

__all__ = ["CurvatureResult", "CurvatureSettings"]


@dataclass(frozen=True)
class CurvatureSettings:
    """Settings of the curvature-optimal QP.

    Attributes
    ----------
    spacing : float
        Node spacing along the centerline, m.
    w_vy : float
        Weight of the squared side-slip angle (v_y / v_hat)^2 (the paper's w_1), dimensionless.
    w_ddelta : float
        Weight of the squared steering change (delta_k - delta_{k-1})^2 (the paper's w_2),
        dimensionless.
    speed_fraction : float
        v_hat = this fraction of the speed profile (see the module docstring), dimensionless.
    max_iterations : int
        Maximum number of QPs.
    tol : float
        Stop ('converged') when the line moves less than this between iterations (max |Delta e_y|),
        m.
    car_width : float
        Body width of the car, m.
    margin : float or None
        Clearance to the track edge, m (None: WALL_MARGIN with walls, OPEN_MARGIN on an open
        track, both 0.8).
    delta_max : float
        Steering angle bound, rad.
    v_top : float or None
        Top speed for the speed profile, m/s. None: the model's top speed under
        :func:`racing_lib.planning.plan` (``CarModel.v_top``), 190 km/h when the solver is called
        directly. Given here, it replaces the model's.
    osqp_eps : float
        OSQP's absolute and relative tolerance (when ``solver="OSQP"``).
    solver : str
        QP solver through cvxpy: ``"CLARABEL"`` (default) or ``"OSQP"``. Both give the same lines;
        Clarabel (interior point) is faster here: on Norisring (4 m grid, 574 nodes, no proximal
        term) about 0.25 s per QP against 3 s for OSQP at eps 1e-6, whose ADMM iterations crawl
        along the long periodic chain of dynamics; with the proximal term the whole iteration took
        11 s (Clarabel) against 18 s (OSQP) on a 3 m grid.
    relaxation : float
        Under-relaxation of v_hat between iterations (1 = take the new speed profile whole).
    w_prox : float
        Weight of (e_y - e_y,prev)^2, 1/m^2: a tie-breaker for straights, where the curvature does
        not care where the line lies.
    line_step : float
        After ``full_steps`` iterations the line moves only this fraction of the way to the new QP
        solution (damped fixed-point iteration).
    full_steps : int
        Number of undamped iterations at the start.
    lap_tol : float
        An iteration counts as an improvement if it lowers the speed-profile lap time by more than
        this, s.
    patience : int
        Stop ('settled') after this many iterations without improvement; the fastest line found is
        returned.
    """

    spacing: float = 3.0
    w_vy: float = 0.015
    w_ddelta: float = 0.01
    speed_fraction: float = 0.9
    max_iterations: int = 25
    tol: float = 0.1
    car_width: float = DEFAULT_CAR_WIDTH
    margin: float | None = None
    delta_max: float = 0.5
    v_top: float | None = None
    osqp_eps: float = 1e-4
    solver: str = "CLARABEL"
    relaxation: float = 0.5
    line_step: float = 0.5
    full_steps: int = 3
    lap_tol: float = 0.02
    patience: int = 3
    w_prox: float = 1e-6


@dataclass
class CurvatureResult:
    """Result of :func:`solve_curvature`.

    Attributes
    ----------
    success : bool
        True when the iteration stopped by itself ('converged' or 'settled').
    status : str
        'converged' (the line stopped moving), 'settled' (its lap time stopped improving), or
        'max_iterations'.
    iterations : int
        Number of QPs solved.
    solve_time : float
        Wall time of the whole iteration (linearizations, QPs, speed profiles), s.
    qp_time : float
        Time spent inside cvxpy/OSQP (compilation and solve), s.
    trajectory : Trajectory
        The fastest line found, driven at its full speed profile.
    history : list of float
        Max |Delta e_y| of each iteration, m.
    lap_times : list of float
        Speed-profile lap time of the line after each iteration, s.
    e_y, e_psi, v_y, r, delta : ndarray (N,)
        The last QP's solution on the grid (Frenet states relative to the centerline).
    v_x, a_x : ndarray (N,)
        Speed profile of the final line (m/s) and its acceleration (m/s^2) on the grid.
    grid : TrackGrid
        The grid the QP was solved on.
    """

    success: bool
    status: str
    iterations: int
    solve_time: float
    qp_time: float
    trajectory: Trajectory
    history: list[float] = field(default_factory=list)
    lap_times: list[float] = field(default_factory=list)
    e_y: np.ndarray | None = None
    e_psi: np.ndarray | None = None
    v_y: np.ndarray | None = None
    r: np.ndarray | None = None
    delta: np.ndarray | None = None
    v_x: np.ndarray | None = None
    a_x: np.ndarray | None = None
    grid: TrackGrid | None = None
