"""The minimum-lap-time NLP, assembled from the functions of one interval of the grid.

Every term of the NLP of :mod:`racing_lib.planning.time_optimal` couples at most two neighbouring
nodes: the trapezoidal defect of interval k joins nodes k and k + 1, the path constraints touch
node k alone, and the lap time and the steering-rate penalty are sums over the intervals. So the
Lagrangian is a sum of interval terms ``L_k(w_k, w_{k+1})``, and its derivatives are sums of
small blocks:

* one interval's constraints, their Jacobian (with respect to the 14 variables of its two nodes),
  its objective and gradient, and the Hessian of its Lagrangian are CasADi SX functions of about
  a dozen inputs, differentiated once per parameter set, options and settings
  (:class:`IntervalFunctions`, cached);
* a grid of N nodes maps them over its N intervals (``Function.map``) and scatters the blocks into
  the global sparse Jacobian and upper-triangular Hessian with constant index maps
  (:class:`StructuredNLP`), which IPOPT receives as CasADi's ``jac_g``, ``grad_f`` and
  ``hess_lag``;
* the constraints and the three derivative functions are compiled to machine code
  (:mod:`racing_lib.jit`: one compiler run per parameter set, options and settings, cached on
  disk). Evaluated by CasADi's interpreter the derivatives took more than half of each solve,
  the Hessian most; compiled, the evaluations take about a tenth of it and IPOPT's own linear
  algebra the rest, so a solve takes about half the time, to the same plan bit for bit
  (``benchmarks/bench_plan_speed.py`` and ``benchmarks/bench_nlp_iteration.py`` measure it).
  With a learned correction (a GP's mean and standard deviation at every node) the evaluations
  are most of a solve, and the constraints, interpreted, were half of them: compiled too, the
  learning loop's plans on the expressway took 20-32 s instead of 34-52 s.

Why not let CasADi differentiate the whole lap: with one flat SX graph of 1,464 nodes its symbolic
Hessian took 6.3 s to build (expressway), more than the solve, and had to be rebuilt for every
track; an MX graph over the mapped node function builds fast but evaluated its derivatives about
four times slower per iteration. Here the symbolic work is done on one interval (tens of
milliseconds, the same for every track), and the track enters only as data: curvature, grade, arc
length and interval lengths are inputs of the mapped functions. The values are those of the flat
graph up to round-off.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from racing_lib.errors import PlanningError
from racing_lib.jit import compiled_or_interpreted, fix_inputs
from racing_lib.model import NU, NX, U, X, lateral_eigenvalue_test, model_terms, spatial_dynamics
from racing_lib.model.equations import correction_as_input, correction_inputs, function_options
from racing_lib.model.params import ModelOptions, ModelParams
from racing_lib.planning.demands import ellipse_axes
from racing_lib.planning.time_optimal_settings import TimeOptimalSettings

if TYPE_CHECKING:
    # casadi is imported where a problem is built: importing the planners stays cheap
    import casadi as ca

__all__ = [
    "IntervalFunctions",
    "StructuredNLP",
    "clear_interval_caches",
    "interval_functions",
    "NLP_VARS",
    "NLP_SCALE",
]

# Variables per node, in this order, with their typical magnitudes (for scaling).
NLP_VARS = ("VX", "VY", "R", "EPSI", "EY", "DELTA", "AX")
NLP_SCALE = np.array([30.0, 1.0, 0.5, 0.2, 5.0, 0.1, 5.0])
NXS = 5  # states in the NLP (s is the grid itself)
#: Scale of the speed row, m/s: ``(v_x^2 + v_y^2) / SPEED_SCALE^2 <= (v_top / SPEED_SCALE)^2``.
SPEED_SCALE = 30.0
_NW = len(NLP_VARS)
_ROWS = {name: i for i, name in enumerate(NLP_VARS)}

#: Scales of the lateral-stability rows: the determinant (1/s^2) and the trace (1/s) of the
#: lateral block are of the order of 100 1/s^2 and 10 1/s at racing speed.
DET_SCALE = 100.0
TRACE_SCALE = 10.0

#: Largest share of the friction ellipse that a learned correction's uncertainty may take at a
#: node (TimeOptimalSettings.uncertainty_margin): where it would take more, the plan does not go.
MAX_UNCERTAIN_SHARE = 0.9


@dataclass(frozen=True)
class IntervalFunctions:
    """One interval's NLP functions, for one parameter set, options and settings.

    Every function takes ``(w_a, w_b, d_a, d_b, h)``: the scaled variables of the interval's two
    nodes (7 each, in :data:`NLP_VARS` order), their track data ``(kappa, theta, s)`` (1/m, rad,
    m) and the interval's length h (m); ``hess`` also takes the objective's weight and the
    constraint multipliers.

    Attributes
    ----------
    con : casadi.Function
        The interval's constraints: the 5 scaled trapezoidal defects, the steering-rate row
        (with ``steer_rate`` settings), then node a's path constraints.
    con_jac : casadi.Function
        Nonzeros of the constraints' Jacobian with respect to ``(w_a, w_b)``, in the order of
        ``jac_sparsity``. With ``jit`` settings, where a C compiler works, this and the other two
        derivative functions are compiled (``casadi.external``): they take numbers and MX, not
        SX, and have no derivatives of their own; ``con`` and ``obj`` stay symbolic.
    obj : casadi.Function
        The interval's lap time (trapezoid in 1/s_dot, s) plus its steering-rate penalty.
    obj_grad : casadi.Function
        Gradient of ``obj`` with respect to ``(w_a, w_b)`` (14).
    hess : casadi.Function
        Nonzeros of the Hessian of ``sigma obj + lam . con`` with respect to ``(w_a, w_b)``, in
        the order of ``hess_sparsity``.
    inv_sdot : casadi.Function
        One node's ``1 / s_dot`` (s/m) from ``(w, d)``.
    jac_sparsity, hess_sparsity : casadi.Sparsity
        Structure of the interval's Jacobian ((5 + rows after the defects) x 14) and Hessian
        (14 x 14).
    lb_path, ub_path : numpy.ndarray
        Bounds of one interval's constraints after its defects.
    """

    con: ca.Function
    con_jac: ca.Function
    obj: ca.Function
    obj_grad: ca.Function
    hess: ca.Function
    inv_sdot: ca.Function
    jac_sparsity: ca.Sparsity
    hess_sparsity: ca.Sparsity
    lb_path: np.ndarray
    ub_path: np.ndarray

    @property
    def n_con(self) -> int:
        """Constraints per interval (defects and path constraints)."""
        return NXS + len(self.lb_path)


def _path_constraints(
    params: ModelParams,
    st: TimeOptimalSettings,
    z: ca.SX,
    xi: ca.SX,
    u: ca.SX,
    terms: dict[str, ca.SX],
) -> tuple[list[ca.SX], np.ndarray, np.ndarray]:
    """One node's path constraints (CasADi expressions) and their bounds, in scaled form."""
    import casadi as ca

    path, lb, ub = [], [], []
    if st.slip_limit:
        a_f, a_r = params.slip_angle_at(st.slip_force_share)
        path += [terms["alpha_f"] / a_f, terms["alpha_r"] / a_r]
        lb += [-1.0, -1.0]
        ub += [1.0, 1.0]
    if st.friction_ellipse:
        grip_x, grip = ellipse_axes(params)  # along and across the car: the g-g diagram
        # The tyres' whole longitudinal force, a_x less the steered front tyre's lateral force
        # along the car (Eq. 5): with a_x alone in the ellipse the optimum braked beyond it by
        # scrubbing, a steering zig-zag in the braking zones that the car cannot follow.
        a_long = z[_ROWS["AX"]] - terms["F_yf"] * ca.sin(u[int(U.DELTA)]) / params.m
        ellipse = (a_long / grip_x) ** 2 + (terms["a_y"] / grip) ** 2
        if params.correction is not None and st.uncertainty_margin > 0.0:
            # (a_long / grip_x)^2 + (a_y / grip)^2 <= (1 - share)^2 with share the learned
            # accelerations' standard deviations on the ellipse's own scale, written with the
            # same bound: the ellipse shrinks where the correction is unsure. Both axes count:
            # the first plan that used only a_y's braked from the top speed where no lap had
            # braked, on a longitudinal correction nobody had checked, and spun the car.
            spread = ca.sqrt((terms["a_x_std"] / grip_x) ** 2 + (terms["a_y_std"] / grip) ** 2)
            share = st.uncertainty_margin * spread
            ellipse = ellipse + 2.0 * share - share**2
        path.append(ellipse)
        lb.append(-np.inf)
        ub.append(1.0)
        if params.correction is not None and st.uncertainty_margin > 0.0:
            # (1 - share)^2 shrinks the ellipse only while share < 1: beyond, it would grow
            # again where the correction is least sure. The plan keeps the share below
            # MAX_UNCERTAIN_SHARE instead, away from what the laps have not seen.
            path.append(share / MAX_UNCERTAIN_SHARE)
            lb.append(-np.inf)
            ub.append(1.0)
    if st.drive_axle_circle:
        # Rear-wheel drive: the rear tyres alone carry the drive force, on top of their share of
        # the cornering force, inside their own friction circle.
        f_rear = params.mu * params.D_r * terms["F_zr"]
        f_drive = params.m * ca.fmax(z[_ROWS["AX"]], 0.0)
        path.append((f_drive**2 + terms["F_yr"] ** 2) / f_rear**2)
        lb.append(-np.inf)
        ub.append(1.0)
    if st.pedal_limits == "exact":
        pedal = params.pedal
        base = pedal.m_0 + ca.dot(ca.DM(pedal.m_xi), xi)
        path.append((z[_ROWS["AX"]] - base) / 5.0)
        lb.append(-pedal.full_brake() / 5.0)
        ub.append(pedal.m_thr / 5.0)
        if pedal.p_thr is not None:
            # The power limit as a smooth product (throttle power per unit mass), not a min().
            path.append((z[_ROWS["AX"]] - base) * xi[int(X.VX)] / pedal.p_thr)
            lb.append(-np.inf)
            ub.append(1.0)
    elif st.pedal_limits != "iterate":
        raise PlanningError(f"unknown pedal_limits {st.pedal_limits!r}; use 'iterate' or 'exact'.")
    # The top speed bounds the car's speed, not v_x alone: under a bound on v_x the optimum
    # crabbed down the straights at the top speed, weaving with a slip angle (|v_y| up to 3 m/s
    # at 52.8 m/s on the expressway) whose sideways speed it counted as progress. The row is
    # last; its upper bound, (v_top / SPEED_SCALE)^2, is set per solve (:func:`speed_bounds`).
    path.append((xi[int(X.VX)] ** 2 + xi[int(X.VY)] ** 2) / SPEED_SCALE**2)
    lb.append(-np.inf)
    ub.append(1.0)
    return path, np.array(lb, float), np.array(ub, float)


