"""The simulated car's equations of motion: one vector field for the plant and the best-lap planner.

`car_vector_field` is the smooth part of the double-track physics (tyres with load sensitivity and
combined slip, drag, rolling resistance, grade, the steering actuator). It runs on floats (the
simulated car integrates it with RK4) and on CasADi symbols (the best-lap planner optimizes a lap
with it), so both import it from here instead of from each other. The discrete parts (gear choice,
walls, edge friction) stay in `racing_lib.sim.SimulatedCar`.

`rk4_substep_function` is one RK4 substep of that same vector field as a CasADi Function: the
simulated car compiles it (`racing_lib.jit`) and evaluates it in place
(`racing_lib.jit.BufferedFunction`), many times faster than the float path, with the equations
still written once.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from enum import IntEnum
from typing import TYPE_CHECKING

from racing_lib.vehicle.forces import (
    CASADI_OPS,
    MATH_OPS,
    MathOps,
    Numeric,
    drag_force,
    slip_angles,
    wheel_loads,
)
from racing_lib.vehicle.params import VehicleParams

if TYPE_CHECKING:
    # casadi is imported where a Function is built: the simulator's float path never needs it
    import casadi as ca

__all__ = [
    "N_STATE",
    "RK4_IN",
    "RK4_OUT",
    "SimState",
    "car_vector_field",
    "rk4_substep_function",
    "tyre_limits",
]


class SimState(IntEnum):
    """Indices of the simulator's continuous state."""

    X = 0  #: position x, m
    Y = 1  #: position y, m
    PSI = 2  #: yaw angle, rad
    VX = 3  #: longitudinal velocity (body frame), m/s
    VY = 4  #: lateral velocity (body frame, left positive), m/s
    R = 5  #: yaw rate, rad/s
    DELTA = 6  #: actual road-wheel steering angle, rad


N_STATE = len(SimState)
# Plain-int copies of the indices for the hot path (IntEnum lookups cost time there).
_PSI, _VX, _VY, _R, _DELTA = (int(SimState[n]) for n in ("PSI", "VX", "VY", "R", "DELTA"))


def tyre_limits(
    p: VehicleParams,
    fz: Numeric,
    fz_static: float,
    mu: Numeric,
    b: float,
    c: float,
    d: float,
    alpha: Numeric,
    ops: MathOps,
    floor_max: Callable[[Numeric, float], Numeric] | None = None,
) -> tuple[Numeric, Numeric, Numeric, Numeric]:
    """Force limits of one wheel: the simulated car's tyre law (floats, arrays or CasADi).

    Parameters
    ----------
    p : VehicleParams
        The car.
    fz : load on the wheel, N; fz_static : its static value on flat ground, N.
    mu : friction coefficient under the wheel, -; b, c, d : its axle's Pacejka B (1/rad), C, D.
    alpha : slip angle, rad.
    ops : the backend's math (``racing_lib.vehicle.ops_for``).
    floor_max : callable, optional
        ``max(a, floor^2)`` used for the traction control and ABS floors (default ``ops.fmax``);
        planners pass a rounded one, since a kink in a constraint makes IPOPT cycle.

    Returns
    -------
    f_peak : peak force with load sensitivity, N.
    shape : lateral use of the peak in pure slip, ``sin(C atan(B_eff alpha))``, -; the stiffness
        grows less than the load (``B_eff = B (fz_static / fz)^q``).
    f_drive_max : traction control, drive force up to what the lateral use leaves of the circle, N.
    f_brake_max : ABS, brake force up to what keeps part of the lateral grip, N.
    """
    floor_max = floor_max or ops.fmax
    f_peak = mu * fz * d * (1.0 - p.load_sensitivity * (fz - p.F_z0) / p.F_z0)
    b_eff = b * (fz_static / ops.fmax(fz, 1.0)) ** p.stiffness_load_exponent
    shape = ops.sin(c * ops.atan(b_eff * alpha))
    floor2 = 1.0 if p.tcs_floor >= 1.0 else p.tcs_floor * p.tcs_floor
    f_drive_max = f_peak * ops.sqrt(floor_max(1.0 - shape * shape, floor2))
    if p.abs_share is None:
        f_brake_max = f_peak
    else:
        f_brake_max = f_peak * ops.sqrt(floor_max(p.abs_share**2 - shape * shape, floor2))
    return f_peak, shape, f_drive_max, f_brake_max


