"""CommonRoad's single-track drift model (``std``) transcribed into CasADi, for compilation.

A faithful, line-by-line transcription of
``vehiclemodels.vehicle_dynamics_std.vehicle_dynamics_std`` (commonroad-vehicle-models 3.0.2,
TUM, BSD licence) and of what it calls:
``vehiclemodels.utils.steering_constraints.steering_constraints``,
``vehiclemodels.utils.acceleration_constraints.acceleration_constraints``,
``vehiclemodels.utils.vehicle_dynamics_ks_cog.vehicle_dynamics_ks_cog`` and the Pacejka formulas of
``vehiclemodels.utils.tire_model`` (camber ``gamma = 0``, as ``std`` calls them). Every branch of
the package's Python becomes a ``casadi.if_else``, every ``max`` an ``fmax``; the order of the
floating-point operations is the package's, so the transcription computes the same derivative to
rounding (``tests/test_plants.py`` compares the two at many random states, to 1e-12 relative).

The package's function stays the reference: :class:`racing_lib.plants.commonroad.CommonRoadCar`
calls it directly with ``engine="python"``. This module imports nothing from the package; it reads
the parameters from the package's ``VehicleParameters`` object it is given.

State (9, the package's order and units): x, y of the centre of gravity (m), front-wheel steering
angle delta (rad), speed of the centre of gravity v (m/s), yaw angle psi (rad), yaw rate (rad/s),
slip angle at the centre of gravity beta (rad), front and rear wheel angular speeds (rad/s).
Input (2): steering-angle velocity (rad/s), longitudinal acceleration (m/s^2).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca

if TYPE_CHECKING:  # the optional extra's parameter class, named for the signatures only
    from vehiclemodels.vehicle_parameters import VehicleParameters

#: A value of the transcription: a CasADi expression (it is built on SX symbols and compiled),
#: or a float where a parameter or a constant enters.
Expr = ca.SX | ca.MX | ca.DM | float

__all__ = ["N_INPUT", "N_STATE", "Expr", "std_vector_field"]

#: Number of states of the ``std`` model.
N_STATE = 9
#: Number of inputs of the ``std`` model.
N_INPUT = 2

G = 9.81  # m/s^2, the package's own value in vehicle_dynamics_std
V_S, V_B = 0.2, 0.05  # m/s: centre and width of the blend to the kinematic model
V_MIN = V_S / 2  # m/s: below this speed the slip angles are zero


def steering_constraints(
    steering_angle: Expr, steering_velocity: Expr, p: VehicleParameters
) -> Expr:
    """Transcription of ``vehiclemodels.utils.steering_constraints.steering_constraints``.

    The steering-angle velocity (rad/s) clipped to ``[p.v_min, p.v_max]``, and zero when the
    angle (rad) is at a limit ``p.min``/``p.max`` and the velocity points beyond it.
    """
    at_limit = ca.logic_or(
        ca.logic_and(steering_angle <= p.min, steering_velocity <= 0),
        ca.logic_and(steering_angle >= p.max, steering_velocity >= 0),
    )
    clipped = ca.if_else(
        steering_velocity <= p.v_min,
        p.v_min,
        ca.if_else(steering_velocity >= p.v_max, p.v_max, steering_velocity),
    )
    return ca.if_else(at_limit, 0, clipped)


def acceleration_constraints(velocity: Expr, acceleration: Expr, p: VehicleParameters) -> Expr:
    """Transcription of ``vehiclemodels.utils.acceleration_constraints.acceleration_constraints``.

    The acceleration (m/s^2) clipped to ``[-p.a_max, a_pos]`` with the power limit
    ``a_pos = p.a_max p.v_switch / v`` above ``p.v_switch`` (``p.a_max`` below), and zero beyond
    the speed limits ``p.v_min``/``p.v_max`` (m/s) when it points beyond them.
    """
    pos_limit = ca.if_else(velocity > p.v_switch, p.a_max * p.v_switch / velocity, p.a_max)
    at_limit = ca.logic_or(
        ca.logic_and(velocity <= p.v_min, acceleration <= 0),
        ca.logic_and(velocity >= p.v_max, acceleration >= 0),
    )
    clipped = ca.if_else(
        acceleration <= -p.a_max,
        -p.a_max,
        ca.if_else(acceleration >= pos_limit, pos_limit, acceleration),
    )
    return ca.if_else(at_limit, 0, clipped)


def _magic(b: Expr, e: Expr, z: Expr) -> Expr:
    """``atan(B z - E (B z - atan(B z)))``, the core of every Pacejka formula of the package."""
    return ca.atan(b * z - e * (b * z - ca.atan(b * z)))


def formula_longitudinal(kappa: Expr, f_z: Expr, t: Expr) -> Expr:
    """Transcription of ``tire_model.formula_longitudinal`` at camber 0: pure-slip F_x, N."""
    kappa = -kappa
    s_hx = t.p_hx1
    s_vx = f_z * t.p_vx1
    kappa_x = kappa + s_hx
    mu_x = t.p_dx1 * (1 - t.p_dx3 * 0**2)
    c_x = t.p_cx1
    d_x = mu_x * f_z
    e_x = t.p_ex1
    k_x = f_z * t.p_kx1
    b_x = k_x / (c_x * d_x)
    # The package adds the vertical shift S_vx inside the sine; transcribed as it is.
    return d_x * ca.sin(c_x * _magic(b_x, e_x, kappa_x) + s_vx)


def formula_lateral(alpha: Expr, f_z: Expr, t: Expr) -> tuple[Expr, Expr]:
    """Transcription of ``tire_model.formula_lateral`` at camber 0: (pure-slip F_y in N, mu_y)."""
    # sign(gamma) = 0 at camber 0: the shifts S_hy and S_vy vanish (as +0.0 and +-0.0).
    s_hy = 0 * (t.p_hy1 + t.p_hy3 * 0)
    s_vy = 0 * f_z * (t.p_vy1 + t.p_vy3 * 0)
    alpha_y = alpha + s_hy
    mu_y = t.p_dy1 * (1 - t.p_dy3 * 0**2)
    c_y = t.p_cy1
    d_y = mu_y * f_z
    e_y = t.p_ey1
    k_y = f_z * t.p_ky1
    b_y = k_y / (c_y * d_y)
    f_y = d_y * ca.sin(c_y * _magic(b_y, e_y, alpha_y)) + s_vy
    return f_y, mu_y


def formula_longitudinal_comb(kappa: Expr, alpha: Expr, f0_x: Expr, t: Expr) -> Expr:
    """Transcription of ``tire_model.formula_longitudinal_comb``: combined-slip F_x, N."""
    s_hxalpha = t.r_hx1
    alpha_s = alpha + s_hxalpha
    b_xalpha = t.r_bx1 * ca.cos(ca.atan(t.r_bx2 * kappa))
    c_xalpha = t.r_cx1
    e_xalpha = t.r_ex1
    d_xalpha = f0_x / (ca.cos(c_xalpha * _magic(b_xalpha, e_xalpha, s_hxalpha)))
    return d_xalpha * ca.cos(c_xalpha * _magic(b_xalpha, e_xalpha, alpha_s))


def formula_lateral_comb(
    kappa: Expr, alpha: Expr, mu_y: Expr, f_z: Expr, f0_y: Expr, t: Expr
) -> Expr:
    """Transcription of ``tire_model.formula_lateral_comb`` at camber 0: combined-slip F_y, N."""
    s_hykappa = t.r_hy1
    kappa_s = kappa + s_hykappa
    b_ykappa = t.r_by1 * ca.cos(ca.atan(t.r_by2 * (alpha - t.r_by3)))
    c_ykappa = t.r_cy1
    e_ykappa = t.r_ey1
    d_ykappa = f0_y / (ca.cos(c_ykappa * _magic(b_ykappa, e_ykappa, s_hykappa)))
    d_vykappa = mu_y * f_z * (t.r_vy1 + t.r_vy3 * 0) * ca.cos(ca.atan(t.r_vy4 * alpha))
    s_vykappa = d_vykappa * ca.sin(t.r_vy5 * ca.atan(t.r_vy6 * kappa))
    return d_ykappa * ca.cos(c_ykappa * _magic(b_ykappa, e_ykappa, kappa_s)) + s_vykappa


def _kinematic(x: list[Expr], u: list[Expr], p: VehicleParameters) -> tuple[Expr, Expr]:
    """(dv, dpsi) of ``vehicle_dynamics_ks_cog`` (the kinematic model about the CoG), transcribed.

    The function re-applies the acceleration constraints to an input that already meets them,
    as the package's does (its steering output, f[2], is not used by ``std``).
    """
    l_wb = p.a + p.b
    u1 = acceleration_constraints(x[3], u[1], p.longitudinal)
    beta = ca.atan(ca.tan(x[2]) * p.b / l_wb)
    return u1, x[3] * ca.cos(beta) * ca.tan(x[2]) / l_wb


def std_vector_field(x: list[Expr], u_init: list[Expr], p: VehicleParameters) -> list[Expr]:
    """The right-hand side of CommonRoad's ``std`` model, on CasADi symbols.

    Transcribes ``vehiclemodels.vehicle_dynamics_std.vehicle_dynamics_std`` (version 2020a, as
    shipped in commonroad-vehicle-models 3.0.2), statement by statement.

    Parameters
    ----------
    x : list of 9 casadi.SX
        The state in the package's order (see the module docstring; SI units).
    u_init : list of 2 casadi.SX
        Steering-angle velocity, rad/s, and longitudinal acceleration, m/s^2, before the
        package's constraints (applied here, as in the package).
    p : vehiclemodels.vehicle_parameters.VehicleParameters
        The vehicle; its values become constants of the expression.

    Returns
    -------
    list of 9 casadi.SX
        The time derivative of the state.
    """
    lf, lr, lwb, m, inertia = p.a, p.b, p.a + p.b, p.m, p.I_z
    delta, v, psi, r, beta, om_f, om_r = x[2], x[3], x[4], x[5], x[6], x[7], x[8]
    u = [
        steering_constraints(delta, u_init[0], p.steering),
        acceleration_constraints(v, u_init[1], p.longitudinal),
    ]
    moving = v > V_MIN
    alpha_f = ca.if_else(
        moving, ca.atan((v * ca.sin(beta) + r * lf) / (v * ca.cos(beta))) - delta, 0
    )
    alpha_r = ca.if_else(moving, ca.atan((v * ca.sin(beta) - r * lr) / (v * ca.cos(beta))), 0)
    f_zf = m * (-u[1] * p.h_s + G * lr) / (lr + lf)
    f_zr = m * (u[1] * p.h_s + G * lf) / (lr + lf)
    u_wf = ca.fmax(
        0, v * ca.cos(beta) * ca.cos(delta) + (v * ca.sin(beta) + p.a * r) * ca.sin(delta)
    )
    u_wr = ca.fmax(0, v * ca.cos(beta))
    s_f = 1 - p.R_w * om_f / ca.fmax(u_wf, V_MIN)
    s_r = 1 - p.R_w * om_r / ca.fmax(u_wr, V_MIN)
    t = p.tire
    f0_xf = formula_longitudinal(s_f, f_zf, t)
    f0_xr = formula_longitudinal(s_r, f_zr, t)
    f0_yf, mu_yf = formula_lateral(alpha_f, f_zf, t)
    f0_yr, mu_yr = formula_lateral(alpha_r, f_zr, t)
    f_xf = formula_longitudinal_comb(s_f, alpha_f, f0_xf, t)
    f_xr = formula_longitudinal_comb(s_r, alpha_r, f0_xr, t)
    f_yf = formula_lateral_comb(s_f, alpha_f, mu_yf, f_zf, f0_yf, t)
    f_yr = formula_lateral_comb(s_r, alpha_r, mu_yr, f_zr, f0_yr, t)
    t_b = ca.if_else(u[1] > 0, 0.0, m * p.R_w * u[1])
    t_e = ca.if_else(u[1] > 0, m * p.R_w * u[1], 0.0)

    d_v = 1 / m * (-f_yf * ca.sin(delta - beta) + f_yr * ca.sin(beta) + f_xr * ca.cos(beta)
                   + f_xf * ca.cos(delta - beta))  # fmt: skip
    dd_psi = 1 / inertia * (f_yf * ca.cos(delta) * lf - f_yr * lr + f_xf * ca.sin(delta) * lf)
    d_beta = ca.if_else(
        moving,
        -r + 1 / (m * v) * (f_yf * ca.cos(delta - beta) + f_yr * ca.cos(beta)
                            - f_xr * ca.sin(beta) + f_xf * ca.sin(delta - beta)),
        0,
    )  # fmt: skip
    # Wheel dynamics; the package forbids negative wheel spin (and clamps the state after use).
    d_om_f = ca.if_else(om_f >= 0, 1 / p.I_y_w * (-p.R_w * f_xf + p.T_sb * t_b + p.T_se * t_e), 0)
    d_om_r = ca.if_else(
        om_r >= 0, 1 / p.I_y_w * (-p.R_w * f_xr + (1 - p.T_sb) * t_b + (1 - p.T_se) * t_e), 0
    )
    om_f, om_r = ca.fmax(0, om_f), ca.fmax(0, om_r)

    # The kinematic model, blended in at low speed.
    dv_ks, dpsi_ks = _kinematic([x[0], x[1], delta, v, psi], u, p)
    d_beta_ks = (p.b * u[0]) / (
        lwb * ca.cos(delta) ** 2 * (1 + (ca.tan(delta) ** 2 * p.b / lwb) ** 2)
    )
    dd_psi_ks = 1 / lwb * (u[1] * ca.cos(beta) * ca.tan(delta)
                           - v * ca.sin(beta) * d_beta_ks * ca.tan(delta)
                           + v * ca.cos(beta) * u[0] / ca.cos(delta) ** 2)  # fmt: skip
    d_om_f_ks = (1 / 0.02) * (u_wf / p.R_w - om_f)
    d_om_r_ks = (1 / 0.02) * (u_wr / p.R_w - om_r)
    w_std = 0.5 * (ca.tanh((v - V_S) / V_B) + 1)
    w_ks = 1 - w_std
    return [
        v * ca.cos(beta + psi),
        v * ca.sin(beta + psi),
        u[0],
        w_std * d_v + w_ks * dv_ks,
        w_std * r + w_ks * dpsi_ks,
        w_std * dd_psi + w_ks * dd_psi_ks,
        w_std * d_beta + w_ks * d_beta_ks,
        w_std * d_om_f + w_ks * d_om_f_ks,
        w_std * d_om_r + w_ks * d_om_r_ks,
    ]
