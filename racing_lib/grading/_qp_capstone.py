"""Exercise 5.5's machinery: the reader's QP, in OSQP's form, inside the coupled MPC's loop.

The reader writes ``build_qp(step) -> (P, q, A, l, u)``: from one control period's
:class:`~racing_lib.control.mpc.StepQP` (the coupled MPC's linear model, reference, weights and
bounds) the QP ``minimize 1/2 z'Pz + q'z subject to l <= A z <= u`` over the decision vector

    z = [x_1, ..., x_N, u_0, ..., u_{N-1}, eps_1, ..., eps_N]      (stage by stage)

of :mod:`racing_lib.control.mpc.qp_problem`: the states predicted at stages 1..N (x_0 is measured,
not a variable), the inputs, and the slack of the soft band on e_y. Any number of constraint rows,
in any order.

* :class:`ReaderQP` solves those matrices each period for
  :meth:`~racing_lib.control.mpc.CoupledMPC.use_qp`, as the library solves its own: OSQP with the
  library's settings, warm-started, and Clarabel when OSQP fails.
* :func:`diagnose_step` is the check of one period before a lap is driven: it solves the reader's
  QP to high accuracy (Clarabel) and names what differs from the library's QP, from the structure
  of the reader's solution (does it follow the model? the band? the bounds?) and from the optimum
  of the grader's own form of the QP with one named mistake (:func:`osqp_form`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
import osqp
import scipy.sparse as sp

from racing_lib.control.mpc import (
    QPData,
    QPSettings,
    QPShape,
    QPSolution,
    StepQP,
    solve_with_clarabel,
    tracking_cost,
)
from racing_lib.control.mpc.qp_problem import failed_solution
from racing_lib.grading.grader import Wrong, as_tuple, call

__all__ = ["Layout", "ReaderQP", "Situation", "check_format", "diagnose_step", "osqp_form"]

#: Names and units of the coupled MPC's states (MX order) and inputs, for messages.
STATES = (("v_x", "m/s"), ("v_y", "m/s"), ("r", "rad/s"), ("e_psi", "rad"), ("e_y", "m"),
          ("delta", "rad"))  # fmt: skip
INPUTS = (("steering command", "rad"), ("a_x", "m/s^2"))
#: Slack in the structural checks of the reader's solution, in each quantity's unit. Clarabel
#: solves to about 1e-8; a correct answer's QP, dense and unscaled, is met to 1e-7 or better.
_TOL = 1e-5
#: Relative tolerance on a cost: Clarabel's optima of these QPs agree with a tight OSQP's to
#: about 2e-8 of the cost; a QP with a mistake in its cost is off by 1e-4 or more.
_COST_TOL = 1e-6


class Layout(NamedTuple):
    """Where each block of the decision vector z sits: ``N`` stages, ``n`` states, ``m`` inputs."""

    N: int
    n: int
    m: int

    @classmethod
    def of(cls, step: StepQP) -> Layout:
        """The layout of ``step``'s QP."""
        N, n, m = step.B.shape
        return cls(int(N), int(n), int(m))

    @property
    def size(self) -> int:
        """Length of z: N n states, N m inputs, N slacks."""
        return self.N * (self.n + self.m + 1)

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x (N, n), u (N, m), eps (N,))`` of a decision vector, stage by stage."""
        N, n, m = self
        return z[: N * n].reshape(N, n), z[N * n : N * (n + m)].reshape(N, m), z[N * (n + m) :]

    def describe(self) -> str:
        """The layout in words, with the sizes."""
        N, n, m = self
        return (
            f"z = [x_1..x_N ({N} x {n} = {N * n}), u_0..u_{{N-1}} ({N} x {m} = {N * m}), "
            f"eps_1..eps_N ({N})], {self.size} entries in all, stage by stage"
        )


# --------------------------------------------------------------------------------------------------
# The reader's matrices


class ReaderMatrices(NamedTuple):
    """The reader's QP, read: P as OSQP reads it (upper triangle), the rest as floats."""

    P: sp.csc_matrix
    q: np.ndarray
    A: sp.csc_matrix
    l: np.ndarray
    u: np.ndarray