def car_vector_field(
    state: Sequence[Numeric],
    delta_cmd: Numeric,
    f_drive: Numeric,
    f_brake: Numeric,
    theta: Numeric,
    mu_wheels: tuple[Numeric, Numeric, Numeric, Numeric],
    a_transfer: tuple[Numeric, Numeric],
    p: VehicleParams,
    ops: MathOps = MATH_OPS,
) -> tuple[tuple[Numeric, ...], tuple[Numeric, Numeric]]:
    """Continuous-time dynamics of the simulated car (the smooth part).

    Works with floats (``ops=MATH_OPS``, the simulator's fast path) and with CasADi symbols
    (``ops=CASADI_OPS``); min/max are the only non-smooth operations.

    Parameters
    ----------
    state : sequence of 7
        [x, y, psi, v_x, v_y, r, delta] (see `SimState`), m, m, rad, m/s, m/s, rad/s, rad.
    delta_cmd : steering command after the angle limit, rad.
    f_drive : total drive force the powertrain delivers to the rear wheels (before the tyre
        limit), N, >= 0.
    f_brake : total brake force (before the split and the tyre limit), N, >= 0.
    theta : road pitch, rad (positive uphill).
    mu_wheels : friction coefficients of the wheels (FL, FR, RL, RR), -.
    a_transfer : (a_x, a_y), the accelerations that set the load transfer, m/s^2. The wheel loads
        depend on the tyre forces, which depend on the loads (an algebraic loop). The simulator
        closes it quasi-statically with the ground-force accelerations of the previous substep
        (returned here as the second output); a planner can make them decision variables with the
        constraint a_transfer == returned accelerations.
    p : vehicle parameters.
    ops : math backend (`racing_lib.vehicle.MATH_OPS` or `CASADI_OPS`).

    Returns
    -------
    d_state : tuple of 7
        Time derivative of the state.
    a_ground : (a_x, a_y)
        Accelerations of the ground forces on the tyres (drive, brake, rolling, lateral), body
        frame, m/s^2: the load-transfer input for the next substep.
    """
    psi, vx, vy, r, delta = state[_PSI], state[_VX], state[_VY], state[_R], state[_DELTA]
    sin, cos, fmin, fmax = ops.sin, ops.cos, ops.fmin, ops.fmax
    m = p.m
    sd, cd = sin(delta), cos(delta)

    # Vertical loads (double track, longitudinal + lateral transfer, paper Eq. 11-13).
    fz_fl, fz_fr, fz_rl, fz_rr = wheel_loads(p, a_transfer[0], a_transfer[1], theta, ops)

    # Slip angles; the speed in the denominator is clamped so the dynamics stay bounded near
    # standstill (the car is not meant to reverse).
    vx_s = fmax(ops.fabs(vx), p.v_min_slip)
    alpha_f, alpha_r = slip_angles(vx_s, vy, r, delta, p.l_f, p.l_r, ops, small_angle=False)

    # Smooth sign of the motion: brakes and rolling resistance fade out at standstill.
    sgn = ops.tanh(vx / p.v_smooth)
    fb_f = -0.5 * p.brake_front_share * f_brake * sgn  # per front wheel, N
    fb_r = -0.5 * (1.0 - p.brake_front_share) * f_brake * sgn  # per rear wheel, N
    fx_r_cmd = 0.5 * f_drive + fb_r  # rear-wheel drive, equal split (ideal differential)

    min_share2 = p.min_lateral_share * p.min_lateral_share
    w_half = 0.5 * m * p.g / (p.l_f + p.l_r)
    fzs_f, fzs_r = w_half * p.l_r, w_half * p.l_f  # static wheel loads on flat ground, N

    def wheel(
        fz: Numeric,
        fz_static: float,
        mu: Numeric,
        b: float,
        c: float,
        d: float,
        alpha: Numeric,
        fx_cmd: Numeric,
    ) -> tuple[Numeric, Numeric]:
        # The longitudinal force is limited by the peak, traction control and ABS; the lateral
        # force gets what is left of the friction ellipse.
        f_peak, shape, f_drive_max, f_brake_max = tyre_limits(
            p, fz, fz_static, mu, b, c, d, alpha, ops
        )
        fx = fmin(fmax(fx_cmd, -f_brake_max), fmin(f_peak, f_drive_max))
        share = ops.sqrt(fmax(1.0 - fx * fx / (f_peak * f_peak + 1.0), min_share2))
        return fx, f_peak * shape * share

    fx_fl, fy_fl = wheel(fz_fl, fzs_f, mu_wheels[0], p.B_f, p.C_f, p.D_f, alpha_f, fb_f)
    fx_fr, fy_fr = wheel(fz_fr, fzs_f, mu_wheels[1], p.B_f, p.C_f, p.D_f, alpha_f, fb_f)
    fx_rl, fy_rl = wheel(fz_rl, fzs_r, mu_wheels[2], p.B_r, p.C_r, p.D_r, alpha_r, fx_r_cmd)
    fx_rr, fy_rr = wheel(fz_rr, fzs_r, mu_wheels[3], p.B_r, p.C_r, p.D_r, alpha_r, fx_r_cmd)

    # Front wheel forces rotated by the steering angle into the body frame.
    fxb_fl, fyb_fl = fx_fl * cd - fy_fl * sd, fx_fl * sd + fy_fl * cd
    fxb_fr, fyb_fr = fx_fr * cd - fy_fr * sd, fx_fr * sd + fy_fr * cd
    rolling = p.c_rr * (fz_fl + fz_fr + fz_rl + fz_rr) * sgn
    f_x = fxb_fl + fxb_fr + fx_rl + fx_rr - rolling
    f_y = fyb_fl + fyb_fr + fy_rl + fy_rr
    half_t = 0.5 * p.l_t
    m_z = (
        p.l_f * (fyb_fl + fyb_fr)
        - p.l_r * (fy_rl + fy_rr)
        + half_t * (fxb_fr - fxb_fl + fx_rr - fx_rl)  # left wheels sit at y = +l_t/2
    )
    drag = drag_force(vx, p.C_xw, ops)

    d_vx = (f_x - drag) / m - p.g * sin(theta) + r * vy
    d_vy = f_y / m - r * vx
    d_r = m_z / p.I_zz
    sp, cp = sin(psi), cos(psi)
    d_x = vx * cp - vy * sp
    d_y = vx * sp + vy * cp
    # Steering actuator: first-order lag, rate-limited.
    d_delta = fmin(fmax((delta_cmd - delta) / p.steer_tau, -p.steer_rate_max), p.steer_rate_max)
    return (d_x, d_y, r, d_vx, d_vy, d_r, d_delta), (f_x / m, f_y / m)


