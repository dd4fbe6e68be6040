"""The car's parameters and force laws.

`VehicleParams` holds the true parameters of the simulated car (`racing_lib.sim.SimulatedCar`): the
paper's table for the Mazda Demio XD Touring '15 plus every value the paper does not give, each
documented once, in the dataclass. The force laws below are written once and evaluated with
floats, NumPy arrays or CasADi symbols alike, so the planning model (`racing_lib.model`) reuses
them: the math backend is picked from the argument types (`ops_for`).

Sign conventions: x forward, y left, yaw counter-clockwise; a positive lateral acceleration (a left
turn) loads the right wheels.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, fields
from types import SimpleNamespace
from typing import Any

import numpy as np

from racing_lib.errors import ModelError

__all__ = [
    "CASADI_OPS",
    "MATH_OPS",
    "NUMPY_OPS",
    "VehicleParams",
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
    "static_axle_loads",
    "wheel_loads",
]

G = 9.81  # gravitational acceleration, m/s^2


@dataclass(frozen=True)
class VehicleParams:
    """True parameters of the simulated car (defaults: a Mazda Demio XD-like hatch, RWD).

    The first block is the paper's table (identified in Gran Turismo Sport). Everything else is
    our own plausible choice for a small 77 kW diesel hatch, tuned so that the car reaches about
    190 km/h (rev-limited in top gear), brakes at about 1.05 g, does 0-100 km/h in about 9 s, and
    is stable under braking and throttle in corners (mild understeer, traction control). The
    paper states front-wheel steering and rear-wheel drive; we follow it.

    Attributes
    ----------
    m : float
        Mass, kg. Paper.
    l_f : float
        Distance CoG to front axle, m. Paper.
    l_r : float
        Distance CoG to rear axle, m. Paper.
    width : float
        Body width, m (used for wall contact and track-edge checks). Paper.
    h_c : float
        Height of the centre of gravity, m (load transfer). Paper.
    mu : float
        Tire-road friction coefficient on the track surface, -. Paper.
    C_xw : float
        Aerodynamic drag coefficient in F = C_xw v_x^2, kg/m. Paper.
    I_zz : float
        Yaw moment of inertia, kg m^2. Paper.
    g : float
        Gravitational acceleration, m/s^2.
    l_t : float
        Track width (distance between left and right wheel centres), m. Demio: 1.495 front, 1.475
        rear; we use one value.
    overhang_front : float
        Body length ahead of the front axle, m (Demio: 4.06 m long, 2.57 m wheelbase).
    overhang_rear : float
        Body length behind the rear axle, m.
    B_f, C_f, D_f : float
        Simplified Pacejka stiffness, shape and peak factors, front tires, -. B 10, C 1.9, D 1 are
        common racing-tire values (peak at about 0.11 rad slip).
    B_r, C_r, D_r : float
        Same for the rear tires; B_r > B_f (stiffer per unit load) makes the car mildly understeer.
    load_sensitivity : float
        Drop of the peak factor per unit of relative load increase, -: a wheel with load F_z has
        D (1 - k (F_z - F_z0) / F_z0), F_z0 = m g / 4. It is what makes lateral load transfer cost
        grip; real tires have 0.1-0.2.
    stiffness_load_exponent : float
        Exponent q of the tire stiffness's load dependence, -: a wheel with load F_z uses
        B (F_z,static / F_z)^q, so its cornering stiffness grows like F_z^(1 - q) (real tires:
        sublinear). B_f, B_r are the values at the static loads. Without it (q = 0) the high CoG
        makes the car spin under moderate braking in corners.
    min_lateral_share : float
        Share of a wheel's lateral grip kept when its longitudinal force is at the friction limit, -
        (friction ellipse; an idealized ABS / traction control keeps the wheel rolling).
    tcs_floor : float
        Traction control: a driven wheel's drive force is capped at f_peak sqrt(1 - s_y^2), s_y the
        wheel's lateral use of its peak, but never below tcs_floor f_peak, -. 1.0 switches traction
        control off. Without it full throttle out of a hairpin spins this rear-driven car.
    abs_share : float or None
        Anti-lock brakes: a wheel's brake force is capped at f_peak sqrt(abs_share^2 - s_y^2)
        (never below tcs_floor f_peak), so a braking wheel keeps at least sqrt(1 - abs_share^2)
        of its lateral grip, -. Gran Turismo's cars brake with ABS by default. None: no ABS (a
        wheel brakes up to its peak and keeps only min_lateral_share); then a hard stop on a
        gentle curve locks the lightly loaded rear and spins the car.
    c_rr : float
        Rolling resistance coefficient, - (R_x = c_rr F_z; road tires 0.010-0.015).
    r_w : float
        Loaded wheel radius, m (185/60 R16 tire).
    engine_rpm : tuple of float
        Engine speed grid of the full-load torque curve, rpm, increasing.
    engine_torque_max : tuple of float
        Full-load engine torque on that grid, N m (1.5 l diesel: 250 N m from 1500 to 2500 rpm,
        77 kW at 4000 rpm); zero at the last point, the rev limiter.
    power_max : float
        Engine power limit, W (77 kW). Throttle u_p scales the full-load torque; pedal 0 coasts
        (the model has no engine braking).
    launch_rpm : float
        Engine speed held by the slipping clutch at low vehicle speed, rpm.
    gear_ratios : tuple of float
        Gearbox ratios, first to top gear, -.
    final_drive : float
        Final drive ratio, -. With the top gear it puts the rev limiter at about 53 m/s.
    driveline_efficiency : float
        Engine-to-wheel efficiency, -.
    upshift_rpm : float
        Automatic gearbox shifts up above this engine speed, rpm.
    downshift_rpm : float
        Automatic gearbox shifts down below this engine speed, rpm.
    shift_time : float
        Drive torque is cut for this long during a shift, s.
    brake_force_max : float
        Total brake force at full pedal before the tire limit, N (about 1.2 m g, so that a full
        brake is tire-limited at the front).
    brake_front_share : float
        Share of the brake force on the front axle, -.
    steer_max : float
        Road-wheel steering angle limit, rad.
    steer_rate_max : float
        Steering rate limit of the actuator, rad/s.
    steer_tau : float
        Time constant of the steering actuator's first-order lag, s.
    offtrack_mu_factor : float
        Friction on grass / run-off relative to the track, - (open tracks).
    wall_mu : float
        Friction coefficient between the body and a wall, - (tangential impulse <= wall_mu times
        the normal impulse of a contact).
    wall_entry_keep : float
        Share of the speed kept when a wall contact begins (impact losses beyond friction), -.
    wall_release_gap : float
        A contact episode ends only once the body is this far from the wall, m (so scraping along a
        wall counts as one contact).
    steer_noise_std : float
        Standard deviation of the actuation noise added to each steering command, rad (per trial
        randomness, drawn per control step).
    pedal_noise_std : float
        Standard deviation of the noise added to each pedal command, -.
    mu_variation_std : float
        Relative standard deviation of the per-trial friction variation, - (mu (1 + std N(0, 1))).
    v_min_slip : float
        Lower clamp of the speed in slip-angle denominators, m/s (keeps the low-speed dynamics
        bounded and the integrator stable).
    v_smooth : float
        Speed scale of the smooth sign used for rolling resistance and brakes, m/s (forces fade to
        zero at standstill instead of pushing the car backwards).
    """

    # --- the paper's table ---
    m: float = 1355.2
    l_f: float = 0.9338
    l_r: float = 1.6363
    width: float = 2.008
    h_c: float = 0.6161
    mu: float = 1.25
    C_xw: float = 0.1302
    I_zz: float = 2475.33
    # --- geometry ---
    g: float = G
    l_t: float = 1.48
    overhang_front: float = 0.83
    overhang_rear: float = 0.66
    # --- tires ---
    B_f: float = 8.0
    C_f: float = 1.9
    D_f: float = 1.0
    B_r: float = 14.0
    C_r: float = 1.9
    D_r: float = 1.0
    load_sensitivity: float = 0.1
    stiffness_load_exponent: float = 0.5
    min_lateral_share: float = 0.1
    tcs_floor: float = 0.2
    abs_share: float | None = 0.9
    c_rr: float = 0.012
    r_w: float = 0.30
    # --- powertrain (rear-wheel drive) ---
    engine_rpm: tuple[float, ...] = (
        1000.0, 1500.0, 2000.0, 2500.0, 3000.0, 3500.0, 4000.0, 4500.0, 5000.0, 5200.0,
    )  # fmt: skip
    engine_torque_max: tuple[float, ...] = (
        160.0, 250.0, 250.0, 250.0, 240.0, 215.0, 184.0, 160.0, 135.0, 0.0,
    )  # fmt: skip
    power_max: float = 77_000.0
    launch_rpm: float = 1500.0
    gear_ratios: tuple[float, ...] = (3.60, 2.10, 1.40, 1.05, 0.87, 0.74)
    final_drive: float = 4.10
    driveline_efficiency: float = 0.92
    upshift_rpm: float = 4800.0
    downshift_rpm: float = 2200.0
    shift_time: float = 0.2
    # --- brakes ---
    brake_force_max: float = 16_000.0
    brake_front_share: float = 0.8
    # --- steering actuator ---
    steer_max: float = 0.5
    steer_rate_max: float = 1.2
    steer_tau: float = 0.08
    # --- environment ---
    offtrack_mu_factor: float = 0.6
    wall_mu: float = 0.5
    wall_entry_keep: float = 0.95
    wall_release_gap: float = 0.05
    # --- per-trial randomness ---
    steer_noise_std: float = 0.002
    pedal_noise_std: float = 0.01
    mu_variation_std: float = 0.005
    # --- numerics ---
    v_min_slip: float = 1.0
    v_smooth: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            values = value if isinstance(value, tuple) else (value,)
            if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
                raise ModelError(
                    f"VehicleParams.{f.name} = {value!r} is not a finite number; "
                    "pass finite floats (see the VehicleParams docstring for units)."
                )
        positive = ("m", "l_f", "l_r", "width", "h_c", "mu", "I_zz", "g", "l_t", "r_w",
                    "power_max", "final_drive", "driveline_efficiency", "steer_max",
                    "steer_rate_max", "steer_tau", "v_min_slip", "v_smooth")  # fmt: skip
        for name in positive:
            if getattr(self, name) <= 0.0:
                raise ModelError(f"VehicleParams.{name} must be > 0, got {getattr(self, name)}.")
        if len(self.engine_rpm) != len(self.engine_torque_max) or len(self.engine_rpm) < 2:
            raise ModelError(
                "VehicleParams.engine_rpm and engine_torque_max must have the same length (>= 2)."
            )
        if any(b <= a for a, b in zip(self.engine_rpm, self.engine_rpm[1:], strict=False)):
            raise ModelError("VehicleParams.engine_rpm must be strictly increasing.")
        if not self.gear_ratios or any(r <= 0 for r in self.gear_ratios):
            raise ModelError("VehicleParams.gear_ratios must be a non-empty tuple of ratios > 0.")
        if not 0.0 <= self.brake_front_share <= 1.0:
            raise ModelError("VehicleParams.brake_front_share must lie in [0, 1].")

    @property
    def wheelbase(self) -> float:
        """l_f + l_r, m."""
        return self.l_f + self.l_r

    @property
    def F_z0(self) -> float:
        """Nominal wheel load m g / 4, N (reference of the tire load sensitivity)."""
        return self.m * self.g / 4.0


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


def ops_for(*args: Any) -> Any:
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


def pacejka_lateral(alpha: Any, F_z: Any, mu: Any, B: Any, C: Any, D: Any) -> Any:
    """Simplified Pacejka magic formula F_y = mu F_z D sin(C atan(B alpha)) (paper Eq. 9-10).

    Parameters
    ----------
    alpha : slip angle, rad.
    F_z : vertical load, N.
    mu : friction coefficient, -.
    B, C, D : stiffness, shape and peak factors, -.

    Returns
    -------
    Lateral tire force, N (same type as the inputs).
    """
    ops = ops_for(alpha, F_z, mu, B, C, D)
    return mu * F_z * D * ops.sin(C * ops.atan(B * alpha))


def axle_cornering_stiffness(F_z: float, mu: float, B: float, C: float, D: float) -> float:
    """Slope of `pacejka_lateral` at zero slip, mu F_z D B C, N/rad."""
    return mu * F_z * D * B * C


def drag_force(v_x: Any, C_xw: float) -> Any:
    """Aerodynamic drag F_xw = C_xw v_x^2 (paper Eq. 7), N, acting against the motion."""
    ops = ops_for(v_x)
    return C_xw * v_x * ops.fabs(v_x)


def rolling_resistance(F_z: Any, c_rr: float) -> Any:
    """Rolling resistance R_x = c_rr F_z, N (magnitude; it acts against the motion)."""
    return c_rr * F_z


def static_axle_loads(
    m: float,
    l_f: float,
    l_r: float,
    g: float = G,
    theta: Any = 0.0,
    a_z: Any = 0.0,
    ops: Any = None,
) -> tuple[Any, Any]:
    """Axle loads without load transfer, m (g cos(theta) + a_z) l_{r,f} / (l_f + l_r) (Eq. 11-12).

    Returns
    -------
    (F_zf, F_zr) : front and rear axle loads, N.
    """
    ops = ops or ops_for(theta, a_z)
    w = m * (g * ops.cos(theta) + a_z) / (l_f + l_r)
    return w * l_r, w * l_f


def longitudinal_load_transfer(m: float, a_x: Any, h_c: float, l_f: float, l_r: float) -> Any:
    """Longitudinal load transfer Delta W = m a_x h_c / (l_f + l_r) (paper Eq. 11), N.

    Positive `a_x` (accelerating) moves load from the front to the rear axle.
    """
    return m * a_x * h_c / (l_f + l_r)


def lateral_load_transfer(
    m: float, a_y: Any, h_c: float, l_t: float, l_f: float, l_r: float
) -> tuple[Any, Any]:
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
    p: VehicleParams, a_x: Any, a_y: Any, theta: Any = 0.0, ops: Any = None
) -> tuple[Any, Any, Any, Any]:
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


def engine_torque_ops(p: VehicleParams, rpm: Any, ops: Any = None) -> Any:
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


def drive_force_envelope(p: VehicleParams, v_x: Any, ops: Any = None) -> Any:
    """Largest full-throttle drive force over all gears at speed v_x, N (any backend).

    The smooth-ish envelope of the gearbox (max over gears), for planners that treat the gear choice
    as ideal. Tire friction is not included.
    """
    ops = ops or ops_for(v_x)
    best = None
    for k, ratio_g in enumerate(p.gear_ratios, start=1):
        ratio = ratio_g * p.final_drive
        rpm = ops.fmax(v_x / p.r_w * ratio * _RPM_PER_RAD_S, p.launch_rpm)
        f = engine_torque_ops(p, rpm, ops) * ratio * p.driveline_efficiency / p.r_w
        best = f if k == 1 else ops.fmax(best, f)
    return best
