"""The MPC's QP on OSQP's fast path.

Matrices built once with a fixed sparsity pattern, only their values overwritten at each control
step, warm-started from the previous solution.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp

from racing_lib.control.mpc.qp_problem import (
    SOLVED_STATUSES,
    QPData,
    QPSettings,
    QPShape,
    QPSolution,
    check_qp_data,
    failed_solution,
)
from racing_lib.errors import ControlError

__all__ = ["TrackingQP", "solve_with_clarabel"]


class _Result(NamedTuple):
    """What a step reads of an OSQP solve: the solution ``x`` and OSQP's ``info`` object.

    ``info`` is OSQP's live object, which the next solve overwrites: read it at once.
    """

    x: np.ndarray | None
    info: Any


# The attributes of OSQP's extension object (osqp >= 1.0) that a control step uses.
_EXT_ATTRIBUTES = ("update_data_vec", "update_data_mat", "solve", "info", "solution")


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
            warm_starting=st.warm_start,
            polishing=st.polish,
        )
        # Each step talks to OSQP's compiled solver object directly. The Python wrapper's update()
        # looks a constant up through importlib twice and its solve() copies 18 info fields into a
        # namespace: 35-40 us of a step of about 900 us, for the same numbers from the same C
        # calls (tested). The wrapper stays the way in for setup and warm starts.
        self._ext = getattr(self._solver, "_solver", None)
        if not all(hasattr(self._ext, name) for name in _EXT_ATTRIBUTES):
            self._ext = None  # an OSQP whose internals moved: take the wrapper's way
        # OSQP's bounds are finite: +-infinity is its OSQP_INFTY (what the wrapper clips to).
        self._osqp_inf = float(self._solver.constant("OSQP_INFTY"))
        self._l_osqp = np.empty(self._n_rows)
        self._u_osqp = np.empty(self._n_rows)
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
        check_qp_data(sh, data)
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
        if not (np.isfinite(Ax).all() and np.isfinite(rhs).all() and np.isfinite(q).all()):
            return failed_solution(sh, "non-finite problem data")
        # NaN compares false both ways, so asking for l <= u everywhere also refuses a NaN bound,
        # which the Clarabel rescue would otherwise read as no bound at all.
        if not (self._l <= self._u).all():
            return failed_solution(sh, "inconsistent bounds (NaN, or lower > upper)")
        tic = time.perf_counter()
        res = self._osqp_solve(Ax, q)
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
            return failed_solution(sh, status, iterations, elapsed)
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

    def _osqp_solve(self, Ax: np.ndarray, q: np.ndarray) -> _Result:
        """Give OSQP the values of A, the cost ``q`` and the bounds ``self._l, self._u``; solve.

        The result has OSQP's ``x`` and ``info`` (``status``, ``iter``, ``obj_val``).
        """
        if self._ext is None:
            self._solver.update(Ax=Ax, q=q, l=self._l, u=self._u)
            res = self._solver.solve(raise_error=False)
            return _Result(x=res.x, info=res.info)
        ext = self._ext
        np.maximum(self._l, -self._osqp_inf, out=self._l_osqp)
        np.minimum(self._u, self._osqp_inf, out=self._u_osqp)
        ext.update_data_vec(q=q, l=self._l_osqp, u=self._u_osqp)
        ext.update_data_mat(P_x=None, P_i=None, A_x=Ax, A_i=None)
        ext.solve()
        return _Result(x=ext.solution.x, info=ext.info)

    def _usable(self, status: str, z: np.ndarray | None) -> bool:
        """Whether an OSQP status and solution vector can be used as the control."""
        ok = status == "solved" or (self.settings.accept_inaccurate and status in SOLVED_STATUSES)
        return ok and z is not None and bool(np.isfinite(z).all())

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
        A = self._A.copy()
        A.data = Ax
        status, z, iterations, objective = solve_with_clarabel(
            self._P, self._q.copy(), A, self._l, self._u
        )
        if z is None:
            return f"{osqp_status}; clarabel: {status}", None, iterations, objective
        return "solved (clarabel)", z, iterations, objective


def solve_with_clarabel(
    P: sp.spmatrix, q: np.ndarray, A: sp.spmatrix, l: np.ndarray, u: np.ndarray
) -> tuple[str, np.ndarray | None, int, float]:
    """Solve a QP given in OSQP's form with Clarabel, an interior-point solver.

    ``minimize 1/2 z'Pz + q'z subject to l <= A z <= u`` becomes Clarabel's ``A_c z + s = b``:
    the rows with ``l = u`` with ``s`` in the zero cone, the finite upper and lower sides with
    ``s >= 0``; infinite sides are no constraint. Used by :class:`TrackingQP` when OSQP fails
    (:attr:`QPSettings.rescue`), and where a QP must be solved to high accuracy without tuning
    (the exercise checks of :mod:`racing_lib.grading.ch05`).

    Parameters
    ----------
    P : sparse matrix, shape (nz, nz)
        The upper triangle of the cost's Hessian (as OSQP reads it).
    q : ndarray, shape (nz,)
        Linear cost.
    A : sparse matrix, shape (n_rows, nz)
        Constraint matrix.
    l, u : ndarray, shape (n_rows,)
        Lower and upper sides (``-inf`` / ``inf`` for none).

    Returns
    -------
    status : str
        Clarabel's status (``"Solved"`` on success).
    z : ndarray or None
        The solution (None unless solved with finite values).
    iterations : int
        Clarabel's iterations.
    objective : float
        Its objective value (NaN when not solved).
    """
    import clarabel

    A = sp.csc_matrix(A)
    lo, up = np.asarray(l, dtype=float), np.asarray(u, dtype=float)
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
    sol = clarabel.DefaultSolver(sp.csc_matrix(P), q, A_c, b, cones, settings).solve()
    status = str(sol.status)
    z = np.asarray(sol.x, dtype=float)
    if status != "Solved" or not np.all(np.isfinite(z)):
        return status, None, int(sol.iterations), float("nan")
    return status, z, int(sol.iterations), float(sol.obj_val)
