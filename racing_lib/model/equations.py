"""The planning and control model: a dynamic bicycle in Frenet coordinates, written once in CasADi.

Taught in notebook 02 ("the race vehicle model"); the planner (``racing_lib.planning``), the MPC
(``racing_lib.control.mpc``), system identification and the tests all use this one definition.

State and input (paper Eq. 1), indexed by :class:`X` and :class:`U`::

    xi = [v_x, v_y, r, e_psi, e_y, s]     (m/s, m/s, rad/s, rad, m, m)
    u  = [delta, a_x]                     (rad, m/s^2)

``a_x`` is the longitudinal acceleration produced by the tyres (drive or brake); drag, rolling
resistance and grade are modelled separately. Two per-point parameters come from the reference
line: its curvature ``kappa`` (1/m, > 0 for a left turn) and the road pitch ``theta`` (rad, > 0
uphill).

Term by term (time domain, ``xi_dot = g(xi, u; kappa, theta)``):

* Frenet kinematics (Eq. 2-4): ``s_dot = (v_x cos e_psi - v_y sin e_psi) / (1 - kappa e_y)``,
  ``e_psi_dot = r - kappa s_dot``, ``e_y_dot = v_x sin e_psi + v_y cos e_psi``.
* Longitudinal dynamics (Eq. 5): ``v_x_dot = a_x - (F_yf sin(delta) + R_x + F_xw)/m - g sin(theta)
  + r v_y`` with drag ``F_xw = C_xw v_x^2`` (Eq. 8; switch ``drag``; written ``C_xw v_x |v_x|``
  so that it always opposes the motion) and rolling resistance
  ``R_x = c_rr (F_zf + F_zr) = c_rr m g cos(theta)``.
* Lateral dynamics (Eq. 6-7): ``v_y_dot = (F_yf cos(delta) + F_yr)/m - r v_x`` and
  ``r_dot = (l_f F_yf cos(delta) - l_r F_yr)/I_zz``.
* Tyres (Eq. 9-10), simplified Pacejka: ``F_y = mu F_z D sin(C arctan(B alpha))`` with slip
  angles (Eq. 11) ``alpha_f = delta - (v_y + l_f r)/v_x`` and ``alpha_r = -(v_y - l_r r)/v_x``. The
  ``v_x`` in the denominator is replaced by a smooth maximum with :data:`VX_GUARD` so that the model
  stays finite at standstill; above about 2 m/s the difference is below 1e-3 m/s.
* Longitudinal load transfer (Eq. 12-14; switch ``longitudinal_weight_transfer``):
  ``Delta W = m v_x_dot h_c / (l_f + l_r)``, ``F_zf = m g cos(theta) l_r / L - Delta W``,
  ``F_zr = m g cos(theta) l_f / L + Delta W``. The vertical acceleration ``a_z`` of Eq. 13-14 is
  taken as zero (no vertical curvature of the road).
* Lateral load transfer (Eq. 15 and Appendix A; switch ``lateral_weight_transfer``, the double-track
  variant): ``Delta W_F = m a_y h_c / l_t * l_r / L`` moves load from the inner to the outer front
  wheel. Both front wheels share one slip angle and the tyre force is proportional to the load, so
  the axle's total force is unchanged; only the yaw moment of the two rotated front forces remains:
  ``r_dot += 0.5 l_t (F_yFL - F_yFR) sin(delta) / I_zz``
  ``= -0.5 l_t mu D_f sin(C_f arctan(B_f alpha_f)) Delta W_F sin(delta) / I_zz``.
  We use the lateral acceleration of the centre of gravity, ``a_y = v_y_dot + r v_x``, where the
  paper writes ``V_y_dot``: in steady cornering ``V_y_dot = 0`` and the literal reading would
  transfer no load at all. (The paper's ``F_zRL = (F_zf - Delta W_R)/2`` is a typo for ``F_zr``;
  the rear split does not change the dynamics either way.) This model keeps the paper's form
  ``F_zFL = (F_zf - Delta W_F)/2`` as printed, which moves only half the load a roll-moment
  balance needs (``Delta W_F/2`` per wheel instead of ``Delta W_F``); with tyres proportional to
  the load it only scales the small yaw term above. The simulated car uses the physical loads
  (:func:`racing_lib.vehicle.wheel_loads`), where load-sensitive tyres make the difference matter.

The algebraic loop of Eq. 5 and 12-13
-------------------------------------
``Delta W`` needs ``v_x_dot``, which needs ``F_yf`` (through ``F_yf sin(delta)``), which needs
``F_zf``, which needs ``Delta W``. Because the simplified Pacejka force is *proportional* to the
load, ``F_yf = phi_f F_zf`` with ``phi_f = mu D_f sin(C_f arctan(B_f alpha_f))`` independent of the
load, the loop is one *linear* scalar equation in ``v_x_dot``::

    v_x_dot = c - k (F_zf0 - m h_c v_x_dot / L) / m,   k = phi_f sin(delta),
    c = a_x - (R_x + F_xw)/m - g sin(theta) + r v_y,   F_zf0 = m g cos(theta) l_r / L

whose solution is ``v_x_dot = (c - k F_zf0 / m) / (1 - k h_c / L)``. We use this closed form: it
is exact (residual at round-off level, checked in ``tests/test_model.py``), explicit, smooth, and
cheaper than unrolled fixed-point iterations. The denominator cannot vanish:
``|k| <= mu D_f |sin(delta)|``, so for the default car ``|k h_c / L| <= 0.3 |sin(delta)|`` (0.14
at the steering limit of 0.5 rad). The closed form relies on the force being proportional to the
load, which holds for the paper's tyre law (``racing_lib.vehicle.pacejka_lateral``, reused here
like every force law of ``racing_lib.vehicle``); a load-sensitive tyre would need an iteration.

Spatial domain (Section "Trajectory Planning"): ``dxi/ds = xi_dot / s_dot``; its ``s`` component is
exactly 1. Neither form guards ``s_dot`` against zero: the car must move forward along the line.

Everything is built with CasADi SX and returned as ``casadi.Function`` objects (cached per parameter
set and options), plus :class:`~racing_lib.model.numeric.Model`, a numpy convenience wrapper. Numpy
batches hold one state per
*row* (shape ``(N, 6)``); CasADi functions and their ``map`` hold one state per *column*.
"""