#: Layout of the input of :func:`rk4_substep_function`: name -> (first index, length).
RK4_IN = {
    "state": (0, N_STATE),
    "delta_cmd": (7, 1),
    "f_drive": (8, 1),
    "f_brake": (9, 1),
    "theta": (10, 1),
    "mu_wheels": (11, 4),
    "a_transfer": (15, 2),
    "h": (17, 1),
}
#: Layout of its output: the new state, the ground-force accelerations at the end of the substep
#: (the next substep's load transfer) and d(v_x)/dt, d(v_y)/dt there.
RK4_OUT = {"state": (0, N_STATE), "a_ground": (7, 2), "d_vx_vy": (9, 2)}


@functools.lru_cache(maxsize=16)
def rk4_substep_function(p: VehicleParams) -> ca.Function:
    """One classical RK4 substep of :func:`car_vector_field` as a CasADi Function.

    The loads are frozen over the substep (the input ``a_transfer``), as in the simulator.

    Parameters
    ----------
    p : VehicleParams
        The car; its values are baked into the Function (built once per parameter set, in about
        0.1 s).

    Returns
    -------
    casadi.Function
        ``z (18) -> out (11)``, laid out as :data:`RK4_IN` and :data:`RK4_OUT` (SI units as in
        :func:`car_vector_field`; ``h`` in s).
    """
    import casadi as ca  # imported here: the simulator's float path never needs casadi

    z = ca.SX.sym("z", RK4_IN["h"][0] + 1)

    def part(name: str) -> list[ca.SX]:
        first, length = RK4_IN[name]
        return [z[first + i] for i in range(length)]

    y0 = part("state")
    (delta_cmd,), (f_drive,), (f_brake,) = part("delta_cmd"), part("f_drive"), part("f_brake")
    (theta,), (h,) = part("theta"), part("h")
    mu_w, a_tr = tuple(part("mu_wheels")), tuple(part("a_transfer"))

    def field(y: list[ca.SX]) -> tuple[tuple[Numeric, ...], tuple[Numeric, Numeric]]:
        return car_vector_field(y, delta_cmd, f_drive, f_brake, theta, mu_w, a_tr, p, CASADI_OPS)

    k1, _ = field(y0)
    k2, _ = field([a + 0.5 * h * b for a, b in zip(y0, k1, strict=True)])
    k3, _ = field([a + 0.5 * h * b for a, b in zip(y0, k2, strict=True)])
    k4, a_g = field([a + h * b for a, b in zip(y0, k3, strict=True)])
    c = h / 6.0
    new = [
        a + c * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
        for a, b1, b2, b3, b4 in zip(y0, k1, k2, k3, k4, strict=True)
    ]
    out = ca.vertcat(*new, *a_g, k4[_VX], k4[_VY])
    return ca.Function("car_rk4_substep", [z], [out])