def _vector(value: object, what: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise Wrong(f"{what} should be an array of numbers, got {type(value).__name__}.") from None
    if np.isnan(arr).any():
        raise Wrong(f"{what} contains NaN.")
    return arr


def _matrix(value: object, what: str) -> sp.csc_matrix:
    try:
        mat = sp.csc_matrix(value if sp.issparse(value) else np.asarray(value, dtype=float))
    except (TypeError, ValueError):
        raise Wrong(f"{what} should be a matrix of numbers, got {type(value).__name__}.") from None
    if not np.all(np.isfinite(mat.data)):
        raise Wrong(f"{what} contains NaN or infinite values.")
    return mat


def _wrong_size(nz: int, lay: Layout) -> Wrong:
    """The mistake behind a decision vector of ``nz`` entries instead of ``lay.size``."""
    N, n, m = lay
    hint = ""
    if nz == lay.size + n:
        hint = (
            " It has room for x_0 too: x_0 is measured, not a variable; the first state in z is "
            "x_1, and A_0 x_0 moves to the right-hand side of the first model rows."
        )
    elif nz in (lay.size - N, lay.size - 2 * N):
        # N too few: no slack, or five states a stage; 2N: both. The sizes cannot tell which.
        hint = (
            f" It has {lay.size - nz} entries too few: the band on e_y is soft, with one slack "
            f"eps_k per stage, and x_k has all {n} states, the steering angle behind the "
            "actuator's lag the last."
        )
    return Wrong(f"your QP has {nz} variables; {lay.describe()}.{hint}", 3.0)


def read_matrices(out: object, lay: Layout, *, thorough: bool = True) -> ReaderMatrices:
    """The reader's ``(P, q, A, l, u)`` as OSQP takes them, or :class:`Wrong` saying what is amiss.

    ``thorough`` also checks that P is symmetric (or an upper triangle) and positive
    semidefinite: a matter of milliseconds, done once per situation, not at every period of a lap.
    """
    P, q, A, l, u = as_tuple(out, 5, "build_qp")
    q = _vector(q, "q")
    if not np.all(np.isfinite(q)):
        raise Wrong("q contains infinite values.")
    if q.size != lay.size:
        raise _wrong_size(q.size, lay)
    P, A = _matrix(P, "P"), _matrix(A, "A")
    if P.shape != (lay.size, lay.size):
        raise Wrong(f"P has shape {P.shape}; with {lay.size} variables in z it is "
                    f"({lay.size}, {lay.size}).", 3.0)  # fmt: skip
    if A.ndim != 2 or A.shape[1] != lay.size:
        raise Wrong(f"A has shape {A.shape}: one column per entry of z ({lay.size}).", 3.0)
    l, u = _vector(l, "l"), _vector(u, "u")
    if l.size != A.shape[0] or u.size != A.shape[0]:
        raise Wrong(f"A has {A.shape[0]} rows but l has {l.size} and u {u.size} entries: one "
                    "lower and one upper side per row.", 3.0)  # fmt: skip
    bad = np.flatnonzero(l > u)
    if bad.size:
        i = int(bad[0])
        raise Wrong(f"row {i} of your constraints has its lower side above its upper side "
                    f"(l = {l[i]:.4g}, u = {u[i]:.4g}): no z can meet it.", 3.0)  # fmt: skip
    if np.any((l == u) & ~np.isfinite(l)):
        raise Wrong("an equality row of yours has l = u = infinity.", 3.0)
    upper = sp.triu(P, format="csc")
    if thorough:
        _check_hessian(P, upper)
    return ReaderMatrices(upper, q, A, l, u)


def _check_hessian(P: sp.csc_matrix, upper: sp.csc_matrix) -> None:
    """P symmetric (or only its upper triangle given) and positive semidefinite."""
    dense = P.toarray()
    scale = max(float(np.abs(dense).max()), 1.0)
    if np.abs(dense - dense.T).max() > 1e-9 * scale and np.abs(np.tril(dense, -1)).max() > 0:
        if np.abs(np.triu(dense, 1)).max() == 0:
            raise Wrong(
                "your P holds only its lower triangle, and OSQP reads only the upper one: the "
                "coupling terms of your cost are lost. Give P whole (symmetric) or its upper "
                "triangle.",
                3.0,
            )
        raise Wrong(
            "your P is not symmetric; OSQP reads only its upper triangle, so the cost it "
            "minimizes is not the one you wrote. Make P symmetric: 1/2 z'Pz with P = P'.",
            3.0,
        )
    full = upper.toarray()
    full = full + np.triu(full, 1).T
    smallest = float(np.linalg.eigvalsh(full).min())
    if smallest < -1e-8 * scale:
        raise Wrong(
            f"your P is not positive semidefinite (an eigenvalue of {smallest:.3g}): the cost "
            "has no minimum. Every weight enters P with a positive sign (2 w on the diagonal).",
            3.0,
        )


# --------------------------------------------------------------------------------------------------
# The grader's own form of the QP, with named mistakes


def osqp_form(step: StepQP, mistake: str | None = None) -> ReaderMatrices:
    """The tracking QP of ``step`` in OSQP's form over the layout of :class:`Layout`.

    Built block by block with sparse Kronecker products, independently of the exercise's
    solution. ``mistake`` makes one named mistake, to recognise an answer that made it:
    ``"no rate cost"`` (W_du left out), ``"rate from zero"`` (the first input change measured
    from 0, not from u_prev, in the cost), ``"P not doubled"`` (P = W instead of 2 W: OSQP's
    1/2 forgotten), ``"no reference"`` (the states pulled to 0), ``"reference sign"`` (``+2 W
    x_ref`` in q), ``"no slack price"`` (rho_1 left out), ``"rate limit from zero"`` (the first
    steering change limited around 0, not u_prev).
    """
    N, n, m = Layout.of(step)
    nx, nu = N * n, N * m
    eye_n = sp.identity(N, format="csc")
    w_du = np.zeros(m) if mistake == "no rate cost" else step.rate_weights
    u_prev = np.zeros(m) if mistake == "rate from zero" else step.u_prev
    # (D u)_k = u_k - u_{k-1} for k >= 1 and u_0 at k = 0 (u_prev moves to q and to l, u).
    D = sp.kron(eye_n - sp.eye(N, k=-1), sp.identity(m))
    P = sp.block_diag([
        sp.diags(2.0 * step.state_weights.ravel()),
        2.0 * D.T @ sp.diags(np.tile(w_du, N)) @ D,
        2.0 * step.slack_quadratic * eye_n,
    ], format="csc")  # fmt: skip
    if mistake == "P not doubled":
        P = 0.5 * P
    sign = {"no reference": 0.0, "reference sign": 1.0}.get(mistake or "", -1.0)
    q_u = np.zeros(nu)
    q_u[:m] = -2.0 * w_du * u_prev
    slack_price = 0.0 if mistake == "no slack price" else step.slack_linear
    q = np.concatenate([sign * 2.0 * (step.state_weights * step.x_ref).ravel(), q_u,
                        np.full(N, slack_price)])  # fmt: skip
    # Model rows x_{k+1} - A_k x_k - B_k u_k = d_k (+ A_0 x_0 for k = 0).
    below = sp.block_diag(list(step.A[1:]), format="csc")
    minus_A = sp.bmat([[None, sp.csc_matrix((n, n))], [-below, None]], format="csc")
    if N == 1:
        minus_A = sp.csc_matrix((n, n))
    model = sp.hstack([sp.identity(nx) + minus_A, -sp.block_diag(list(step.B)),
                       sp.csc_matrix((nx, N))])  # fmt: skip
    rhs = step.d.copy()
    rhs[0] += step.A[0] @ step.x0
    # Band rows e_y +- eps, slack rows, input rows, rate rows.
    pick = sp.kron(eye_n, sp.csr_matrix(([1.0], ([0], [step.band_index])), shape=(1, n)))
    no_u, no_x = sp.csc_matrix((N, nu)), sp.csc_matrix((nu, nx))
    band_low = sp.hstack([pick, no_u, eye_n])
    band_high = sp.hstack([pick, no_u, -eye_n])
    slack = sp.hstack([sp.csc_matrix((N, nx + nu)), eye_n])
    inputs = sp.hstack([no_x, sp.identity(nu), sp.csc_matrix((nu, N))])
    rates = sp.hstack([no_x, D, sp.csc_matrix((nu, N))])
    limit = np.tile(step.rate_limits, N)
    centre = np.zeros(nu)
    centre[:m] = 0.0 if mistake == "rate limit from zero" else step.u_prev
    inf = np.full(N, np.inf)
    A = sp.vstack([model, band_low, band_high, slack, inputs, rates], format="csc")
    lower = np.concatenate([rhs.ravel(), step.band_min, -inf, np.zeros(N), step.u_min.ravel(),
                            centre - limit])  # fmt: skip
    upper = np.concatenate([rhs.ravel(), inf, step.band_max, inf, step.u_max.ravel(),
                            centre + limit])  # fmt: skip
    return ReaderMatrices(sp.triu(P, format="csc"), q, A, lower, upper)


def solve_accurately(qp: ReaderMatrices) -> tuple[str, np.ndarray | None]:
    """Clarabel's status and solution of ``qp`` (None when it has none)."""
    status, z, _, _ = solve_with_clarabel(qp.P, qp.q, qp.A, qp.l, qp.u)
    return status, z


#: The cost mistakes :func:`diagnose_step` looks for, with what the reader should do instead.
COST_MISTAKES = {
    "P not doubled": (
        "OSQP minimizes 1/2 z'Pz + q'z: a term w (x - x_ref)^2 puts 2 w on P's diagonal and "
        "-2 w x_ref in q (your P holds w, so the optimum tracks twice the reference)."
    ),
    "rate from zero": (
        "The first input change is u_0 - u_prev, from the command the car has now: the rate "
        "term puts -2 W_du u_prev into q at u_0."
    ),
    "no rate cost": (
        "The input-rate term sum_k (u_k - u_{k-1})' W_du (u_k - u_{k-1}) is missing: it couples "
        "neighbouring inputs in P (2 W_du on the diagonal, -2 W_du beside it)."
    ),
    "no reference": (
        "Your cost pulls the states to zero, not to the reference: q holds -2 W x_ref for the "
        "states."
    ),
    "reference sign": "The states' part of q is -2 W x_ref, with a minus.",
    "no slack price": (
        "The slack costs rho_1 eps + rho_2 eps^2: q holds slack_linear for every eps_k."
    ),
    "rate limit from zero": (
        "The first steering change is limited around the command the car has now: "
        "u_prev - rate_limit <= u_0 <= u_prev + rate_limit."
    ),
}


# --------------------------------------------------------------------------------------------------
# The reader's QP inside the loop


class ReaderQP:
    """The reader's QP, built and solved at every period (for :meth:`CoupledMPC.use_qp`).

    Runs the reader's ``build_qp`` each period and solves its matrices as the library solves its
    own (:meth:`racing_lib.control.mpc.CoupledMPC.use_qp`): OSQP with the library's settings
    (:class:`~racing_lib.control.mpc.QPSettings`), warm-started from the previous period's
    solution, and Clarabel when OSQP does not report a solution (counted in :attr:`rescues`).
    The reader's function gets a copy of the period's :class:`~racing_lib.control.mpc.StepQP`.

    Parameters
    ----------
    shape : QPShape
        The coupled MPC's :attr:`~racing_lib.control.mpc.CoupledMPC.qp_shape`.
    build_qp : callable
        ``build_qp(step) -> (P, q, A, l, u)``.
    settings : QPSettings, optional
        OSQP's settings (default: the library's).

    Attributes
    ----------
    rescues : int
        Periods OSQP failed and Clarabel was asked.
    failures : dict
        Status -> count of periods neither solver solved.
    build_seconds, solve_seconds : float
        Time spent in the reader's function and in the solvers, s.
    """

    def __init__(self, shape: QPShape, build_qp: Callable[[StepQP], object],
                 settings: QPSettings | None = None) -> None:  # fmt: skip
        self.shape = shape
        self._build = build_qp
        self.settings = settings or QPSettings()
        self.rescues = 0
        self.failures: dict[str, int] = {}
        self.build_seconds = 0.0
        self.solve_seconds = 0.0
        self._z: np.ndarray | None = None

    def solve(self, data: QPData) -> QPSolution:
        """The reader's QP of this period, solved (``success`` False when neither solver can)."""
        step = StepQP.from_parts(self.shape, data)
        lay = Layout.of(step)
        tic = time.perf_counter()
        qp = read_matrices(call(self._build, step), lay, thorough=False)
        toc = time.perf_counter()
        st = self.settings
        solver = osqp.OSQP()
        big = 1e30  # OSQP's infinity
        solver.setup(qp.P, qp.q, qp.A, np.maximum(qp.l, -big), np.minimum(qp.u, big),
                     verbose=False, eps_abs=st.eps_abs, eps_rel=st.eps_rel, max_iter=st.max_iter,
                     adaptive_rho=st.adaptive_rho, adaptive_rho_interval=st.adaptive_rho_interval,
                     check_termination=st.check_termination, warm_starting=st.warm_start,
                     polishing=st.polish)  # fmt: skip
        if st.warm_start and self._z is not None and self._z.size == qp.q.size:
            solver.warm_start(x=self._z)  # consecutive periods' QPs are close
        res = solver.solve(raise_error=False)
        status, z = str(res.info.status), res.x
        usable = status == "solved" or (st.accept_inaccurate and status == "solved inaccurate")
        if not (usable and z is not None and np.all(np.isfinite(z))):
            self.rescues += 1
            clarabel_status, z = solve_accurately(qp)
            if z is None:
                status = f"{status}; clarabel: {clarabel_status}"
            else:
                status = "solved (clarabel)"
        self.build_seconds += toc - tic
        self.solve_seconds += time.perf_counter() - toc
        self._z = z
        if z is None:
            self.failures[status] = self.failures.get(status, 0) + 1
            return failed_solution(self.shape, status)
        x, u, eps = lay.split(z)
        return QPSolution(True, status, x.copy(), u.copy(), np.maximum(eps, 0.0).copy())


# --------------------------------------------------------------------------------------------------
# The check of one period


class Situation(NamedTuple):
    """One period of the pre-check: what the car is doing, the QP, and the library's pieces."""

    what: str
    step: StepQP
    shape: QPShape
    data: QPData


def _simulate(step: StepQP, u: np.ndarray) -> np.ndarray:
    """States x_1..x_N (N, n) of the linear model under inputs u (N, m), from x_0."""
    x, out = step.x0, []
    for k in range(u.shape[0]):
        x = step.A[k] @ x + step.B[k] @ u[k] + step.d[k]
        out.append(x)
    return np.array(out)


def _needed_slack(step: StepQP, x: np.ndarray) -> np.ndarray:
    e_y = x[:, step.band_index]
    return np.maximum(0.0, np.maximum(step.band_min - e_y, e_y - step.band_max))


def cost_of_inputs(sit: Situation, u: np.ndarray) -> float:
    """The library's cost (:func:`~racing_lib.control.mpc.tracking_cost`) of inputs ``u``."""
    x = _simulate(sit.step, u)
    return tracking_cost(sit.shape, sit.data, x, u, _needed_slack(sit.step, x))


def _model_of(step: StepQP) -> Callable[[int, np.ndarray, np.ndarray], np.ndarray]:
    """``rule(k, x_k, u_k) = A_k x_k + B_k u_k + d_k``: the model's prediction of x_{k+1}."""

    def rule(k: int, xk: np.ndarray, uk: np.ndarray) -> np.ndarray:
        return step.A[k] @ xk + step.B[k] @ uk + step.d[k]

    return rule


def _model_variants(step: StepQP) -> dict[str, tuple[Callable, str]]:
    """Model rows the reader may have written instead of x_{k+1} = A_k x_k + B_k u_k + d_k.

    Name -> (the prediction ``rule(k, x_k, u_k)`` those rows make, what to do instead).
    """
    A, B, d = step.A, step.B, step.d
    return {
        "no x_0": (
            lambda k, x, u: (A[k] @ x if k else 0.0) + B[k] @ u + d[k],
            "x_0 is measured, not a variable: A_0 x_0 belongs on the right-hand side of the first "
            "model rows (l = u = d_0 + A_0 x_0), and your QP left it out.",
        ),
        "d sign": (
            lambda k, x, u: A[k] @ x + B[k] @ u - d[k],
            "Your model rows have d_k with the wrong sign: x_{k+1} - A_k x_k - B_k u_k = d_k, so "
            "l = u = d_k (+ A_0 x_0 in the first block).",
        ),
        "blocks sign": (
            lambda k, x, u: -(A[k] @ x) - B[k] @ u + d[k],
            "Your model rows hold +A_k and +B_k: moving A_k x_k + B_k u_k to the left side of "
            "x_{k+1} = A_k x_k + B_k u_k + d_k changes their sign (-A_k, -B_k in A).",
        ),
        "A transposed": (
            lambda k, x, u: A[k].T @ x + B[k] @ u + d[k],
            "Your model rows hold A_k transposed: row i of the block is A_k[i, :], the "
            "contributions of every state to state i.",
        ),
    }


def _model_error(step: StepQP, x: np.ndarray, u: np.ndarray, rule: Callable) -> np.ndarray:
    """|x_{k+1} - rule(k, x_k, u_k)| relative to 1 + |prediction|, shape (N, n)."""
    prev = np.vstack([step.x0[None, :], x[:-1]])
    pred = np.array([rule(k, prev[k], u[k]) for k in range(u.shape[0])])
    return np.abs(x - pred) / (1.0 + np.abs(pred))


def _check_model(sit: Situation, lay: Layout, z: np.ndarray, earlier: Sequence[StepQP]) -> None:
    """The reader's optimal states follow the model from their own inputs, or a named Wrong."""
    step = sit.step
    x, u, _ = lay.split(z)
    model = _model_of(step)
    err = _model_error(step, x, u, model)
    if err.max() <= _TOL:
        return
    k, i = np.unravel_index(int(np.argmax(err)), err.shape)
    prev = step.x0 if k == 0 else x[k - 1]
    name, unit = STATES[i]
    msg = (
        f"with the car {sit.what}, the states your QP predicts do not follow the model: your "
        f"{name} at stage {k + 1} is {x[k, i]:.3f} {unit}, and A_{k} x_{k} + B_{k} u_{k} + d_{k} "
        f"gives {model(k, prev, u[k])[i]:.3f} {unit} from your own x_{k} and u_{k}."
    )
    for _, (rule, hint) in _model_variants(step).items():
        if _model_error(step, x, u, rule).max() <= _TOL:
            raise Wrong(msg, 2.0, hint)
    for old in earlier:
        if _model_error(old, x, u, _model_of(old)).max() <= _TOL:
            raise Wrong(
                msg,
                2.0,
                "Your QP follows the model of an earlier call: build it from "
                "this step's data at every call (A_k, B_k, d_k change every period).",
            )
    N, n, m = lay
    by_input = z[N * n : N * (n + m)].reshape(m, N).T
    if _model_error(step, x, by_input, model).max() <= _TOL:
        raise Wrong(msg, 2.0, "Your inputs are ordered input by input (all steering commands, "
                    "then all a_x); z holds them stage by stage: u_0 = (delta_0, a_x,0), then "
                    "u_1...")  # fmt: skip
    by_state = z[: N * n].reshape(n, N).T
    if _model_error(step, by_state, u, model).max() <= _TOL:
        raise Wrong(
            msg,
            2.0,
            "Your states are ordered state by state (all v_x, then all v_y, "
            "...); z holds them stage by stage: x_1 (all six states), then x_2...",
        )
    raise Wrong(msg, 0.0, "Check the model rows: x_{k+1} - A_k x_k - B_k u_k = d_k, with the "
                "blocks in the columns of x_{k+1}, x_k and u_k.")  # fmt: skip


def _check_constraints(sit: Situation, lay: Layout, z: np.ndarray) -> None:
    """Slack, band, input bounds and rate limits hold at the reader's optimum, or a named Wrong."""
    step, what = sit.step, sit.what
    x, u, eps = lay.split(z)
    if eps.min() < -_TOL:
        k = int(np.argmin(eps))
        raise Wrong(f"with the car {what}, your slack eps_{k + 1} is {eps[k]:.3f} m: a negative "
                    "slack narrows the band and earns a reward of rho_1 |eps|.", 2.0,
                    "Add the rows eps_k >= 0.")  # fmt: skip
    e_y = x[:, step.band_index]
    out = np.maximum(step.band_min - eps - e_y, e_y - step.band_max - eps)
    if out.max() > _TOL:
        k = int(np.argmax(out))
        raise Wrong(f"with the car {what}, your e_y at stage {k + 1} is {e_y[k]:.3f} m, beyond "
                    f"the band [{step.band_min[k]:.2f}, {step.band_max[k]:.2f}] m by more than "
                    f"its slack eps = {eps[k]:.3f} m.", 2.0,
                    "Soften the band on e_y (state band_index): band_min_k - eps_k <= e_y,k <= "
                    "band_max_k + eps_k.")  # fmt: skip
    beyond = np.maximum(step.u_min - u, u - step.u_max)
    if beyond.max() > _TOL:
        k, j = np.unravel_index(int(np.argmax(beyond)), beyond.shape)
        name, unit = INPUTS[j]
        raise Wrong(f"with the car {what}, your {name} at stage {k} is {u[k, j]:.3f} {unit}, "
                    f"outside its bounds [{step.u_min[k, j]:.3f}, {step.u_max[k, j]:.3f}].", 2.0,
                    "Bound every input: u_min_k <= u_k <= u_max_k.")  # fmt: skip
    change = np.abs(np.diff(np.vstack([step.u_prev[None, :], u]), axis=0)) - step.rate_limits
    if change.max() > _TOL:
        k, j = np.unravel_index(int(np.argmax(change)), change.shape)
        name, unit = INPUTS[j]
        limit = step.rate_limits[j]
        start = "from the command the car has now" if k == 0 else f"from stage {k - 1}"
        raise Wrong(f"with the car {what}, your {name} changes by {change[k, j] + limit:.3f} "
                    f"{unit} at stage {k} ({start}); the actuator's slew rate allows "
                    f"{limit:.3f} {unit} per period.", 2.0,
                    "Limit |u_k - u_{k-1}| <= rate_limits, with u_{-1} = u_prev (inf: no "
                    "limit).")  # fmt: skip


def _solves(qp: ReaderMatrices, z: np.ndarray, tol: float) -> bool:
    """Whether ``z`` is an optimum of ``qp``: feasible, and its cost within ``tol`` of the best.

    Costs, not solutions, are compared: where an input hardly matters (a_x late in the horizon,
    whose rate weight is small) two accurate solvers' solutions differ by 1e-3 m/s^2 while their
    costs agree to 1e-8.
    """
    status, best = solve_accurately(qp)
    if best is None:
        return False
    Az = qp.A @ z
    slack = 1e-5 * (1.0 + np.abs(np.where(np.isfinite(qp.l), qp.l, 0.0)))
    upper_slack = 1e-5 * (1.0 + np.abs(np.where(np.isfinite(qp.u), qp.u, 0.0)))
    if np.any(Az < qp.l - slack) or np.any(Az > qp.u + upper_slack):
        return False

    def objective(v: np.ndarray) -> float:
        return float(0.5 * v @ (qp.P @ v + qp.P.T @ v - qp.P.diagonal() * v) + qp.q @ v)

    return objective(z) <= objective(best) + tol


def _check_optimum(sit: Situation, lay: Layout, z: np.ndarray) -> None:
    """The reader's inputs are the QP's optimum, or a Wrong naming the cost's mistake."""
    _, u, _ = lay.split(z)
    status, best = solve_accurately(osqp_form(sit.step))
    if best is None:  # the library's own QP is always feasible (soft band): never expected
        raise RuntimeError(f"the grader's QP failed ({status})")
    _, u_best, _ = lay.split(best)
    cost, optimum = cost_of_inputs(sit, u), cost_of_inputs(sit, u_best)
    if cost <= optimum * (1.0 + _COST_TOL) + _COST_TOL:
        return
    msg = (
        f"with the car {sit.what}, your QP's inputs cost {cost:.4f}, the optimum {optimum:.4f}; "
        f"the first input, the one the car gets, is ({u[0, 0]:+.4f} rad, {u[0, 1]:+.3f} m/s^2) "
        f"against ({u_best[0, 0]:+.4f} rad, {u_best[0, 1]:+.3f} m/s^2)."
    )
    for mistake, hint in COST_MISTAKES.items():
        if _solves(osqp_form(sit.step, mistake), z, _COST_TOL * (1.0 + optimum)):
            raise Wrong(msg, 1.0, hint)
    raise Wrong(
        msg,
        0.0,
        "Check the cost: 2 W on P's diagonal for the states, -2 W x_ref in q; "
        "the rate term in P and, at u_0, in q; rho_1 and 2 rho_2 for the slack.",
    )


def check_format(build_qp: Callable[[StepQP], object], sit: Situation) -> None:
    """Raise :class:`Wrong` when ``build_qp``'s matrices for ``sit`` are not a QP over z.

    Sizes, sides, symmetry and convexity: the same in every situation, so checked once.
    """
    step = sit.step.copy()
    read_matrices(call(build_qp, step), Layout.of(step))


def diagnose_step(build_qp: Callable[[StepQP], object], sit: Situation,
                  earlier: Sequence[StepQP] = ()) -> None:  # fmt: skip
    """Raise :class:`Wrong` naming the mistake when ``build_qp``'s QP of ``sit`` is not the MPC's.

    ``earlier`` are the steps the function was called with before (a QP built once and reused
    follows one of their models).
    """
    given = sit.step.copy()
    lay = Layout.of(given)
    qp = read_matrices(call(build_qp, given), lay)
    for name, value, original in zip(StepQP._fields, given, sit.step, strict=True):
        if isinstance(value, np.ndarray) and not np.array_equal(value, original):
            raise Wrong(
                f"with the car {sit.what}, your function changed step.{name} in place: "
                "the controller still needs it afterwards. Work on a copy.",
                3.0,
            )
    status, z = solve_accurately(qp)
    if z is None:
        hint = "Check the signs of your rows and their sides l and u."
        if "Infeasible" in status and "Dual" not in status:
            hint = (
                "Where the car is already beyond the band no state can meet a hard band: "
                "soften it with the slack (band_min - eps <= e_y <= band_max + eps)."
            )
        elif "Dual" in status:
            hint = "Some variable lowers the cost without end: does every variable have a cost?"
        raise Wrong(f"with the car {sit.what}, your QP has no solution (Clarabel: {status}).",
                    2.0, hint)  # fmt: skip
    _check_model(sit, lay, z, earlier)
    _check_constraints(sit, lay, z)
    _check_optimum(sit, lay, z)