from __future__ import annotations

import functools
import inspect
from types import ModuleType
from typing import Any

import casadi as ca

from racing_lib.errors import ModelError
from racing_lib.model.correction import CorrectionTemplate, correction_template
from racing_lib.model.params import ModelOptions, ModelParams
from racing_lib.model.states import NU, NX, Domain, Method, U, X, as_float

# The force laws are defined once, in racing_lib/vehicle/forces.py, for floats, numpy and CasADi
from racing_lib.vehicle import (
    MathOps,
    Numeric,
    drag_force,
    lateral_load_transfer,
    longitudinal_load_transfer,
    pacejka_lateral,
    rolling_resistance,
    slip_angles,
    static_axle_loads,
)

__all__ = [
    "VX_GUARD",
    "discrete_dynamics",
    "discrete_linearization",
    "discretize",
    "frenet_kinematics",
    "jacobians",
    "model_terms",
    "spatial_dynamics",
    "time_dynamics",
]


#: Smooth lower bound (m/s) used for ``v_x`` in the slip-angle denominators.
VX_GUARD: float = 1.0
#: Width (m/s) of the smooth corner of that bound; the error at ``v_x >> VX_GUARD`` is about
#: ``VX_GUARD_WIDTH**2 / (4 (v_x - VX_GUARD))``.
VX_GUARD_WIDTH: float = 0.1


def _smooth_max(x: Numeric, lower: float, width: float) -> Numeric:
    """``max(x, lower)`` with a hyperbolic corner of size ``width`` (smooth, exact far away)."""
    return 0.5 * (x + lower + ca.sqrt((x - lower) ** 2 + width**2))


