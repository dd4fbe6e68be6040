"""The QP inside every MPC of racing_lib: linear time-varying tracking with a soft band.

One QP, two implementations that must agree (a test checks it):

* :class:`CvxpyTrackingQP` writes the problem as it reads on paper, with cvxpy ``Parameter`` objects
  (DPP, so cvxpy compiles it once) and OSQP underneath. It is the reference: easy to read, slow
  (cvxpy spends several ms per solve in its own bookkeeping; 20-50 ms measured here).
* :class:`TrackingQP` builds OSQP's matrices once with a fixed sparsity pattern and, at each control
  step, only overwrites their values (``update(Ax=..., q=..., l=..., u=...)``) and warm-starts from
  the previous solution: 0.5-0.8 ms median for the coupled MPC's 6 states, 2 inputs and 20-30
  stages (including the numeric refactorization that new matrix values require).

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

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from racing_lib.errors import ControlError

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


def _check_data(shape: QPShape, data: QPData) -> None:
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
        got = np.shape(getattr(data, name))
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


def _failed(shape: QPShape, status: str, iterations: int = 0, solve_time: float = 0.0):
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


class TrackingQP:
    """The fast path: OSQP called directly on a fixed sparsity pattern, updated in place.

    Decision vector ``z = [x_1..x_N, u_0..u_{N-1}, eps_1..eps_N]`` (the slack block only with a
    band). Constraint rows: N*n dynamics equalities, then (with a band) 2N soft-band rows and N rows
    eps >= 0, then N*m input bounds. Every entry of every A_k and B_k block is kept in the pattern,
    even if it is zero at setup, so that later linearizations only change values; OSQP then
    re-factorizes its KKT matrix numerically without a new symbolic analysis.

    Parameters
    ----------
    shape : QPShape
        Sizes and weights (see :meth:`QPShape.make`).
    settings : QPSettings, optional
        OSQP settings.

    Examples
    --------
    >>> import numpy as np
    >>> shape = QPShape.make(1, 1, 5, state_weights=[1.0], rate_weights=[0.0])
    >>> qp = TrackingQP(shape)
    >>> N = 5
    >>> data = QPData(x0=np.zeros(1), A=np.ones((N, 1, 1)), B=0.1 * np.ones((N, 1, 1)),
    ...               d=np.zeros((N, 1)), x_ref=np.ones((N, 1)), u_prev=np.zeros(1),
    ...               u_min=-np.ones((N, 1)), u_max=np.ones((N, 1)))
    >>> sol = qp.solve(data)
    >>> sol.success, bool(sol.u[0, 0] > 0.9)
    (True, True)
    """

    def __init__(self, shape: QPShape, settings: QPSettings | None = None) -> None:
        import osqp

        self.shape = shape
        self.settings = settings or QPSettings()
        n, m, N = shape.n_state, shape.n_input, shape.horizon
        self._ns = 1 if shape.band_index is not None else 0
        self._nx_tot = N * n
        self._nu_tot = N * m
        self._nz = self._nx_tot + self._nu_tot + N * self._ns
        self._P = self._build_P()
        self._build_A_pattern()
        self._q = np.zeros(self._nz)
        self._l = np.zeros(self._n_rows)
        self._u = np.zeros(self._n_rows)
        self._static_bounds()
        self._solver = osqp.OSQP()
        st = self.settings
        # osqp 1.x renamed warm_start and added raise_error; 0.6 knows neither.
        self._osqp1 = int(str(getattr(osqp, "__version__", "0")).split(".")[0]) >= 1
        warm_key = "warm_starting" if self._osqp1 else "warm_start"
        polish_key = "polishing" if self._osqp1 else "polish"
        self._solver.setup(
            self._P,
            self._q,
            self._A,
            self._l,
            self._u,
            verbose=False,
            eps_abs=st.eps_abs,
            eps_rel=st.eps_rel,
            max_iter=st.max_iter,
            adaptive_rho=st.adaptive_rho,
            adaptive_rho_interval=st.adaptive_rho_interval,
            check_termination=st.check_termination,
            **{warm_key: st.warm_start, polish_key: st.polish},
        )
        self._has_solution = False
        #: Solves that OSQP failed and Clarabel was asked to rescue (see :attr:`QPSettings.rescue`).
        self.rescues = 0

    # --- index helpers ---------------------------------------------------------------------------
    def _ix(self, k: int, i: int) -> int:
        """Column of state i at stage k (k = 1..N)."""
        return (k - 1) * self.shape.n_state + i

    def _iu(self, k: int, j: int) -> int:
        """Column of input j at stage k (k = 0..N-1)."""
        return self._nx_tot + k * self.shape.n_input + j

    def _ie(self, k: int) -> int:
        """Column of the slack at stage k (k = 1..N)."""
        return self._nx_tot + self._nu_tot + (k - 1)

    # --- matrices --------------------------------------------------------------------------------
    def _build_P(self) -> sp.csc_matrix:
        """Hessian (upper triangle) of 1/2 z'Pz: constant, since the weights are fixed."""
        sh = self.shape
        n, m, N = sh.n_state, sh.n_input, sh.horizon
        rows, cols, vals = [], [], []
        for k in range(1, N + 1):
            for i in range(n):
                rows.append(self._ix(k, i))
                cols.append(self._ix(k, i))
                vals.append(2.0 * sh.state_weights[k - 1, i])
        for k in range(N):
            for j in range(m):
                # u_k enters the rate terms (u_k - u_{k-1}) and (u_{k+1} - u_k), the last only once.
                n_terms = 2.0 if k < N - 1 else 1.0
                rows.append(self._iu(k, j))
                cols.append(self._iu(k, j))
                vals.append(2.0 * (n_terms * sh.rate_weights[j] + sh.input_weights[j]))
                if k < N - 1:
                    rows.append(self._iu(k, j))
                    cols.append(self._iu(k + 1, j))
                    vals.append(-2.0 * sh.rate_weights[j])
        for k in range(1, N + 1 if self._ns else 1):
            rows.append(self._ie(k))
            cols.append(self._ie(k))
            vals.append(2.0 * sh.slack_quadratic)
        P = sp.coo_matrix((vals, (rows, cols)), shape=(self._nz, self._nz)).tocsc()
        P.sort_indices()
        return P

    def _build_A_pattern(self) -> None:
        """Constraint matrix with a fixed pattern and a map from block values to CSC data slots.

        Entries are generated in a known order: first the constant ones (identity of x_{k+1},
        band and bound rows), then -A_k (k = 1..N-1, row-major), then -B_k (k = 0..N-1). A vector of
        values in that order, permuted by ``self._perm``, is exactly ``A.data`` of the CSC matrix.
        """
        sh = self.shape
        n, m, N = sh.n_state, sh.n_input, sh.horizon
        rows: list[int] = []
        cols: list[int] = []
        const_vals: list[float] = []
        # Dynamics rows r = k*n + i (k = 0..N-1): x_{k+1} - A_k x_k - B_k u_k = d_k.
        for k in range(N):
            for i in range(n):
                rows.append(k * n + i)
                cols.append(self._ix(k + 1, i))
                const_vals.append(1.0)
        row = N * n
        self._band_row0 = row
        if self._ns:
            b = sh.band_index
            for k in range(1, N + 1):
                # lower: e_y + eps >= band_min
                rows += [row, row]
                cols += [self._ix(k, b), self._ie(k)]
                const_vals += [1.0, 1.0]
                row += 1
                # upper: e_y - eps <= band_max
                rows += [row, row]
                cols += [self._ix(k, b), self._ie(k)]
                const_vals += [1.0, -1.0]
                row += 1
            self._slack_row0 = row
            for k in range(1, N + 1):
                rows.append(row)
                cols.append(self._ie(k))
                const_vals.append(1.0)
                row += 1
        self._input_row0 = row
        for k in range(N):
            for j in range(m):
                rows.append(row)
                cols.append(self._iu(k, j))
                const_vals.append(1.0)
                row += 1
        # Rate rows (only inputs with a finite limit): u_k - u_{k-1}, with u_{-1} on the bound side.
        self._rate_inputs = [j for j in range(m) if np.isfinite(sh.rate_limits[j])]
        self._rate_row0 = row
        for k in range(N):
            for j in self._rate_inputs:
                rows.append(row)
                cols.append(self._iu(k, j))
                const_vals.append(1.0)
                if k > 0:
                    rows.append(row)
                    cols.append(self._iu(k - 1, j))
                    const_vals.append(-1.0)
                row += 1
        self._n_rows = row
        self._n_const = len(const_vals)
        # -A_k x_k for k = 1..N-1 (x_0 is not a variable: it moves to the right-hand side).
        for k in range(1, N):
            for i in range(n):
                for j in range(n):
                    rows.append(k * n + i)
                    cols.append(self._ix(k, j))
        for k in range(N):
            for i in range(n):
                for j in range(m):
                    rows.append(k * n + i)
                    cols.append(self._iu(k, j))
        n_entries = len(rows)
        # Mark each entry with its position so the CSC conversion reveals the permutation.
        marks = np.arange(1, n_entries + 1, dtype=float)
        A = sp.coo_matrix((marks, (rows, cols)), shape=(self._n_rows, self._nz)).tocsc()
        A.sort_indices()
        if A.nnz != n_entries:
            raise ControlError("internal error: duplicate entries in the MPC constraint pattern.")
        self._perm = A.data.astype(np.int64) - 1
        self._values = np.empty(n_entries)
        self._values[: self._n_const] = const_vals
        # Set-up values: any nonzero numbers (the pattern is what matters; a zero could be dropped
        # as an explicit zero by some sparse routine, which would change the pattern).
        self._na = (N - 1) * n * n
        self._values[self._n_const :] = -1.0
        A.data = self._values[self._perm].copy()
        self._A = A

    def _static_bounds(self) -> None:
        n_rate = len(self._rate_inputs)
        if n_rate:
            r0 = self._rate_row0
            lim = np.tile(self.shape.rate_limits[self._rate_inputs], self.shape.horizon)
            self._l[r0 : r0 + lim.size] = -lim
            self._u[r0 : r0 + lim.size] = lim
        if self._ns:
            N = self.shape.horizon
            s0 = self._slack_row0
            self._l[s0 : s0 + N] = 0.0
            self._u[s0 : s0 + N] = np.inf
            b0 = self._band_row0
            self._u[b0 : b0 + 2 * N : 2] = np.inf  # lower band rows have no upper bound
            self._l[b0 + 1 : b0 + 2 * N : 2] = -np.inf  # upper band rows have no lower bound
            self._q[self._nx_tot + self._nu_tot :] = self.shape.slack_linear

    # --- solve -----------------------------------------------------------------------------------
    def solve(self, data: QPData) -> QPSolution:
        """Update the QP with ``data`` and solve it (warm-started from the previous solution).

        Parameters
        ----------
        data : QPData
            The instance; shapes are checked.

        Returns
        -------
        QPSolution
            ``success`` False with the solver's status if OSQP did not solve it (never raises for
            a solver failure; raises :class:`ControlError` for malformed data).
        """
        sh = self.shape
        n, m, N = sh.n_state, sh.n_input, sh.horizon
        _check_data(sh, data)
        A = np.asarray(data.A, dtype=float)
        B = np.asarray(data.B, dtype=float)
        d = np.asarray(data.d, dtype=float)
        # Matrix values: -A_1..-A_{N-1}, -B_0..-B_{N-1}, in the order of the pattern.
        self._values[self._n_const : self._n_const + self._na] = -A[1:].ravel()
        self._values[self._n_const + self._na :] = -B.ravel()
        Ax = self._values[self._perm]
        # Dynamics right-hand side: d_k, plus A_0 x_0 in the first block.
        rhs = d.copy()
        rhs[0] += A[0] @ np.asarray(data.x0, dtype=float)
        rhs = rhs.ravel()
        self._l[: N * n] = rhs
        self._u[: N * n] = rhs
        if self._ns:
            b0 = self._band_row0
            self._l[b0 : b0 + 2 * N : 2] = data.band_min
            self._u[b0 + 1 : b0 + 2 * N : 2] = data.band_max
        i0 = self._input_row0
        self._l[i0 : i0 + N * m] = np.asarray(data.u_min, dtype=float).ravel()
        self._u[i0 : i0 + N * m] = np.asarray(data.u_max, dtype=float).ravel()
        if self._rate_inputs:
            # First rate row: u_0 - u_prev in [-r, r]  <=>  u_0 in [u_prev - r, u_prev + r].
            r0 = self._rate_row0
            for i, j in enumerate(self._rate_inputs):
                lim = sh.rate_limits[j]
                self._l[r0 + i] = data.u_prev[j] - lim
                self._u[r0 + i] = data.u_prev[j] + lim
        # Linear cost: -2 W x_ref for states, rate term couples u_0 with u_prev, input reference.
        q = self._q
        q[: N * n] = (-2.0 * sh.state_weights * data.x_ref).ravel()
        qu = np.zeros((N, m))
        qu[0] = -2.0 * sh.rate_weights * np.asarray(data.u_prev, dtype=float)
        if data.u_ref is not None:
            qu -= 2.0 * sh.input_weights * np.asarray(data.u_ref, dtype=float)
        q[self._nx_tot : self._nx_tot + N * m] = qu.ravel()
        if not (np.all(np.isfinite(Ax)) and np.all(np.isfinite(rhs)) and np.all(np.isfinite(q))):
            return _failed(sh, "non-finite problem data")
        if np.any(self._l > self._u):
            return _failed(sh, "inconsistent bounds (lower > upper)")
        tic = time.perf_counter()
        self._solver.update(Ax=Ax, q=q, l=self._l, u=self._u)
        res = self._solver.solve(raise_error=False) if self._osqp1 else self._solver.solve()
        iterations = int(res.info.iter)
        status = str(res.info.status)
        z = res.x if self._usable(status, res.x) else None
        objective = float(res.info.obj_val)
        if z is None and self.settings.rescue:
            self.rescues += 1
            status, z, n_ipm, objective = self._rescue(Ax, status)
            iterations += n_ipm
        elapsed = time.perf_counter() - tic
        if z is None:
            # Do not warm-start the next solve from garbage.
            if self._has_solution:
                self._solver.warm_start(x=np.zeros(self._nz), y=np.zeros(self._n_rows))
            self._has_solution = False
            return _failed(sh, status, iterations, elapsed)
        if res.x is None or z is not res.x:
            self._solver.warm_start(x=z)  # the next OSQP solve starts from the rescued answer
        self._has_solution = True
        x = z[: N * n].reshape(N, n)
        u = z[self._nx_tot : self._nx_tot + N * m].reshape(N, m)
        eps = z[self._nx_tot + self._nu_tot :] if self._ns else np.zeros(N)
        return QPSolution(
            success=True,
            status=status,
            x=x.copy(),
            u=u.copy(),
            slack=np.maximum(np.asarray(eps, dtype=float).copy(), 0.0),
            iterations=iterations,
            solve_time=elapsed,
            objective=objective,
        )

    def _usable(self, status: str, z: np.ndarray | None) -> bool:
        """Whether an OSQP status and solution vector can be used as the control."""
        ok = status == "solved" or (self.settings.accept_inaccurate and status in SOLVED_STATUSES)
        return ok and z is not None and bool(np.all(np.isfinite(z)))

    def _rescue(
        self, Ax: np.ndarray, osqp_status: str
    ) -> tuple[str, np.ndarray | None, int, float]:
        """Solve the current QP with Clarabel (see :attr:`QPSettings.rescue`).

        OSQP's ``l <= A z <= u`` becomes Clarabel's ``A_c z + s = b``: the equality rows with
        ``s`` in the zero cone, the finite upper and lower sides with ``s >= 0``.

        Returns
        -------
        status : str
            ``"solved (clarabel)"``, or both solvers' statuses when Clarabel fails too.
        z : ndarray or None
            The solution (None on failure).
        iterations : int
            Clarabel's iterations.
        objective : float
            Its objective value.
        """
        import clarabel

        A = self._A.copy()
        A.data = Ax
        lo, up = self._l, self._u
        eq = lo == up
        has_up = np.isfinite(up) & ~eq
        has_lo = np.isfinite(lo) & ~eq
        A_c = sp.vstack([A[eq], A[has_up], -A[has_lo]]).tocsc()
        b = np.concatenate([up[eq], up[has_up], -lo[has_lo]])
        cones = [
            clarabel.ZeroConeT(int(eq.sum())),
            clarabel.NonnegativeConeT(int(has_up.sum() + has_lo.sum())),
        ]
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        sol = clarabel.DefaultSolver(self._P, self._q.copy(), A_c, b, cones, settings).solve()
        status = str(sol.status)
        z = np.asarray(sol.x, dtype=float)
        if status != "Solved" or not np.all(np.isfinite(z)):
            return f"{osqp_status}; clarabel: {status}", None, int(sol.iterations), float("nan")
        return "solved (clarabel)", z, int(sol.iterations), float(sol.obj_val)