def _node_function(
    params: ModelParams, options: ModelOptions, st: TimeOptimalSettings
) -> tuple[ca.Function, np.ndarray, np.ndarray]:
    """One node's ``(w, d) -> (dxi/ds of the 5 states, path constraints, 1/s_dot)``."""
    import casadi as ca

    w = ca.SX.sym("w", _NW)
    d = ca.SX.sym("d", 3)  # kappa (1/m), theta (rad), s (m)
    z = w * ca.DM(NLP_SCALE)
    xi = ca.SX(NX, 1)  # the model's state and input, filled by name
    for name in NLP_VARS[:NXS]:
        xi[int(X[name])] = z[_ROWS[name]]
    xi[int(X.S)] = d[2]
    u = ca.SX(NU, 1)
    u[int(U.DELTA)] = z[_ROWS["DELTA"]]
    u[int(U.AX)] = z[_ROWS["AX"]]
    f_all = spatial_dynamics(params, options)(xi, u, d[0], d[1])
    f = ca.vertcat(*[f_all[int(X[name])] for name in NLP_VARS[:NXS]])
    terms_fn = model_terms(params, options)
    terms = dict(zip(terms_fn.name_out(), terms_fn(xi, u, d[0], d[1]), strict=True))
    path, lb, ub = _path_constraints(params, st, z, xi, u, terms)
    if st.lateral_stability is not None:
        # Stable (the block's determinant and trace: both eigenvalues left of zero), and both
        # on one side of -lateral_stability (the shifted determinant, det + sigma trace +
        # sigma^2). Under braking, where one eigenvalue moves right while the other stays far
        # left (the divergence identification measures), that keeps the first left of
        # -lateral_stability; near the tyres' peak in a corner both may slow down together,
        # and there plain stability suffices (a shifted trace bound every such corner and cost
        # 3 % of lap time that the laps did not need).
        det, trace = lateral_eigenvalue_test(params, options)(xi, u, d[0], d[1], 0.0)
        sigma = st.lateral_stability
        rows = [det / DET_SCALE, trace / TRACE_SCALE]
        lb_rows, ub_rows = [0.0, -np.inf], [np.inf, 0.0]
        if sigma > 0.0:  # at 0 the shifted row is the first one again
            rows.append((det + sigma * trace + sigma**2) / DET_SCALE)
            lb_rows.append(0.0)
            ub_rows.append(np.inf)
        path[-1:-1] = rows  # the speed row stays last
        lb = np.concatenate([lb[:-1], lb_rows, lb[-1:]])
        ub = np.concatenate([ub[:-1], ub_rows, ub[-1:]])
    node = ca.Function(
        "node", [w, d], [f, ca.vertcat(*path), 1.0 / terms["s_dot"]], function_options(params)
    )
    return node, lb, ub