def frenet_kinematics(
    v_x: Numeric,
    v_y: Numeric,
    r: Numeric,
    e_psi: Numeric,
    e_y: Numeric,
    kappa: Numeric,
    ops: MathOps | ModuleType = ca,
) -> tuple[Numeric, Numeric, Numeric]:
    """The Frenet kinematics of the paper's Eq. (2)-(4), for any math backend.

    The one definition of these rows: the model's dynamics use it, and so does any other model
    written in Frenet coordinates (the best-lap planner on the simulated car's equations).

    Parameters
    ----------
    v_x, v_y : float, array or casadi expression
        Body-frame velocities, m/s.
    r : float, array or casadi expression
        Yaw rate, rad/s.
    e_psi, e_y : float, array or casadi expression
        Heading error (rad) and lateral offset (m, left positive) to the reference line.
    kappa : float, array or casadi expression
        Curvature of the reference line at the car's s, 1/m.
    ops : MathOps or module
        Provides ``sin`` and ``cos``: the ``casadi`` module (default), ``numpy`` or ``math``, or a
        backend of :mod:`racing_lib.vehicle.forces` (``CASADI_OPS``).

    Returns
    -------
    s_dot, e_psi_dot, e_y_dot
        Progress along the line (m/s), heading-error rate (rad/s), lateral rate (m/s).
    """
    s_dot = (v_x * ops.cos(e_psi) - v_y * ops.sin(e_psi)) / (1 - kappa * e_y)
    return s_dot, r - kappa * s_dot, v_x * ops.sin(e_psi) + v_y * ops.cos(e_psi)


