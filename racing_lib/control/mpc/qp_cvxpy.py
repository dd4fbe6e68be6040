"""The MPC's QP as it reads on paper, in cvxpy: the readable reference.

DPP parameters, OSQP underneath; the fast :class:`~racing_lib.control.mpc.qp_osqp.TrackingQP`
must agree with it (a test checks it).
"""

from __future__ import annotations

import time

import numpy as np

from racing_lib.control.mpc.qp_problem import (
    QPData,
    QPShape,
    QPSolution,
    check_qp_data,
    failed_solution,
)
from racing_lib.errors import ControlError

__all__ = ["CvxpyTrackingQP"]


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
        check_qp_data(sh, data)
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
            return failed_solution(sh, f"solver error: {exc}", 0, time.perf_counter() - tic)
        elapsed = time.perf_counter() - tic
        status = str(self.problem.status)
        if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or self.x.value is None:
            return failed_solution(sh, status, 0, elapsed)
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