@functools.lru_cache(maxsize=16)
def interval_functions(
    params: ModelParams, options: ModelOptions, st: TimeOptimalSettings
) -> IntervalFunctions:
    """The interval functions for a parameter set, options and settings (cached).

    Parameters
    ----------
    params : ModelParams
        Planning model parameters.
    options : ModelOptions
        Model effects.
    st : TimeOptimalSettings
        The settings that shape the NLP (path constraints, steering-rate weight).

    Returns
    -------
    IntervalFunctions

    Notes
    -----
    With ``st.jit`` the first call for a parameter set compiles the derivative functions with
    the system's C compiler (about a second; the build is kept on disk, :mod:`racing_lib.jit`),
    or logs one warning and keeps them interpreted when no compiler works. A learned correction's
    data are an input of that code, not part of it
    (:func:`racing_lib.model.equations.correction_as_input`): every correction of one layout
    shares one build (one per uncertainty margin, which is part of the settings).
    """
    build, values = correction_as_input(params)
    fns = _interval_functions(build, options, st)
    bound = {
        name: fix_inputs(getattr(fns, name), values)
        for name in ("con", "con_jac", "obj", "obj_grad", "hess", "inv_sdot")
    }
    return dataclasses.replace(fns, **bound)


def clear_interval_caches() -> None:
    """Forget every cached interval function: the next plan builds (or loads) them anew."""
    interval_functions.cache_clear()
    _interval_functions.cache_clear()