def _equations(
    xi: ca.SX, u: ca.SX, kappa: ca.SX, theta: ca.SX, p: ModelParams, o: ModelOptions
) -> tuple[ca.SX, dict[str, ca.SX]]:
    """Time-domain right-hand side and the named intermediate terms, symbolically."""
    v_x, v_y, r, e_psi, e_y = (xi[X.VX], xi[X.VY], xi[X.R], xi[X.EPSI], xi[X.EY])
    delta, a_x = u[U.DELTA], u[U.AX]
    L = p.wheelbase

    s_dot, e_psi_dot, e_y_dot = frenet_kinematics(v_x, v_y, r, e_psi, e_y, kappa, ca)

    # Slip angles, Eq. (11), with a guarded v_x so standstill does not divide by zero
    v_x_safe = _smooth_max(v_x, VX_GUARD, VX_GUARD_WIDTH)
    alpha_f, alpha_r = slip_angles(v_x_safe, v_y, r, delta, p.l_f, p.l_r, ca, small_angle=True)

    # Tyre force per newton of load: the simplified Pacejka force is proportional to F_z
    phi_f = pacejka_lateral(alpha_f, 1.0, p.mu, p.B_f, p.C_f, p.D_f)
    phi_r = pacejka_lateral(alpha_r, 1.0, p.mu, p.B_r, p.C_r, p.D_r)

    # Static loads, Eq. (13)-(14) with Delta W = 0 and a_z = 0
    F_zf0, F_zr0 = static_axle_loads(p.m, p.l_f, p.l_r, p.g, theta)

    F_xw = drag_force(v_x, p.C_xw) if o.drag else ca.SX(0)  # Eq. (8), C_xw v_x |v_x|
    R_x = rolling_resistance(F_zf0 + F_zr0, p.c_rr)  # total load does not depend on Delta W

    # Longitudinal balance, Eq. (5), without the F_yf sin(delta) coupling
    c = a_x - (R_x + F_xw) / p.m - p.g * ca.sin(theta) + r * v_y
    k = phi_f * ca.sin(delta)  # F_yf sin(delta) = k F_zf
    if o.longitudinal_weight_transfer:
        # Exact solution of the linear loop v_x_dot = c - k (F_zf0 - m h_c v_x_dot / L) / m
        v_x_dot = (c - k * F_zf0 / p.m) / (1 - k * p.h_c / L)
        delta_W = longitudinal_load_transfer(p.m, v_x_dot, p.h_c, p.l_f, p.l_r)  # Eq. (12)
    else:
        v_x_dot = c - k * F_zf0 / p.m
        delta_W = ca.SX(0)
    F_zf = F_zf0 - delta_W
    F_zr = F_zr0 + delta_W
    F_yf = phi_f * F_zf  # Eq. (9)
    F_yr = phi_r * F_zr  # Eq. (10)

    # Lateral dynamics, Eq. (6)-(7)
    a_y = (F_yf * ca.cos(delta) + F_yr) / p.m  # lateral acceleration of the CoG
    v_y_dot = a_y - r * v_x
    r_dot = (p.l_f * F_yf * ca.cos(delta) - p.l_r * F_yr) / p.I_zz
    if o.lateral_weight_transfer:
        # Eq. (15) with a_y (see module docstring); left wheels lose load in a left turn
        delta_W_F, delta_W_R = lateral_load_transfer(p.m, a_y, p.h_c, p.l_t, p.l_f, p.l_r)
        F_yFL = phi_f * (F_zf - delta_W_F) / 2
        F_yFR = phi_f * (F_zf + delta_W_F) / 2
        # Appendix A: the rotated front forces act at +-l_t/2 and add a yaw moment
        r_dot = r_dot + 0.5 * p.l_t * (F_yFL - F_yFR) * ca.sin(delta) / p.I_zz
    else:
        delta_W_F = ca.SX(0)
        delta_W_R = ca.SX(0)

    if p.correction is not None:
        # The learned residual accelerations (racing_lib.model.correction), added last: they
        # stand for what the terms above leave out, load transfer included
        dv_x, dv_y, dr = p.correction.casadi(ca.vertcat(v_x, alpha_f, alpha_r, a_x))
        v_x_dot, v_y_dot, r_dot = v_x_dot + dv_x, v_y_dot + dv_y, r_dot + dr
        # The lateral acceleration the grip limits bound is the car's, correction included:
        # otherwise a planner finds grip in the correction that no limit accounts for
        a_y = a_y + dv_y
        a_x_std, a_y_std, _ = p.correction.casadi_std(ca.vertcat(v_x, alpha_f, alpha_r, a_x))
    else:
        a_x_std = a_y_std = ca.SX(0)

    xi_dot = ca.vertcat(v_x_dot, v_y_dot, r_dot, e_psi_dot, e_y_dot, s_dot)
    terms = {
        "s_dot": s_dot,
        "alpha_f": alpha_f,
        "alpha_r": alpha_r,
        "F_zf": F_zf,
        "F_zr": F_zr,
        "F_yf": F_yf,
        "F_yr": F_yr,
        "F_xw": F_xw,
        "R_x": R_x,
        "delta_W": delta_W,
        "delta_W_F": delta_W_F,
        "delta_W_R": delta_W_R,
        "a_y": a_y,
        "a_x_std": a_x_std,
        "a_y_std": a_y_std,
    }
    return xi_dot, terms


def _symbols() -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    return ca.SX.sym("xi", NX), ca.SX.sym("u", NU), ca.SX.sym("kappa"), ca.SX.sym("theta")


INPUT_NAMES = ["xi", "u", "kappa", "theta"]


def function_options(params: ModelParams) -> dict[str, Any]:
    """Options of a CasADi Function built from ``params``.

    A model whose correction is a :class:`~racing_lib.model.correction.CorrectionTemplate` has
    the correction's data as a free symbol in its expressions; the Functions built along the way
    must allow it, and the code that builds the final one makes it an input.
    """
    return {"allow_free": True} if isinstance(params.correction, CorrectionTemplate) else {}


def correction_as_input(params: ModelParams) -> tuple[ModelParams, list[ca.DM]]:
    """``params`` with its learned correction's data as a symbol, and the data's value.

    Code built from the returned parameters, with :func:`correction_inputs` appended to its
    inputs, is the same for every correction of one layout, so :mod:`racing_lib.jit` compiles it
    once; call it with the values (:func:`racing_lib.jit.fix_inputs`). Without a correction:
    ``params`` unchanged and no values.
    """
    correction = params.correction
    if correction is None or isinstance(correction, CorrectionTemplate):
        return params, []
    template = correction_template(correction.layout)
    return params.replace(correction=template), [ca.DM(correction.packed())]


