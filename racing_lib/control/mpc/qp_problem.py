"""The QP inside every MPC of racing_lib: linear time-varying tracking with a soft band.

One QP (the data and settings here), two implementations that must agree (a test checks it):

* :class:`~racing_lib.control.mpc.qp_cvxpy.CvxpyTrackingQP` writes the problem as it reads on
  paper, with cvxpy ``Parameter`` objects (DPP, so cvxpy compiles it once) and OSQP underneath.
  It is the reference: easy to read, slow (cvxpy spends several ms per solve in its own
  bookkeeping; 20-50 ms measured here).
* :class:`~racing_lib.control.mpc.qp_osqp.TrackingQP` builds OSQP's matrices once with a fixed
  sparsity pattern and, at each control step, only overwrites their values
  (``update(Ax=..., q=..., l=..., u=...)``) and warm-starts from the previous solution: 0.5-0.8 ms
  median for the coupled MPC's 6 states, 2 inputs and 20-30 stages (including the numeric
  refactorization that new matrix values require).

The problem, over a horizon of ``N`` stages (``x_0`` given, ``u_{-1}`` the last applied input)::

    minimize   sum_{k=1..N} ||x_k - x_ref_k||^2_W            (state tracking)
             + sum_{k=0..N-1} ||u_k - u_{k-1}||^2_{W_du}      (input rate, e.g. steering rate)
             + sum_{k=0..N-1} ||u_k - u_ref_k||^2_{W_u}       (input deviation, usually zero)
             + sum_{k=1..N} rho_1 eps_k + rho_2 eps_k^2        (slack of the soft band)
    subject to x_{k+1} = A_k x_k + B_k u_k + d_k,              k = 0..N-1
               band_min_k - eps_k <= x_k[band] <= band_max_k + eps_k,  eps_k >= 0,   k = 1..N
               u_min_k <= u_k <= u_max_k,                      k = 0..N-1
               |u_k - u_{k-1}| <= rate_max,                    k = 0..N-1 (optional, per input)

The band (the track edges on e_y) is soft, so the QP is feasible whatever the state: a car that
already crossed the band pays the slack penalty instead of making the problem infeasible. Input
bounds are hard (they always admit a solution: the dynamics are equalities without other
constraints). The optional rate limit (the steering actuator's slew rate) is hard too: with
``u_{-1}`` inside a constant box it always admits a solution. Taught in notebook 05 (the coupled
MPC).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from racing_lib.errors import ControlError

__all__ = [
    "SOLVED_STATUSES",
    "QPData",
    "QPSettings",
    "QPShape",
    "QPSolution",
    "StepQP",
    "check_qp_data",
    "failed_solution",
    "tracking_cost",
]

#: OSQP statuses that count as a usable solution.
SOLVED_STATUSES = frozenset({"solved", "solved inaccurate"})


@dataclass(frozen=True)
class QPSettings:
    """OSQP settings of the fast path (the cvxpy reference uses its own, tighter ones).

    Attributes
    ----------
    eps_abs, eps_rel : float
        Absolute and relative tolerances of OSQP's termination criteria (dimensionless, in the
        units of the scaled problem).
    max_iter : int
        ADMM iteration cap; a solve that hits it reports ``"maximum iterations reached"``.
    rescue : bool
        When OSQP fails, solve the same QP once more with Clarabel, an interior-point solver, and
        use its answer. The QPs of a car near the edge of the track with its soft band active, or
        sliding, are badly conditioned for ADMM: on the expressway some needed 2,000-20,000 OSQP
        iterations (15-150 ms) where a normal step needs 25-100, a few were declared "primal
        infeasible" although the soft band keeps every instance feasible, and they came in runs of
        consecutive periods, which the shifted previous solution cannot bridge safely. Clarabel
        solved each of them in 12-20 iterations and 4-6 ms. Only a QP that both solvers fail
        counts as a failure.
    polish : bool
        Run OSQP's solution polishing (an extra factorization: more accurate active set, slower).
    warm_start : bool
        Start each solve from the previous primal/dual solution (consecutive MPC problems are
        close).
    adaptive_rho : bool
        Let OSQP adapt its step size rho (recommended).
    adaptive_rho_interval : int
        Iterations between rho updates. Fixed (not OSQP's default 0, which times the setup and
        so makes results depend on the machine's load): the closed loop is then bit-for-bit
        reproducible.
    check_termination : int
        Check the termination criteria every this many iterations.
    accept_inaccurate : bool
        Treat ``"solved inaccurate"`` as a success (its solution is still a good control).
    """

    eps_abs: float = 1e-4
    eps_rel: float = 1e-4
    max_iter: int = 1000
    rescue: bool = True
    polish: bool = False
    warm_start: bool = True
    adaptive_rho: bool = True
    adaptive_rho_interval: int = 25
    check_termination: int = 10
    accept_inaccurate: bool = True


@dataclass
class QPData:
    """The numbers of one QP instance (everything that changes from one control step to the next).

    Shapes use N = horizon, n = number of states, m = number of inputs.

    Attributes
    ----------
    x0 : ndarray, shape (n,)
        Current (measured) state.
    A : ndarray, shape (N, n, n)
        Discrete state matrices A_k, k = 0..N-1.
    B : ndarray, shape (N, n, m)
        Discrete input matrices B_k.
    d : ndarray, shape (N, n)
        Affine terms d_k of the linearization.
    x_ref : ndarray, shape (N, n)
        Reference states for stages 1..N.
    u_prev : ndarray, shape (m,)
        The input applied in the previous control period (u_{-1} of the rate penalty).
    u_min, u_max : ndarray, shape (N, m)
        Input bounds per stage (use +-inf for none).
    band_min, band_max : ndarray, shape (N,), optional
        Soft band on the band state for stages 1..N (ignored if the QP has no band).
    u_ref : ndarray, shape (N, m), optional
        Input reference of the input-deviation term (zero if omitted).
    """

    x0: np.ndarray
    A: np.ndarray
    B: np.ndarray
    d: np.ndarray
    x_ref: np.ndarray
    u_prev: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    band_min: np.ndarray | None = None
    band_max: np.ndarray | None = None
    u_ref: np.ndarray | None = None


@dataclass
class QPSolution:
    """Result of one QP solve.

    Attributes
    ----------
    success : bool
        True when the solver status is a usable solution.
    status : str
        The solver's own status string (for example ``"solved"``, ``"maximum iterations reached"``).
    x : ndarray, shape (N, n)
        Predicted states x_1..x_N (NaN when not successful).
    u : ndarray, shape (N, m)
        Inputs u_0..u_{N-1} (NaN when not successful).
    slack : ndarray, shape (N,)
        Band slack eps_1..eps_N, in the band state's unit (zeros if the QP has no band).
    iterations : int
        Solver iterations.
    solve_time : float
        Wall time of the solve call, s.
    objective : float
        Optimal cost without the constant terms (comparable between implementations only up to a
        constant; use :func:`tracking_cost` for the full cost).
    """

    success: bool
    status: str
    x: np.ndarray
    u: np.ndarray
    slack: np.ndarray
    iterations: int = 0
    solve_time: float = 0.0
    objective: float = float("nan")


@dataclass(frozen=True)
class QPShape:
    """The fixed structure of a tracking QP: sizes, weights and which state carries the band.

    Attributes
    ----------
    n_state, n_input, horizon : int
        n, m and N.
    state_weights : ndarray, shape (n,) or (N, n)
        Diagonal of W (per stage if 2-D), in 1/unit^2 of each state.
    rate_weights : ndarray, shape (m,)
        Diagonal of W_du, penalty on the change of each input per control period.
    input_weights : ndarray, shape (m,)
        Diagonal of W_u, penalty on u_k - u_ref_k (zeros: no input-deviation term).
    band_index : int or None
        Index of the state with the soft band (e_y), or None for no band.
    slack_linear, slack_quadratic : float
        rho_1 and rho_2 of the slack penalty. A linear penalty larger than the largest Lagrange
        multiplier of the band makes the soft band exact whenever the hard one is feasible.
    rate_limits : ndarray, shape (m,)
        Largest change of each input per stage, in the input's unit (inf: no limit).
    """

    n_state: int
    n_input: int
    horizon: int
    state_weights: np.ndarray
    rate_weights: np.ndarray
    input_weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    band_index: int | None = None
    slack_linear: float = 1e3
    slack_quadratic: float = 1e4
    rate_limits: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def make(
        cls,
        n_state: int,
        n_input: int,
        horizon: int,
        state_weights,
        rate_weights,
        input_weights=None,
        band_index: int | None = None,
        slack_linear: float = 1e3,
        slack_quadratic: float = 1e4,
        rate_limits=None,
    ) -> QPShape:
        """Check and normalize the arguments (weights become float arrays of the right shape)."""
        n, m, N = int(n_state), int(n_input), int(horizon)
        if n < 1 or m < 1 or N < 1:
            raise ControlError(
                f"a tracking QP needs at least one state, input and stage, got n={n}, m={m}, N={N}."
            )
        w = np.asarray(state_weights, dtype=float)
        if w.shape == (n,):
            w = np.broadcast_to(w, (N, n)).copy()
        if w.shape != (N, n):
            raise ControlError(
                f"state_weights must have shape ({n},) or ({N}, {n}), got {w.shape}."
            )
        wdu = np.broadcast_to(np.asarray(rate_weights, dtype=float), (m,)).copy()
        wu = (
            np.zeros(m)
            if input_weights is None
            else np.broadcast_to(np.asarray(input_weights, dtype=float), (m,)).copy()
        )
        for name, arr in (("state", w), ("rate", wdu), ("input", wu)):
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ControlError(f"{name} weights must be finite and >= 0, got {arr}.")
        if band_index is not None and not 0 <= int(band_index) < n:
            raise ControlError(f"band_index {band_index} is not a state index (0..{n - 1}).")
        if slack_linear < 0 or slack_quadratic <= 0:
            raise ControlError(
                "the slack penalty needs slack_linear >= 0 and slack_quadratic > 0, got "
                f"{slack_linear}, {slack_quadratic}."
            )
        rate = (
            np.full(m, np.inf)
            if rate_limits is None
            else np.broadcast_to(np.asarray(rate_limits, dtype=float), (m,)).copy()
        )
        if np.any(np.isnan(rate)) or np.any(rate <= 0):
            raise ControlError(f"rate_limits must be > 0 (inf for none), got {rate}.")
        return cls(
            n, m, N, w, wdu, wu,
            None if band_index is None else int(band_index),
            float(slack_linear), float(slack_quadratic), rate,
        )  # fmt: skip


class StepQP(NamedTuple):
    """One control period's tracking QP as plain arrays: the linear model, the weights, the bounds.

    Everything the QP of the module docstring needs, in one place: :class:`QPData` (what changes
    from one period to the next) with the fixed parts of :class:`QPShape`. A copy of the numbers
    the controller solves (:attr:`racing_lib.control.mpc.CoupledMPC.last_step_qp`), for building
    that QP in a form of one's own (exercise 5.5 builds OSQP's matrices from it). Shapes use
    ``N`` stages, ``n`` states, ``m`` inputs. For the coupled MPC, ``n = 6`` states ``[v_x (m/s),
    v_y (m/s), r (rad/s), e_psi (rad), e_y (m), delta (rad)]`` (:class:`~racing_lib.control.mpc.MX`;
    the last is the steering angle behind the actuator's lag) and ``m = 2`` inputs ``[delta_cmd
    (rad), a_x (m/s^2)]``; "unit" below means each state's or input's own unit.

    Attributes
    ----------
    x0 : ndarray, shape (n,)
        The measured state now (x_0); not a decision variable.
    A : ndarray, shape (N, n, n)
        State matrices of ``x_{k+1} = A_k x_k + B_k u_k + d_k``, k = 0..N-1; entry (i, j) in
        the unit of state i per unit of state j.
    B : ndarray, shape (N, n, m)
        Input matrices B_k; entry (i, j) in the unit of state i per unit of input j.
    d : ndarray, shape (N, n)
        Affine terms d_k of the linearization, in the states' units.
    x_ref : ndarray, shape (N, n)
        Reference states of stages 1..N (row k - 1 is stage k).
    u_prev : ndarray, shape (m,)
        The input applied in the previous period, u_{-1} (rad, m/s^2).
    u_min, u_max : ndarray, shape (N, m)
        Bounds of u_0..u_{N-1} (hard).
    band_min, band_max : ndarray, shape (N,)
        The soft band on state ``band_index`` at stages 1..N (e_y, m: the track edges).
    band_index : int
        Which state the band bounds (4, e_y, for the coupled MPC).
    state_weights : ndarray, shape (N, n)
        Diagonal of W per stage 1..N, 1/unit^2 (0 for a state that is not tracked).
    rate_weights : ndarray, shape (m,)
        Diagonal of W_du, the penalty on ``u_k - u_{k-1}``, 1/unit^2.
    rate_limits : ndarray, shape (m,)
        Largest ``|u_k - u_{k-1}|`` per period, unit (``inf``: none; the steering's slew rate
        times the period for the coupled MPC).
    slack_linear, slack_quadratic : float
        rho_1 (1/m) and rho_2 (1/m^2) of the band's slack penalty ``rho_1 eps + rho_2 eps^2``.
    """

    x0: np.ndarray
    A: np.ndarray
    B: np.ndarray
    d: np.ndarray
    x_ref: np.ndarray
    u_prev: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    band_min: np.ndarray
    band_max: np.ndarray
    band_index: int
    state_weights: np.ndarray
    rate_weights: np.ndarray
    rate_limits: np.ndarray
    slack_linear: float
    slack_quadratic: float

    @classmethod
    def from_parts(cls, shape: QPShape, data: QPData) -> StepQP:
        """The QP of ``shape`` and ``data``, every array copied (changing it changes nothing else).

        Raises
        ------
        ControlError
            The QP has no band, or an input-deviation term (``input_weights`` not all zero),
            which this form leaves out.
        """
        check_qp_data(shape, data)
        if shape.band_index is None:
            raise ControlError("StepQP describes a tracking QP with a band; this one has none.")
        if np.any(shape.input_weights != 0.0):
            raise ControlError(
                "StepQP leaves out the input-deviation term, but this QP's input_weights are "
                f"{shape.input_weights}."
            )

        def own(value: object) -> np.ndarray:
            return np.array(value, dtype=float)  # always a new array

        return cls(
            x0=own(data.x0),
            A=own(data.A),
            B=own(data.B),
            d=own(data.d),
            x_ref=own(data.x_ref),
            u_prev=own(data.u_prev),
            u_min=own(data.u_min),
            u_max=own(data.u_max),
            band_min=own(data.band_min),
            band_max=own(data.band_max),
            band_index=int(shape.band_index),
            state_weights=own(shape.state_weights),
            rate_weights=own(shape.rate_weights),
            rate_limits=own(shape.rate_limits),
            slack_linear=float(shape.slack_linear),
            slack_quadratic=float(shape.slack_quadratic),
        )

    def copy(self) -> StepQP:
        """The same QP with every array copied."""
        return StepQP(*(np.array(v, dtype=float) if isinstance(v, np.ndarray) else v for v in self))


def check_qp_data(shape: QPShape, data: QPData) -> None:
    """Refuse QP data whose arrays do not fit ``shape`` (a ControlError names them)."""
    n, m, N = shape.n_state, shape.n_input, shape.horizon
    expected = {
        "x0": (n,),
        "A": (N, n, n),
        "B": (N, n, m),
        "d": (N, n),
        "x_ref": (N, n),
        "u_prev": (m,),
        "u_min": (N, m),
        "u_max": (N, m),
    }
    for name, shp in expected.items():
        value = getattr(data, name)
        # An array's own attribute: np.shape's wrapper costs more than the check, each step.
        got = value.shape if isinstance(value, np.ndarray) else np.shape(value)
        if got != shp:
            raise ControlError(f"QPData.{name} must have shape {shp}, got {got}.")
    if shape.band_index is not None:
        for name in ("band_min", "band_max"):
            got = np.shape(getattr(data, name))
            if got != (N,):
                raise ControlError(
                    f"QPData.{name} must have shape ({N},) for a QP with a band, got {got}."
                )


def tracking_cost(shape: QPShape, data: QPData, x: np.ndarray, u: np.ndarray, slack) -> float:
    """The full cost of a candidate solution (with all constants), to compare two solvers.

    Parameters
    ----------
    shape, data : QPShape, QPData
        The problem.
    x : ndarray, shape (N, n)
        States x_1..x_N.
    u : ndarray, shape (N, m)
        Inputs u_0..u_{N-1}.
    slack : ndarray, shape (N,)
        Band slack (ignored without a band).
    """
    ex = x - data.x_ref
    cost = float(np.sum(shape.state_weights * ex**2))
    du = np.diff(np.vstack([data.u_prev[None, :], u]), axis=0)
    cost += float(np.sum(shape.rate_weights * du**2))
    u_ref = np.zeros_like(u) if data.u_ref is None else data.u_ref
    cost += float(np.sum(shape.input_weights * (u - u_ref) ** 2))
    if shape.band_index is not None:
        eps = np.asarray(slack, dtype=float)
        cost += float(np.sum(shape.slack_linear * eps + shape.slack_quadratic * eps**2))
    return cost


def failed_solution(shape: QPShape, status: str, iterations: int = 0, solve_time: float = 0.0):
    """A :class:`QPSolution` that reports ``status`` and holds NaN in place of a solution."""
    N, n, m = shape.horizon, shape.n_state, shape.n_input
    return QPSolution(
        success=False,
        status=status,
        x=np.full((N, n), np.nan),
        u=np.full((N, m), np.nan),
        slack=np.full(N, np.nan),
        iterations=iterations,
        solve_time=solve_time,
    )