@functools.lru_cache(maxsize=16)
def _interval_functions(
    params: ModelParams, options: ModelOptions, st: TimeOptimalSettings
) -> IntervalFunctions:
    """:func:`interval_functions` of parameters whose correction, if any, is a template.

    A template's data symbol is the last input of every function (after the multipliers of
    ``hess``).
    """
    import casadi as ca

    data = correction_inputs(params)

    node, lb, ub = _node_function(params, options, st)
    wa, wb = ca.SX.sym("wa", _NW), ca.SX.sym("wb", _NW)
    da, db = ca.SX.sym("da", 3), ca.SX.sym("db", 3)
    h = ca.SX.sym("h")
    f_a, path_a, q_a = node(wa, da)
    f_b, _, q_b = node(wb, db)
    inv_scale = ca.DM(1.0 / NLP_SCALE[:NXS])
    i_delta = _ROWS["DELTA"]
    d_delta = (wb[i_delta] - wa[i_delta]) * NLP_SCALE[i_delta]
    # Trapezoidal collocation in scaled units (each defect divided by its state's scale).
    defect = wb[:NXS] - wa[:NXS] - 0.5 * h * (f_a + f_b) * inv_scale
    con = ca.vertcat(defect, path_a)
    if st.steer_rate is not None:
        # The steering actuator's rate limit between two nodes, over the time the car takes
        # from one to the other. Without it the optimum of a car whose lateral stability is
        # bound alternated the steering node by node (+-0.07 rad 3 m apart at 40 m/s, 2 rad/s),
        # whose slip lowers the front tyres' slope and so meets the bound while braking harder.
        rate = d_delta / (0.5 * h * (q_a + q_b) * st.steer_rate)
        con = ca.vertcat(defect, rate, path_a)
        lb, ub = np.concatenate([[-1.0], lb]), np.concatenate([[1.0], ub])
    i_ax = _ROWS["AX"]
    d_ax = (wb[i_ax] - wa[i_ax]) * NLP_SCALE[i_ax]
    obj = 0.5 * h * (q_a + q_b) + (st.w_ddelta * d_delta**2 + st.w_dax * d_ax**2) / h
    v = ca.vertcat(wa, wb)
    args = [wa, wb, da, db, h]
    jac = ca.jacobian(con, v)
    sigma, lam = ca.SX.sym("sigma"), ca.SX.sym("lam", con.numel())
    hess = ca.hessian(sigma * obj + ca.dot(lam, con), v)[0]
    functions = [
        ca.Function("interval_con", [*args, *data], [con]),
        ca.Function("interval_con_jac", [*args, *data], [jac.nz[:]]),
        ca.Function("interval_obj_grad", [*args, *data], [ca.gradient(obj, v)]),
        ca.Function("interval_hess", [*args, sigma, lam, *data], [hess.nz[:]]),
    ]
    if st.jit:
        # The constraints and the derivatives are evaluated at every IPOPT iteration; compiled,
        # they cost a fraction of what CasADi's interpreter takes (the same numbers to the last
        # bit). Interpreted, the constraints of a plan with a learned correction took half its
        # evaluation time. nlpsol differentiates the constraints' graph as it is built, though
        # it is handed every derivative it calls: finite differences let it, and no solve
        # evaluates them. (Only the structured graph gets here: the flat ones, which CasADi
        # differentiates, run without jit, see time_optimal._shape_settings.)
        functions = compiled_or_interpreted(
            functions,
            "the time-optimal NLP's constraints and derivatives",
            "TimeOptimalSettings(jit=False)",
            name="racing_lib_nlp_interval",
            finite_differences={"interval_con"},
        )
    con_fn, con_jac, obj_grad, hess_fn = functions
    return IntervalFunctions(
        con=con_fn,
        con_jac=con_jac,
        obj=ca.Function("interval_obj", [*args, *data], [obj]),
        obj_grad=obj_grad,
        hess=hess_fn,
        inv_sdot=ca.Function("inv_sdot", [wa, da, *data], [q_a]),
        jac_sparsity=jac.sparsity(),
        hess_sparsity=hess.sparsity(),
        lb_path=lb,
        ub_path=ub,
    )