def correction_inputs(params: ModelParams) -> list[ca.SX]:
    """The extra inputs of code built from ``params``: its template's data symbol, or none."""
    correction = params.correction
    return [correction.data] if isinstance(correction, CorrectionTemplate) else []


def check_args(params: object, options: object) -> None:
    """Refuse ``params`` that are not a ModelParams or ``options`` not a ModelOptions."""
    if not isinstance(params, ModelParams):
        raise ModelError(f"params must be a ModelParams; got {type(params).__name__}.")
    if not isinstance(options, ModelOptions):
        raise ModelError(f"options must be a ModelOptions; got {type(options).__name__}.")


def _check_method_domain(method: str, domain: str) -> None:
    if method not in ("rk4", "euler"):
        raise ModelError(f"unknown method {method!r}; use 'rk4' or 'euler'.")
    if domain not in ("time", "spatial"):
        raise ModelError(f"unknown domain {domain!r}; use 'time' or 'spatial'.")


def _cached(fn: Any) -> Any:
    """Cache a Function builder on its full argument tuple (defaults filled in).

    Cache a Function builder on its full argument tuple (defaults filled in), so that
    ``time_dynamics()`` and ``time_dynamics(ModelParams(), ModelOptions())`` share one build.
    """
    signature = inspect.signature(fn)
    inner = functools.lru_cache(maxsize=64)(fn)

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        try:
            hash(bound.args)
        except TypeError:
            raise ModelError(
                f"{fn.__name__} takes a ModelParams, a ModelOptions and plain numbers/strings; "
                f"got {[type(a).__name__ for a in bound.args]}."
            ) from None
        return inner(*bound.args)

    wrapper.cache_clear = inner.cache_clear  # type: ignore[attr-defined]
    return wrapper


@_cached
def time_dynamics(
    params: ModelParams = ModelParams(), options: ModelOptions = ModelOptions()
) -> ca.Function:
    """``f(xi, u, kappa, theta) -> xi_dot``: the time-domain model (Eq. 2-15), a CasADi Function.

    Inputs: ``xi`` (6x1; m/s, m/s, rad/s, rad, m, m), ``u`` (2x1; rad, m/s^2), ``kappa`` (1/m),
    ``theta`` (rad). Output ``xi_dot`` (6x1, time derivatives). Cached per (params, options).
    """
    check_args(params, options)
    xi, u, kappa, theta = _symbols()
    xi_dot, _ = _equations(xi, u, kappa, theta, params, options)
    return ca.Function(
        "f_time", [xi, u, kappa, theta], [xi_dot], INPUT_NAMES, ["xi_dot"], function_options(params)
    )


@_cached
def spatial_dynamics(
    params: ModelParams = ModelParams(), options: ModelOptions = ModelOptions()
) -> ca.Function:
    """``f_s(xi, u, kappa, theta) -> dxi/ds = xi_dot / s_dot``: the spatial-domain model.

    Same inputs as :func:`time_dynamics`; the ``s`` component of the output is exactly 1.
    """
    check_args(params, options)
    xi, u, kappa, theta = _symbols()
    xi_dot, terms = _equations(xi, u, kappa, theta, params, options)
    dxi_ds = xi_dot / terms["s_dot"]
    dxi_ds[X.S] = 1.0
    return ca.Function(
        "f_spatial",
        [xi, u, kappa, theta],
        [dxi_ds],
        INPUT_NAMES,
        ["dxi_ds"],
        function_options(params),
    )


