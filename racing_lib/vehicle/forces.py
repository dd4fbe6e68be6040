"""The car's force laws, written once for floats, NumPy arrays and CasADi symbols.

The same formula serves the simulated car (floats, its fast path), analysis (arrays) and the
planners (CasADi symbols): the math backend is picked from the argument types (`ops_for`). Sign
conventions: x forward, y left, yaw counter-clockwise; a positive lateral acceleration (a left turn)
loads the right wheels.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, Protocol, TypeAlias

import numpy as np

from racing_lib.vehicle.params import G, VehicleParams

if TYPE_CHECKING:
    # casadi is imported lazily (see _casadi_ops): the simulator's fast path never needs it
    import casadi as ca

__all__ = [
    "CASADI_OPS",
    "MATH_OPS",
    "NUMPY_OPS",
    "MathOps",
    "Numeric",
    "axle_cornering_stiffness",
    "drag_force",
    "drive_force",
    "drive_force_envelope",
    "engine_torque",
    "engine_torque_ops",
    "gear_rpm",
    "lateral_load_transfer",
    "longitudinal_load_transfer",
    "ops_for",
    "pacejka_lateral",
    "rolling_resistance",
    "slip_angles",
    "static_axle_loads",
    "wheel_loads",
]

Numeric: TypeAlias = "float | np.ndarray | ca.SX | ca.MX | ca.DM"
"""A number the force laws and the model equations accept: a float, a NumPy array or a CasADi
expression (SX, MX, DM); a function typed with it returns the kind it was given (:func:`ops_for`
picks the backend). A string, so that casadi is imported only where a formula meets a symbol."""


class MathOps(Protocol):
    """A math backend: :data:`MATH_OPS`, :data:`NUMPY_OPS` or :data:`CASADI_OPS`.

    The element-wise functions the formulas call, named as in CasADi (:func:`ops_for` picks one);
    the ``casadi`` module itself is one too.
    """

    sin: Callable[[Numeric], Numeric]
    cos: Callable[[Numeric], Numeric]
    tan: Callable[[Numeric], Numeric]
    atan: Callable[[Numeric], Numeric]
    sqrt: Callable[[Numeric], Numeric]
    tanh: Callable[[Numeric], Numeric]
    fabs: Callable[[Numeric], Numeric]
    fmin: Callable[[Numeric, Numeric], Numeric]
    fmax: Callable[[Numeric, Numeric], Numeric]


# ---------------------------------------------------------------------------------------------
# Math backends: the same formula runs on floats (math), arrays (numpy) and symbols (casadi).
# ---------------------------------------------------------------------------------------------

MATH_OPS = SimpleNamespace(
    name="math", sin=math.sin, cos=math.cos, tan=math.tan, atan=math.atan, sqrt=math.sqrt,
    tanh=math.tanh, fabs=abs, fmin=min, fmax=max,
)  # fmt: skip
"""Scalar float backend (the simulator's fast path)."""

NUMPY_OPS = SimpleNamespace(
    name="numpy", sin=np.sin, cos=np.cos, tan=np.tan, atan=np.arctan, sqrt=np.sqrt,
    tanh=np.tanh, fabs=np.abs, fmin=np.minimum, fmax=np.maximum,
)  # fmt: skip
"""Element-wise NumPy backend."""


def _casadi_ops() -> SimpleNamespace:
    import casadi as ca  # imported lazily: the simulator's fast path never needs it

    return SimpleNamespace(
        name="casadi", sin=ca.sin, cos=ca.cos, tan=ca.tan, atan=ca.atan, sqrt=ca.sqrt,
        tanh=ca.tanh, fabs=ca.fabs, fmin=ca.fmin, fmax=ca.fmax,
    )  # fmt: skip


class _LazyCasadiOps:
    """Attribute access builds the casadi namespace on first use (casadi import is slow)."""

    _ops: SimpleNamespace | None = None

    def __getattr__(self, item: str) -> Any:
        if _LazyCasadiOps._ops is None:
            _LazyCasadiOps._ops = _casadi_ops()
        return getattr(_LazyCasadiOps._ops, item)


CASADI_OPS = _LazyCasadiOps()
"""CasADi backend (SX, MX, DM); use for symbolic models."""


def ops_for(*args: Numeric) -> MathOps:
    """Pick the math backend from the argument types.

    Any CasADi object (SX, MX, DM) -> casadi; any NumPy array -> numpy; otherwise math (floats).
    """
    for a in args:
        if type(a).__module__.startswith("casadi"):
            return CASADI_OPS
    for a in args:
        if isinstance(a, np.ndarray):
            return NUMPY_OPS
    return MATH_OPS


# ---------------------------------------------------------------------------------------------
# Force laws (paper Eq. 6-11, 13)
# ---------------------------------------------------------------------------------------------


def pacejka_lateral(
    alpha: Numeric, F_z: Numeric, mu: Numeric, B: Numeric, C: Numeric, D: Numeric
) -> Numeric:
    """Simplified Pacejka magic formula F_y = mu F_z D sin(C atan(B alpha)) (paper Eq. 9-10).

    Parameters
    ----------
    alpha : slip angle, rad.
    F_z : vertical load, N.
    mu : friction coefficient, -.
    B, C, D : stiffness, shape and peak factors, -.

    Returns
    -------
    Lateral tyre force, N (same type as the inputs).
    """
    ops = ops_for(alpha, F_z, mu, B, C, D)
    return mu * F_z * D * ops.sin(C * ops.atan(B * alpha))


def axle_cornering_stiffness(F_z: float, mu: float, B: float, C: float, D: float) -> float:
    """Slope of `pacejka_lateral` at zero slip, mu F_z D B C, N/rad."""
    return mu * F_z * D * B * C


def drag_force(v_x: Numeric, C_xw: float, ops: MathOps | None = None) -> Numeric:
    """Aerodynamic drag F_xw = C_xw v_x^2 (paper Eq. 7), N, acting against the motion.

    ``ops`` is the math backend (default: picked from ``v_x``, see :func:`ops_for`).
    """
    ops = ops_for(v_x) if ops is None else ops
    return C_xw * v_x * ops.fabs(v_x)


def slip_angles(
    v_x: Numeric,
    v_y: Numeric,
    r: Numeric,
    delta: Numeric,
    l_f: float,
    l_r: float,
    ops: MathOps,
    small_angle: bool,
) -> tuple[Numeric, Numeric]:
    """Front and rear slip angles (paper Eq. 11), rad.

    ``alpha_f = delta - atan((v_y + l_f r) / v_x)`` and ``alpha_r = -atan((v_y - l_r r) / v_x)``;
    with ``small_angle`` the arctangents are dropped, as in the planning model. ``v_x`` (m/s) is
    used as given: guard or clamp it away from zero first. ``v_y`` in m/s, ``r`` in rad/s,
    ``delta`` in rad, ``l_f`` and ``l_r`` in m; ``ops`` is the math backend (:func:`ops_for`).
    """
    if small_angle:
        return delta - (v_y + l_f * r) / v_x, -(v_y - l_r * r) / v_x
    return delta - ops.atan((v_y + l_f * r) / v_x), -ops.atan((v_y - l_r * r) / v_x)


def rolling_resistance(F_z: Numeric, c_rr: float) -> Numeric:
    """Rolling resistance R_x = c_rr F_z, N (magnitude; it acts against the motion)."""
    return c_rr * F_z


def static_axle_loads(
    m: float,
    l_f: float,
    l_r: float,
    g: float = G,
    theta: Numeric = 0.0,
    a_z: Numeric = 0.0,
    ops: MathOps | None = None,
) -> tuple[Numeric, Numeric]:
    """Axle loads without load transfer, m (g cos(theta) + a_z) l_{r,f} / (l_f + l_r) (Eq. 11-12).

    Returns
    -------
    (F_zf, F_zr) : front and rear axle loads, N.
    """
    ops = ops or ops_for(theta, a_z)
    w = m * (g * ops.cos(theta) + a_z) / (l_f + l_r)
    return w * l_r, w * l_f


def longitudinal_load_transfer(
    m: float, a_x: Numeric, h_c: float, l_f: float, l_r: float
) -> Numeric:
    """Longitudinal load transfer Delta W = m a_x h_c / (l_f + l_r) (paper Eq. 11), N.

    Positive `a_x` (accelerating) moves load from the front to the rear axle.
    """
    return m * a_x * h_c / (l_f + l_r)


def lateral_load_transfer(
    m: float, a_y: Numeric, h_c: float, l_t: float, l_f: float, l_r: float
) -> tuple[Numeric, Numeric]:
    """Lateral load transfer per axle (paper Eq. 13, Appendix A), N.

    Delta W_F = m a_y h_c / l_t * l_r / L and Delta W_R = m a_y h_c / l_t * l_f / L, L = l_f + l_r:
    the roll moment is shared between the axles like the static weight. Delta W is the load one
    wheel of the axle gains and the other loses, so the roll moment of the wheel loads,
    (Delta W_F + Delta W_R) l_t, balances m a_y h_c. The paper writes dV_y/dt for a_y; physically
    it is the lateral acceleration of the CoG, dV_y/dt + r V_x, which is what the simulator passes.
    Positive `a_y` (left turn) loads the right wheels.

    Returns
    -------
    (dW_F, dW_R) : front and rear transfer, N.
    """
    w = m * a_y * h_c / l_t / (l_f + l_r)
    return w * l_r, w * l_f


def wheel_loads(
    p: VehicleParams, a_x: Numeric, a_y: Numeric, theta: Numeric = 0.0, ops: MathOps | None = None
) -> tuple[Numeric, Numeric, Numeric, Numeric]:
    """Vertical loads of the four wheels with longitudinal and lateral load transfer, N.

    Each wheel carries half its axle's load plus or minus the whole transfer of its axle, so the
    loads balance the pitch moment ``m a_x h_c`` and the roll moment ``m a_y h_c``. This corrects
    two slips of the paper's Eq. 15: the rear wheels share F_zr, not F_zf, and the paper's
    ``F_zFL = (F_zf - Delta W_F) / 2`` halves the transfer as well, which leaves the wheel loads
    reacting only half the roll moment. Each load is clamped at zero (a lifted wheel carries
    nothing).

    Parameters
    ----------
    p : vehicle parameters.
    a_x, a_y : accelerations that cause the transfer (from the ground forces), m/s^2.
    theta : road pitch, rad.
    ops : math backend (default: chosen from the argument types).

    Returns
    -------
    (F_zFL, F_zFR, F_zRL, F_zRR), N.
    """
    ops = ops or ops_for(a_x, a_y, theta)
    f_zf, f_zr = static_axle_loads(p.m, p.l_f, p.l_r, p.g, theta, 0.0, ops)
    dw = longitudinal_load_transfer(p.m, a_x, p.h_c, p.l_f, p.l_r)
    dw_f, dw_r = lateral_load_transfer(p.m, a_y, p.h_c, p.l_t, p.l_f, p.l_r)
    f_zf = f_zf - dw
    f_zr = f_zr + dw
    return (
        ops.fmax(0.5 * f_zf - dw_f, 0.0),
        ops.fmax(0.5 * f_zf + dw_f, 0.0),
        ops.fmax(0.5 * f_zr - dw_r, 0.0),
        ops.fmax(0.5 * f_zr + dw_r, 0.0),
    )


# ---------------------------------------------------------------------------------------------
# Powertrain
# ---------------------------------------------------------------------------------------------

_RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


def gear_rpm(p: VehicleParams, v_x: float, gear: int) -> float:
    """Engine speed in `gear` (1-based) at speed v_x (no clutch slip), rpm."""
    return v_x / p.r_w * p.gear_ratios[gear - 1] * p.final_drive * _RPM_PER_RAD_S


def engine_torque(p: VehicleParams, rpm: float) -> float:
    """Full-load engine torque at `rpm` (piecewise linear, power-limited, 0 past the limiter), N m.

    Float-only fast path used by the simulator; `engine_torque_ops` is the same curve for any
    backend.
    """
    rpms, torques = p.engine_rpm, p.engine_torque_max
    if rpm <= rpms[0]:
        t = torques[0]
    elif rpm >= rpms[-1]:
        t = torques[-1]
    else:
        i = bisect.bisect_right(rpms, rpm) - 1
        w = (rpm - rpms[i]) / (rpms[i + 1] - rpms[i])
        t = torques[i] + w * (torques[i + 1] - torques[i])
    omega = max(rpm, 1.0) / _RPM_PER_RAD_S
    return min(t, p.power_max / omega)


def engine_torque_ops(p: VehicleParams, rpm: Numeric, ops: MathOps | None = None) -> Numeric:
    """`engine_torque` for floats, arrays or CasADi symbols.

    The piecewise-linear curve is a sum of ramps, T = T_0 + sum_i c_i max(rpm - rpm_i, 0), which
    only needs max; the power limit uses min. Outside the grid the end values hold.
    """
    ops = ops or ops_for(rpm)
    rpms, torques = p.engine_rpm, p.engine_torque_max
    x = ops.fmin(ops.fmax(rpm, rpms[0]), rpms[-1])
    slopes = [(torques[i + 1] - torques[i]) / (rpms[i + 1] - rpms[i]) for i in range(len(rpms) - 1)]
    t = torques[0] + slopes[0] * (x - rpms[0])
    for i in range(1, len(slopes)):
        t = t + (slopes[i] - slopes[i - 1]) * ops.fmax(x - rpms[i], 0.0)
    omega = ops.fmax(rpm, 1.0) / _RPM_PER_RAD_S
    return ops.fmin(t, p.power_max / omega)


def drive_force(p: VehicleParams, v_x: float, throttle: float, gear: int) -> float:
    """Total drive force at the rear wheels in `gear` for throttle in [0, 1], N (floats only).

    The clutch slips below `launch_rpm`, so the engine never stalls.
    """
    rpm = max(gear_rpm(p, v_x, gear), p.launch_rpm)
    ratio = p.gear_ratios[gear - 1] * p.final_drive
    return throttle * engine_torque(p, rpm) * ratio * p.driveline_efficiency / p.r_w


def drive_force_envelope(p: VehicleParams, v_x: Numeric, ops: MathOps | None = None) -> Numeric:
    """Largest full-throttle drive force over all gears at speed v_x, N (any backend).

    The smooth-ish envelope of the gearbox (max over gears), for planners that treat the gear choice
    as ideal. Tyre friction is not included.
    """
    ops = ops or ops_for(v_x)
    best = None
    for k, ratio_g in enumerate(p.gear_ratios, start=1):
        ratio = ratio_g * p.final_drive
        rpm = ops.fmax(v_x / p.r_w * ratio * _RPM_PER_RAD_S, p.launch_rpm)
        f = engine_torque_ops(p, rpm, ops) * ratio * p.driveline_efficiency / p.r_w
        best = f if k == 1 else ops.fmax(best, f)
    return best