class CvxpyTrackingQP:
    """The reference implementation: the same QP written with cvxpy Parameters (DPP) and OSQP.

    Slow (a few ms per solve) but reads like the formulation; :class:`TrackingQP` is tested
    against it.

    Parameters
    ----------
    shape : QPShape
        Sizes and weights.
    solver_options : dict, optional
        Passed to ``problem.solve`` (defaults: OSQP with tight tolerances and polishing).
    """

    def __init__(self, shape: QPShape, solver_options: dict | None = None) -> None:
        import cvxpy as cp
        import osqp

        self.shape = shape
        n, m, N = shape.n_state, shape.n_input, shape.horizon
        osqp1 = int(str(getattr(osqp, "__version__", "0")).split(".")[0]) >= 1
        self.solver_options = solver_options or {
            "solver": cp.OSQP,
            "eps_abs": 1e-9,
            "eps_rel": 1e-9,
            "max_iter": 200000,
            "polishing" if osqp1 else "polish": True,
        }
        self.x = cp.Variable((N, n), name="x")  # x_1..x_N
        self.u = cp.Variable((N, m), name="u")  # u_0..u_{N-1}
        self.p_x0 = cp.Parameter(n, name="x0")
        self.p_A = [cp.Parameter((n, n), name=f"A{k}") for k in range(N)]
        self.p_B = [cp.Parameter((n, m), name=f"B{k}") for k in range(N)]
        self.p_d = cp.Parameter((N, n), name="d")
        self.p_xref = cp.Parameter((N, n), name="x_ref")
        self.p_uref = cp.Parameter((N, m), name="u_ref")
        self.p_uprev = cp.Parameter(m, name="u_prev")
        self.p_umin = cp.Parameter((N, m), name="u_min")
        self.p_umax = cp.Parameter((N, m), name="u_max")
        # x_0 as a variable pinned to its parameter: A_0 @ x0 would be a product of two parameters,
        # which is not DPP.
        x0 = cp.Variable(n, name="x0")
        cons = [x0 == self.p_x0]
        prev = x0
        for k in range(N):
            cons.append(self.x[k] == self.p_A[k] @ prev + self.p_B[k] @ self.u[k] + self.p_d[k])
            prev = self.x[k]
        cons += [self.u >= self.p_umin, self.u <= self.p_umax]
        for j in range(m):
            if np.isfinite(shape.rate_limits[j]):
                steps = self.u[:, j] - cp.hstack([self.p_uprev[j], self.u[:-1, j]])
                cons += [cp.abs(steps) <= shape.rate_limits[j]]
        W = shape.state_weights
        cost = cp.sum(cp.multiply(W, cp.square(self.x - self.p_xref)))
        du = cp.vstack([cp.reshape(self.u[0] - self.p_uprev, (1, m), order="C"),
                        self.u[1:] - self.u[:-1]]) if N > 1 else cp.reshape(
            self.u[0] - self.p_uprev, (1, m), order="C")  # fmt: skip
        cost += cp.sum(cp.multiply(np.broadcast_to(shape.rate_weights, (N, m)), cp.square(du)))
        if np.any(shape.input_weights > 0):
            cost += cp.sum(
                cp.multiply(
                    np.broadcast_to(shape.input_weights, (N, m)), cp.square(self.u - self.p_uref)
                )
            )
        if shape.band_index is not None:
            self.eps = cp.Variable(N, name="eps")
            self.p_bmin = cp.Parameter(N, name="band_min")
            self.p_bmax = cp.Parameter(N, name="band_max")
            ey = self.x[:, shape.band_index]
            cons += [ey >= self.p_bmin - self.eps, ey <= self.p_bmax + self.eps, self.eps >= 0]
            cost += shape.slack_linear * cp.sum(self.eps) + shape.slack_quadratic * cp.sum_squares(
                self.eps
            )
        else:
            self.eps = None
        self.problem = cp.Problem(cp.Minimize(cost), cons)
        if not self.problem.is_dpp():
            raise ControlError("internal error: the reference MPC QP is not DPP.")

    def solve(self, data: QPData) -> QPSolution:
        """Solve the instance ``data`` (same contract as :meth:`TrackingQP.solve`)."""
        import cvxpy as cp

        sh = self.shape
        N, m = sh.horizon, sh.n_input
        _check_data(sh, data)
        self.p_x0.value = np.asarray(data.x0, dtype=float)
        for k in range(N):
            self.p_A[k].value = np.asarray(data.A[k], dtype=float)
            self.p_B[k].value = np.asarray(data.B[k], dtype=float)
        self.p_d.value = np.asarray(data.d, dtype=float)
        self.p_xref.value = np.asarray(data.x_ref, dtype=float)
        self.p_uref.value = np.zeros((N, m)) if data.u_ref is None else np.asarray(data.u_ref)
        self.p_uprev.value = np.asarray(data.u_prev, dtype=float)
        # cvxpy refuses infinite parameter values: replace by a huge finite bound.
        big = 1e9
        self.p_umin.value = np.clip(np.asarray(data.u_min, dtype=float), -big, big)
        self.p_umax.value = np.clip(np.asarray(data.u_max, dtype=float), -big, big)
        if self.eps is not None:
            self.p_bmin.value = np.clip(np.asarray(data.band_min, dtype=float), -big, big)
            self.p_bmax.value = np.clip(np.asarray(data.band_max, dtype=float), -big, big)
        tic = time.perf_counter()
        try:
            self.problem.solve(**self.solver_options)
        except cp.SolverError as exc:
            return _failed(sh, f"solver error: {exc}", 0, time.perf_counter() - tic)
        elapsed = time.perf_counter() - tic
        status = str(self.problem.status)
        if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or self.x.value is None:
            return _failed(sh, status, 0, elapsed)
        eps = np.zeros(N) if self.eps is None else np.maximum(self.eps.value, 0.0)
        return QPSolution(
            success=True,
            status="solved" if status == cp.OPTIMAL else "solved inaccurate",
            x=np.array(self.x.value),
            u=np.array(self.u.value),
            slack=np.array(eps),
            iterations=int(getattr(self.problem.solver_stats, "num_iters", 0) or 0),
            solve_time=elapsed,
            objective=float(self.problem.value),
        )