@_cached
def model_terms(
    params: ModelParams = ModelParams(), options: ModelOptions = ModelOptions()
) -> ca.Function:
    """Intermediate quantities (named outputs) for plots, constraints and checks.

    ``(xi, u, kappa, theta) -> s_dot (m/s), alpha_f, alpha_r (rad), F_zf, F_zr, F_yf, F_yr, F_xw,
    R_x, delta_W, delta_W_F, delta_W_R (N), a_y (m/s^2), a_x_std, a_y_std`` (m/s^2: the
    posterior standard deviations of a learned correction of ``v_x_dot`` and of ``v_y_dot``, the
    uncertainty along the two axes of the friction ellipse; zero without a correction). Use
    ``fn(xi=..., u=..., ...)["F_zf"]``.
    """
    check_args(params, options)
    xi, u, kappa, theta = _symbols()
    _, terms = _equations(xi, u, kappa, theta, params, options)
    return ca.Function(
        "model_terms",
        [xi, u, kappa, theta],
        list(terms.values()),
        INPUT_NAMES,
        list(terms.keys()),
        function_options(params),
    )


def _continuous(params: ModelParams, options: ModelOptions, domain: str) -> ca.Function:
    return (time_dynamics if domain == "time" else spatial_dynamics)(params, options)


@_cached
def jacobians(
    params: ModelParams = ModelParams(),
    options: ModelOptions = ModelOptions(),
    domain: Domain = "time",
) -> ca.Function:
    """``(xi, u, kappa, theta) -> (A_c, B_c)``: exact Jacobians of the continuous model.

    ``A_c = d f / d xi`` (6x6) and ``B_c = d f / d u`` (6x2) of :func:`time_dynamics`
    (``domain="time"``) or :func:`spatial_dynamics` (``domain="spatial"``), by CasADi's algorithmic
    differentiation.
    """
    _check_method_domain("rk4", domain)
    f = _continuous(params, options, domain)
    xi, u, kappa, theta = _symbols()
    rhs = f(xi, u, kappa, theta)
    return ca.Function(
        f"jac_{domain}",
        [xi, u, kappa, theta],
        [ca.jacobian(rhs, xi), ca.jacobian(rhs, u)],
        INPUT_NAMES,
        ["A_c", "B_c"],
        function_options(params),
    )


@_cached
def lateral_eigenvalue_test(
    params: ModelParams = ModelParams(), options: ModelOptions = ModelOptions()
) -> ca.Function:
    """``(xi, u, kappa, theta, sigma) -> (det, trace)``: lateral eigenvalues left of ``-sigma``.

    The determinant (1/s^2) and the trace (1/s) of ``A_lat + sigma I``, with ``A_lat`` the
    ``(v_y, r)`` block of the time-domain Jacobian ``A_c`` of :func:`jacobians` at the given
    state and input and ``sigma`` a shift (1/s). The block's eigenvalues are those of the lateral
    dynamics linearized there (:mod:`racing_lib.model.lateral` studies them around straight
    driving); both lie left of ``-sigma`` exactly where ``det >= 0`` and ``trace <= 0`` (the
    shifted block is then stable: Routh-Hurwitz for a 2 x 2 matrix). With ``sigma = 0`` the
    test fails where the car starts to diverge by itself, as it does under braking when load
    transfer unloads the rear axle until it oversteers (CommonRoad's BMW 320i from about 37 m/s
    at 4 m/s^2: the determinant turns negative), or near the tyres' peak in a corner, where
    their slopes and with them the trace fall towards zero.
    """
    xi, u, kappa, theta = _symbols()
    a_c = ca.jacobian(time_dynamics(params, options)(xi, u, kappa, theta), xi)
    vy, r = int(X.VY), int(X.R)
    sigma = ca.SX.sym("sigma")
    det = (a_c[vy, vy] + sigma) * (a_c[r, r] + sigma) - a_c[vy, r] * a_c[r, vy]
    trace = a_c[vy, vy] + a_c[r, r] + 2.0 * sigma
    return ca.Function(
        "lateral_eigenvalue_test",
        [xi, u, kappa, theta, sigma],
        [det, trace],
        [*INPUT_NAMES, "sigma"],
        ["det", "trace"],
        function_options(params),
    )