def _global_index(local: np.ndarray, n: int) -> np.ndarray:
    """Global variable index of local variable ``local`` (0-13) of every interval, shape (n, m)."""
    k = np.arange(n)[:, None]
    node = np.where(local < _NW, k, (k + 1) % n)
    return _NW * node + local % _NW


def _scatter(nrow: int, ncol: int, rows: np.ndarray, cols: np.ndarray) -> tuple[Any, Any]:
    """The sparsity of a global matrix and the 0/1 matrix that adds triplets into it.

    Triplet t (entry ``rows[t], cols[t]``) is added into its nonzero, so duplicates are summed.
    """
    import casadi as ca

    sp, mapping = ca.Sparsity.triplet(nrow, ncol, rows.tolist(), cols.tolist(), True)
    mapping = np.asarray(mapping, int)
    gather = ca.DM(
        ca.Sparsity.triplet(sp.nnz(), len(mapping), mapping.tolist(), list(range(len(mapping)))),
        1.0,
    )
    return sp, gather


class StructuredNLP:
    """The minimum-lap-time NLP of one grid, with derivatives assembled from interval blocks.

    Parameters
    ----------
    fns : IntervalFunctions
        One interval's functions.
    kappa, theta, s, ds : numpy.ndarray
        The grid: curvature (1/m), grade (rad), arc length (m) of each node and the length of
        each interval (m; the last one closes the lap).
    t_ref : float
        Reference lap time dividing the objective, s.
    graph : {"structured", "sx", "mx"}
        ``"structured"``: the derivatives assembled from the interval blocks; ``"sx"``, ``"mx"``:
        the whole lap as one graph of that kind, differentiated by CasADi (kept to check and
        measure the structured one against).

    Attributes
    ----------
    nlp : dict
        CasADi's NLP (``x``, ``f``, ``g``) in MX.
    derivatives : dict
        ``grad_f``, ``jac_g`` and ``hess_lag`` for ``nlpsol``'s options.
    lbg, ubg : numpy.ndarray
        Constraint bounds, interval by interval. The speed rows' upper bounds in ``ubg`` are
        placeholders (a speed of :data:`SPEED_SCALE`): a solve sets them to the top speed
        (``_Problem.speed_bounds``).
    speed_rows : numpy.ndarray
        Indices of the speed constraint of every interval in ``g``.
    """

    def __init__(
        self,
        fns: IntervalFunctions,
        kappa: np.ndarray,
        theta: np.ndarray,
        s: np.ndarray,
        ds: np.ndarray,
        t_ref: float,
        graph: str = "structured",
    ) -> None:
        import casadi as ca

        if graph not in ("structured", "sx", "mx"):
            raise PlanningError(f"unknown graph {graph!r}; use 'structured', 'sx' or 'mx'.")
        n = len(s)
        self.n = n
        nv = _NW * n
        x = (ca.SX if graph == "sx" else ca.MX).sym("x", nv)
        w_a = ca.reshape(x, _NW, n)
        nxt = list(range(1, n)) + [0]
        data = np.vstack([kappa, theta, s])
        args = [w_a, w_a[:, nxt], ca.DM(data), ca.DM(data[:, nxt]), ca.DM(ds).T]

        g = ca.vec(fns.con.map(n)(*args))
        f = ca.sum2(fns.obj.map(n)(*args)) / t_ref
        self.nlp = {"x": x, "f": f, "g": g}
        self.lbg = np.tile(np.concatenate([np.zeros(NXS), fns.lb_path]), n)
        self.ubg = np.tile(np.concatenate([np.zeros(NXS), fns.ub_path]), n)
        # The speed constraint is each interval's last row (see _path_constraints).
        self.speed_rows = np.arange(n) * fns.n_con + fns.n_con - 1
        q = fns.inv_sdot.map(n)(w_a, ca.DM(data))
        lap = ca.mtimes(q, ca.DM(0.5 * (ds + np.roll(ds, 1))))
        self.lap_fn = ca.Function("lap", [x], [lap, 1.0 / q])
        self.derivatives: dict[str, Any] = {}
        if graph == "structured":
            self.derivatives = self._derivatives(fns, x, args, f, g, t_ref)

    def _derivatives(
        self, fns: IntervalFunctions, x: Any, args: list, f: Any, g: Any, t_ref: float
    ) -> dict[str, Any]:
        """``grad_f``, ``jac_g`` and ``hess_lag`` from the mapped interval blocks."""
        import casadi as ca

        n, nv, m = self.n, x.numel(), fns.n_con
        p = ca.MX.sym("p", 0, 1)
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", m * n)

        # Gradient: each interval's 14 entries added into its two nodes.
        local = np.arange(2 * _NW)
        grad_idx = _global_index(local, n).ravel()
        _, grad_gather = _scatter(nv, 1, grad_idx, np.zeros_like(grad_idx))
        grad = ca.mtimes(grad_gather, ca.vec(fns.obj_grad.map(n)(*args))) / t_ref

        # Jacobian: interval k's rows are k m ... k m + m - 1; every entry lands once.
        j_rows, j_cols = fns.jac_sparsity.get_triplet()
        j_rows, j_cols = np.asarray(j_rows), np.asarray(j_cols)
        rows = (m * np.arange(n)[:, None] + j_rows).ravel()
        cols = _global_index(j_cols, n).ravel()
        jac_sp, jac_gather = _scatter(m * n, nv, rows, cols)
        jac = ca.MX(jac_sp, ca.mtimes(jac_gather, ca.vec(fns.con_jac.map(n)(*args))))

        # Hessian: the upper triangle of the sum of the interval blocks.
        h_rows, h_cols = fns.hess_sparsity.get_triplet()
        rows = _global_index(np.asarray(h_rows), n).ravel()
        cols = _global_index(np.asarray(h_cols), n).ravel()
        upper = rows <= cols
        hess_sp, hess_gather = _scatter(nv, nv, rows[upper], cols[upper])
        keep = np.flatnonzero(upper)
        lam = ca.reshape(lam_g, m, n)
        blocks = ca.vec(fns.hess.map(n)(*args, ca.repmat(lam_f / t_ref, 1, n), lam))
        hess = ca.MX(hess_sp, ca.mtimes(hess_gather, blocks[keep.tolist()]))

        return {
            "grad_f": ca.Function("grad_f", [x, p], [f, grad], ["x", "p"], ["f", "grad_f_x"]),
            "jac_g": ca.Function("jac_g", [x, p], [g, jac], ["x", "p"], ["g", "jac_g_x"]),
            "hess_lag": ca.Function(
                "hess_lag",
                [x, p, lam_f, lam_g],
                [hess],
                ["x", "p", "lam_f", "lam_g"],
                ["hess_gamma_x_x"],
            ),
        }