def _integrate(f: ca.Function, xi: Any, u: Any, kappa: Any, theta: Any, h: Any, method: str) -> Any:
    """One step of length ``h`` with ``u``, ``kappa``, ``theta`` held constant."""
    if method == "euler":
        return xi + h * f(xi, u, kappa, theta)
    k1 = f(xi, u, kappa, theta)
    k2 = f(xi + h / 2 * k1, u, kappa, theta)
    k3 = f(xi + h / 2 * k2, u, kappa, theta)
    k4 = f(xi + h * k3, u, kappa, theta)
    return xi + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def check_step(step: float | None) -> float | None:
    if step is None:
        return None
    step = as_float("step", step)
    if step <= 0.0:
        raise ModelError(f"step must be > 0 (s in the time domain, m in the spatial); got {step}.")
    return step


@_cached
def discretize(
    params: ModelParams = ModelParams(),
    options: ModelOptions = ModelOptions(),
    step: float | None = 0.1,
    method: Method = "rk4",
    domain: Domain = "time",
) -> ca.Function:
    """Discrete model ``F(xi, u, kappa, theta) -> xi_next`` over one step.

    Parameters
    ----------
    params, options
        Model parameters and switches.
    step : float or None
        ``dt`` in s (``domain="time"``) or ``ds`` in m (``domain="spatial"``). ``None`` adds a fifth
        input ``h`` (the step) to the Function, for non-uniform grids.
    method : {"rk4", "euler"}
        Explicit integrator; ``u``, ``kappa`` and ``theta`` are held constant over the step.
    domain : {"time", "spatial"}
        Integrate ``xi_dot`` over time or ``dxi/ds`` over arc length (then ``s_next = s + ds``).
    """
    _check_method_domain(method, domain)
    step = check_step(step)
    f = _continuous(params, options, domain)
    xi, u, kappa, theta = _symbols()
    h = ca.SX.sym("h") if step is None else step
    xi_next = _integrate(f, xi, u, kappa, theta, h, method)
    inputs, names = [xi, u, kappa, theta], list(INPUT_NAMES)
    if step is None:
        inputs.append(h)
        names.append("h")
    return ca.Function(
        f"F_{method}_{domain}", inputs, [xi_next], names, ["xi_next"], function_options(params)
    )


#: Alias of :func:`discretize`.
discrete_dynamics = discretize


@_cached
def discrete_linearization(
    params: ModelParams = ModelParams(),
    options: ModelOptions = ModelOptions(),
    step: float | None = 0.1,
    method: Method = "rk4",
    domain: Domain = "time",
) -> ca.Function:
    """Affine model of one discrete step around ``(xi_bar, u_bar)``.

    ``(xi_bar, u_bar, kappa, theta[, h]) -> (A_d, B_d, d_d)`` with
    ``xi_next ~= A_d xi + B_d u + d_d`` exact to first order: ``A_d = dF/dxi``, ``B_d = dF/du`` at
    the point and ``d_d = F(xi_bar, u_bar) - A_d xi_bar - B_d u_bar`` (the paper's ``A_k, B_k,
    D_k``). Use ``.map(N)`` to linearize N stages in one call (inputs stacked as columns; ``A_d``
    comes back as 6 x 6N), or :meth:`~racing_lib.model.numeric.Model.linearize` for numpy arrays.
    Arguments as in
    :func:`discretize`.
    """
    F = discretize(params, options, step, method, domain)
    xi, u, kappa, theta = _symbols()
    extra = [ca.SX.sym("h")] if step is None else []
    xi_next = F(xi, u, kappa, theta, *extra)
    A = ca.jacobian(xi_next, xi)
    B = ca.jacobian(xi_next, u)
    d = xi_next - ca.mtimes(A, xi) - ca.mtimes(B, u)
    names = ["xi_bar", "u_bar", "kappa", "theta"] + (["h"] if extra else [])
    return ca.Function(
        f"lin_{method}_{domain}",
        [xi, u, kappa, theta, *extra],
        [A, B, d],
        names,
        ["A_d", "B_d", "d_d"],
        function_options(params),
    )
