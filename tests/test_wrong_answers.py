"""A wrong-answer campaign: plausible mistakes a student could make in every exercise check.

Each case is ``(case_id, check, wrong_function, expected_fragments)``: the check must call the
answer wrong (or report an error when the answer raises) with a message that contains every
fragment, words that name the mistake actually made. Most wrong answers are the official solution
(``exercises/make_notebooks.py``) changed in one place, so that they stay close to right. The
answers already in ``tests/test_exercises.py`` are not repeated here.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import casadi as ca
import cvxpy as cp
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from racing_lib.grading import ch01, ch02, ch03, ch04, ch05, ch06
from racing_lib.model import X

EXERCISES = Path(__file__).resolve().parents[1] / "exercises"


def _solutions(name: str) -> dict:
    """The reader's functions as the solution notebook defines them (as test_exercises does)."""
    spec = importlib.util.spec_from_file_location("make_notebooks", EXERCISES / "make_notebooks.py")
    gen = importlib.util.module_from_spec(spec)
    sys.modules["make_notebooks"] = gen  # dataclasses look their module up while being built
    spec.loader.exec_module(gen)
    chapter = {c.name: c for c in gen.CHAPTERS}[name]
    namespace: dict = {}
    exec(chapter.imports, namespace)  # noqa: S102 - our own notebook code
    for ex in chapter.exercises:
        exec(f"{ex.header}\n{ex.solution}", namespace)  # noqa: S102
    return namespace


S1, S2 = _solutions("01_frenet"), _solutions("02_dynamics")
S3, S4 = _solutions("03_curvature"), _solutions("04_time_optimal")
S5, S6 = _solutions("05_mpc"), _solutions("06_tuning")


# --------------------------------------------------------------------------------------------------
# Chapter 01


def _normal_offset(path, s, x, y):
    cx, cy = path.position(s)
    psi = path.heading(s)
    return -(x - cx) * math.sin(psi) + (y - cy) * math.cos(psi)


def _proj_unsigned(path, x, y):  # e_y as the distance, without its sign
    s, e_y = S1["frenet_projection"](path, x, y)
    return s, abs(e_y)


def _proj_one_search(path, x, y):  # one bounded search over the whole lap: a local minimum
    def dist2(s):
        cx, cy = path.position(s)
        return (cx - x) ** 2 + (cy - y) ** 2

    s = minimize_scalar(dist2, bounds=(0.0, path.length), method="bounded").x
    return s, _normal_offset(path, s, x, y)


def _proj_coarse(path, x, y):  # samples every 10 m, but the refinement only looks 1 m around
    samples = path.sample(ds=10.0)
    px, py = path.position(samples)
    s0 = samples[int(np.argmin((px - x) ** 2 + (py - y) ** 2))]

    def dist2(s):
        cx, cy = path.position(s % path.length)
        return (cx - x) ** 2 + (cy - y) ** 2

    s = minimize_scalar(dist2, bounds=(s0 - 1.0, s0 + 1.0), method="bounded").x % path.length
    return s, _normal_offset(path, s, x, y)


def _proj_tangent(path, x, y):  # e_y as the component of p - r along the tangent
    s, _ = S1["frenet_projection"](path, x, y)
    cx, cy = path.position(s)
    psi = path.heading(s)
    return s, (x - cx) * math.cos(psi) + (y - cy) * math.sin(psi)


def _my_frenet(path, x, y):
    return path.to_frenet(x, y)


def _proj_helper(path, x, y):  # the library's projection, through a helper of one's own
    s, e_y, _ = _my_frenet(path, x, y)
    return s, e_y


def _cart_tangent(path, s, e_y):  # e_y added along the tangent instead of the normal
    cx, cy = path.position(s)
    psi = path.heading(s)
    return cx + e_y * math.cos(psi), cy + e_y * math.sin(psi)


def _cart_radians_again(path, s, e_y):  # the heading taken for degrees and converted
    cx, cy = path.position(s)
    psi = math.radians(path.heading(s))
    return cx - e_y * math.sin(psi), cy + e_y * math.cos(psi)


def _my_cartesian(path, s, e_y):
    return path.to_cartesian(s, e_y)[:2]


def _rates(s_dot, e_y_dot, e_psi_dot):
    return s_dot, e_y_dot, e_psi_dot


def _r_times(v_x, v_y, r, e_psi, e_y, kappa):  # multiplies by 1 - kappa e_y instead of dividing
    s_dot = (v_x * math.cos(e_psi) - v_y * math.sin(e_psi)) * (1.0 - kappa * e_y)
    return _rates(s_dot, v_x * math.sin(e_psi) + v_y * math.cos(e_psi), r - kappa * s_dot)


def _r_plus(v_x, v_y, r, e_psi, e_y, kappa):  # 1 + kappa e_y: the inside of a bend made longer
    s_dot = (v_x * math.cos(e_psi) - v_y * math.sin(e_psi)) / (1.0 + kappa * e_y)
    return _rates(s_dot, v_x * math.sin(e_psi) + v_y * math.cos(e_psi), r - kappa * s_dot)


def _r_vy_sign(v_x, v_y, r, e_psi, e_y, kappa):  # + v_y sin e_psi in s_dot
    s_dot = (v_x * math.cos(e_psi) + v_y * math.sin(e_psi)) / (1.0 - kappa * e_y)
    return _rates(s_dot, v_x * math.sin(e_psi) + v_y * math.cos(e_psi), r - kappa * s_dot)


def _r_cos_sin(v_x, v_y, r, e_psi, e_y, kappa):  # cos and sin swapped in e_y_dot
    s_dot, _, e_psi_dot = S1["frenet_rates"](v_x, v_y, r, e_psi, e_y, kappa)
    return s_dot, v_x * math.cos(e_psi) + v_y * math.sin(e_psi), e_psi_dot


def _r_eydot_sign(v_x, v_y, r, e_psi, e_y, kappa):  # - v_y cos e_psi in e_y_dot
    s_dot, _, e_psi_dot = S1["frenet_rates"](v_x, v_y, r, e_psi, e_y, kappa)
    return s_dot, v_x * math.sin(e_psi) - v_y * math.cos(e_psi), e_psi_dot


def _r_kappa_vx(v_x, v_y, r, e_psi, e_y, kappa):  # e_psi_dot = r - kappa v_x: v_x for s_dot
    s_dot, e_y_dot, _ = S1["frenet_rates"](v_x, v_y, r, e_psi, e_y, kappa)
    return s_dot, e_y_dot, r - kappa * v_x


def _r_turned(v_x, v_y, r, e_psi, e_y, kappa):  # e_psi_dot = kappa s_dot - r: the sign reversed
    s_dot, e_y_dot, e_psi_dot = S1["frenet_rates"](v_x, v_y, r, e_psi, e_y, kappa)
    return s_dot, e_y_dot, -e_psi_dot


def _r_degrees(v_x, v_y, r, e_psi, e_y, kappa):  # e_psi taken for degrees
    return S1["frenet_rates"](v_x, v_y, r, math.radians(e_psi), e_y, kappa)


CH01 = [
    ("1.1 unsigned e_y", ch01.check_frenet_projection, _proj_unsigned, ["sign", "LEFT"]),
    ("1.1 one search over the lap", ch01.check_frenet_projection, _proj_one_search,
     ["another part of the track"]),
    ("1.1 refinement narrower than the samples", ch01.check_frenet_projection, _proj_coarse,
     ["refine"]),
    ("1.1 returns (e_y, s)", ch01.check_frenet_projection,
     lambda path, x, y: S1["frenet_projection"](path, x, y)[::-1], ["(e_y, s)", "s first"]),
    ("1.1 e_y along the tangent", ch01.check_frenet_projection, _proj_tangent,
     ["along the track", "normal"]),
    ("1.1 library through a helper", ch01.check_frenet_projection, _proj_helper,
     ["to_frenet", "yourself"]),
    ("1.2 the centerline point", ch01.check_frenet_to_cartesian,
     lambda path, s, e_y: path.position(s), ["centerline point", "e_y"]),
    ("1.2 e_y along the tangent", ch01.check_frenet_to_cartesian, _cart_tangent,
     ["along the track", "normal"]),
    ("1.2 returns (y, x)", ch01.check_frenet_to_cartesian,
     lambda path, s, e_y: S1["frenet_to_cartesian"](path, s, e_y)[::-1], ["(y, x)"]),
    ("1.2 heading converted to radians again", ch01.check_frenet_to_cartesian,
     _cart_radians_again, ["already in radians"]),
    ("1.2 library through a helper", ch01.check_frenet_to_cartesian,
     lambda path, s, e_y: _my_cartesian(path, s, e_y), ["to_cartesian", "yourself"]),
    ("1.3 times 1 - kappa e_y", ch01.check_frenet_rates, _r_times, ["s_dot", "m/s"]),
    ("1.3 1 + kappa e_y", ch01.check_frenet_rates, _r_plus, ["s_dot", "m/s"]),
    ("1.3 + v_y sin e_psi", ch01.check_frenet_rates, _r_vy_sign, ["expected s_dot"]),
    ("1.3 cos and sin swapped in e_y_dot", ch01.check_frenet_rates, _r_cos_sin,
     ["e_y_dot", "drifts sideways"]),
    ("1.3 sign of v_y in e_y_dot", ch01.check_frenet_rates, _r_eydot_sign, ["expected e_y_dot"]),
    ("1.3 v_x instead of s_dot in e_psi_dot", ch01.check_frenet_rates, _r_kappa_vx,
     ["e_psi_dot", "rad/s"]),
    ("1.3 e_psi_dot reversed", ch01.check_frenet_rates, _r_turned,
     ["e_psi_dot", "turns relative to the road"]),
    ("1.3 e_psi in degrees", ch01.check_frenet_rates, _r_degrees, ["expected s_dot"]),
    ("1.3 two rates only", ch01.check_frenet_rates,
     lambda *args: S1["frenet_rates"](*args)[:2], ["3 values"]),
]  # fmt: skip


# --------------------------------------------------------------------------------------------------
# Chapter 02


def _slip_delta_sign(p, v_x, v_y, r, delta):  # steering subtracted at the front
    return -delta - (v_y + p.l_f * r) / v_x, -(v_y - p.l_r * r) / v_x


def _slip_reversed(p, v_x, v_y, r, delta):  # both slip angles with the opposite sign
    return (v_y + p.l_f * r) / v_x - delta, (v_y - p.l_r * r) / v_x


def _slip_rear_plus(p, v_x, v_y, r, delta):  # the yaw rate adds at the rear too
    return delta - (v_y + p.l_f * r) / v_x, -(v_y + p.l_r * r) / v_x


def _slip_exact(p, v_x, v_y, r, delta):  # arctan where the model's small-angle form is asked
    return delta - math.atan((v_y + p.l_f * r) / v_x), -math.atan((v_y - p.l_r * r) / v_x)


def _slip_no_yaw(p, v_x, v_y, r, delta):  # the yaw rate forgotten: agrees on a straight
    return delta - v_y / v_x, -v_y / v_x


def _slip_speed(p, v_x, v_y, r, delta):  # divided by the total speed instead of v_x
    v = math.hypot(v_x, v_y)
    return delta - (v_y + p.l_f * r) / v, -(v_y - p.l_r * r) / v


def _tyre(alpha, F_z, mu, B, C, D):
    return S2["tyre_force"](alpha, F_z, mu, B, C, D)


def _axle(p, a_x, *, front_share, transfer):
    L = p.l_f + p.l_r
    dW = transfer(p, a_x, L)
    return p.m * p.g * front_share(p) / L - dW, p.m * p.g * (L - front_share(p)) / L + dW


def _spatial(model, xi, u, kappa):
    return model.xi_dot(xi, u, kappa=kappa)


def _spatial_s_zero(model, xi, u, kappa):  # the last component set to 0: s "does not change"
    out = S2["spatial_dynamics"](model, xi, u, kappa)
    out[X.S] = 0.0
    return out


def _spatial_plain(model, xi, u, kappa):  # s_dot without 1 / (1 - kappa e_y)
    v_x, v_y, e_psi = xi[X.VX], xi[X.VY], xi[X.EPSI]
    return _spatial(model, xi, u, kappa) / (v_x * math.cos(e_psi) - v_y * math.sin(e_psi))


CH02 = [
    ("2.1 steering sign", ch02.check_slip_angles, _slip_delta_sign, ["front", "expected alpha_f"]),
    ("2.1 both signs reversed", ch02.check_slip_angles, _slip_reversed, ["sign is reversed"]),
    ("2.1 + l_r r at the rear", ch02.check_slip_angles, _slip_rear_plus,
     ["rear", "expected alpha_r"]),
    ("2.1 exact arctan", ch02.check_slip_angles, _slip_exact, ["tyres see", "deg"]),
    ("2.1 yaw rate forgotten", ch02.check_slip_angles, _slip_no_yaw, ["front", "r = 0.50"]),
    ("2.1 divided by the speed", ch02.check_slip_angles, _slip_speed, ["slip angle"]),
    ("2.1 returns (alpha_r, alpha_f)", ch02.check_slip_angles,
     lambda *args: S2["slip_angles"](*args)[::-1], ["wrong order", "front first"]),
    ("2.2 friction coefficient forgotten", ch02.check_tyre_force,
     lambda alpha, F_z, mu, B, C, D: _tyre(alpha, F_z, 1.0, B, C, D), ["push sideways", "N"]),
    ("2.2 peak factor D forgotten", ch02.check_tyre_force,
     lambda alpha, F_z, mu, B, C, D: _tyre(alpha, F_z, mu, B, C, 1.0), ["push sideways", "D ="]),
    ("2.2 B and C swapped", ch02.check_tyre_force,
     lambda alpha, F_z, mu, B, C, D: _tyre(alpha, F_z, mu, C, B, D), ["push sideways"]),
    ("2.2 slip in degrees", ch02.check_tyre_force,
     lambda alpha, F_z, mu, B, C, D: _tyre(math.degrees(alpha), F_z, mu, B, C, D),
     ["slip angle of 0.5 deg"]),
    ("2.2 |alpha|: no sign", ch02.check_tyre_force,
     lambda alpha, F_z, mu, B, C, D: _tyre(abs(alpha), F_z, mu, B, C, D),
     ["sign of the slip angle"]),
    ("2.2 cos instead of sin", ch02.check_tyre_force,
     lambda alpha, F_z, mu, B, C, D: mu * F_z * D * math.cos(C * math.atan(B * alpha)),
     ["push sideways", "expected F_y"]),
    ("2.3 static shares swapped", ch02.check_axle_loads,
     lambda p, a_x: _axle(p, a_x, front_share=lambda p: p.l_f,
                          transfer=lambda p, a, L: p.m * a * p.h_c / L),
     ["Cruising", "swapped", "l_r / L"]),
    ("2.3 returns (F_zr, F_zf)", ch02.check_axle_loads,
     lambda p, a_x: S2["axle_loads"](p, a_x)[::-1], ["swapped", "front first"]),
    ("2.3 gravity forgotten", ch02.check_axle_loads,
     lambda p, a_x: (p.m * p.l_r / (p.l_f + p.l_r), p.m * p.l_f / (p.l_f + p.l_r)),
     ["Cruising", "front axle", "kN"]),
    ("2.3 mass forgotten in the transfer", ch02.check_axle_loads,
     lambda p, a_x: _axle(p, a_x, front_share=lambda p: p.l_r,
                          transfer=lambda p, a, L: a * p.h_c / L),
     ["Accelerating at 3", "kN"]),
    ("2.3 transfer over l_f", ch02.check_axle_loads,
     lambda p, a_x: _axle(p, a_x, front_share=lambda p: p.l_r,
                          transfer=lambda p, a, L: p.m * a * p.h_c / p.l_f),
     ["Accelerating at 3", "expected F_zf"]),
    ("2.3 transfer times g", ch02.check_axle_loads,
     lambda p, a_x: _axle(p, a_x, front_share=lambda p: p.l_r,
                          transfer=lambda p, a, L: p.m * p.g * a * p.h_c / L),
     ["Accelerating at 3", "kN"]),
    ("2.4 s_dot without the curvature factor", ch02.check_spatial_dynamics, _spatial_plain,
     ["per metre of track", "bend"]),
    ("2.4 times s_dot", ch02.check_spatial_dynamics,
     lambda model, xi, u, kappa: _spatial(model, xi, u, kappa) * xi[X.VX], ["per metre"]),
    ("2.4 curvature forgotten", ch02.check_spatial_dynamics,
     lambda model, xi, u, kappa: S2["spatial_dynamics"](model, xi, u, 0.0), ["per metre"]),
    ("2.4 divided by the state s", ch02.check_spatial_dynamics,
     lambda model, xi, u, kappa: _spatial(model, xi, u, kappa) / xi[X.S], ["per metre"]),
    ("2.4 ds/ds = 0", ch02.check_spatial_dynamics, _spatial_s_zero, ["exactly one metre"]),
    ("2.4 five states only", ch02.check_spatial_dynamics,
     lambda *args: S2["spatial_dynamics"](*args)[:5], ["shape (6,)"]),
]  # fmt: skip


# --------------------------------------------------------------------------------------------------
# Chapter 03


def _corner(kappa, mu, g, v_top, *, root=np.sqrt, size=np.abs, cap=np.minimum):
    with np.errstate(divide="ignore", invalid="ignore"):
        return cap(root(mu * g / size(kappa)), v_top)


def _corner_eps(kappa, mu, g, v_top):  # an epsilon against division by zero on straights
    return np.minimum(np.sqrt(mu * g / (np.abs(kappa) + 1e-6)), v_top)


def _lap(s, v, length, *, end=None, v_next=None, ds=None):
    ds = np.diff(np.append(s, s[0] + length if end is None else end)) if ds is None else ds
    v_next = np.roll(v, -1) if v_next is None else v_next
    return float(np.sum(2.0 * ds / (v + v_next)))


def _steady(p, v, kappa, *, asin=math.asin, per_c=True, mu=None, vy_sign=1.0, front=None):
    """Steady cornering as the solution computes it, with one piece changed."""
    r = v * kappa
    a_y = v * v * kappa
    mu = p.mu if mu is None else mu

    def slip(B, C, D):
        return math.tan(asin(a_y / (p.g * mu * D)) / (C if per_c else 1.0)) / B

    alpha_f = slip(*(front or (p.B_f, p.C_f, p.D_f)))
    alpha_r = slip(p.B_r, p.C_r, p.D_r)
    v_y = p.l_r * r - vy_sign * v * alpha_r
    return v_y, r, alpha_f + (v_y + p.l_f * r) / v


def _steady_radius(p, v, kappa):  # r = v / kappa: curvature taken for the radius
    v_y, _, delta = _steady(p, v, kappa)
    return v_y, v / kappa, delta


def _steady_abs(p, v, kappa):  # a_y = v^2 |kappa|: every bend turns left
    return _steady(p, v, abs(kappa))[0], v * kappa, _steady(p, v, kappa)[2]


def _steady_delta_sign(p, v, kappa):  # delta = alpha_f - (v_y + l_f r) / v
    v_y, r, delta = _steady(p, v, kappa)
    alpha_f = delta - (v_y + p.l_f * r) / v
    return v_y, r, alpha_f - (v_y + p.l_f * r) / v


def _steady_degrees(p, v, kappa):  # the steering angle returned in degrees
    v_y, r, delta = S3["steady_state"](p, v, kappa)
    return v_y, r, math.degrees(delta)


def _qp(oval, margin, *, sign=1.0, centerline=True, power=2, use_margin=True):
    n = cp.Variable(oval.s.size)
    after, before = cp.hstack([n[1:], n[:1]]), cp.hstack([n[-1:], n[:-1]])
    change = sign * (after - 2 * n + before) / oval.ds**power
    kappa = oval.kappa + change if centerline else change
    bound = oval.half_width - (margin if use_margin else 0.0)
    cp.Problem(cp.Minimize(cp.sum_squares(kappa) * oval.ds), [cp.abs(n) <= bound]).solve()
    return n.value


def _my_solver(oval, margin):
    from racing_lib.model import identified_params
    from racing_lib.planning import solve_curvature

    return solve_curvature(oval, identified_params()).e_y


CH03 = [
    ("3.1 |kappa| forgotten", ch03.check_cornering_speed,
     lambda k, mu, g, v: _corner(k, mu, g, v, size=lambda x: x), ["Right-hand", "|kappa|"]),
    ("3.1 square root forgotten", ch03.check_cornering_speed,
     lambda k, mu, g, v: _corner(k, mu, g, v, root=lambda x: x), ["faster than its tyres"]),
    ("3.1 maximum instead of minimum", ch03.check_cornering_speed,
     lambda k, mu, g, v: _corner(k, mu, g, v, cap=np.maximum), ["inf", "top speed"]),
    ("3.1 epsilon on straights", ch03.check_cornering_speed, _corner_eps, ["slower than its"]),
    ("3.1 math.sqrt on an array raises", ch03.check_cornering_speed,
     lambda k, mu, g, v: min(math.sqrt(mu * g / abs(k)), v), ["TypeError"]),
    ("3.2 the loop closed at length", ch03.check_lap_time,
     lambda s, v, length: _lap(s, v, length, end=length), ["s_0 + length"]),
    ("3.2 uniform spacing assumed", ch03.check_lap_time,
     lambda s, v, length: _lap(s, v, length, ds=length / s.size), ["uneven", "s_{k+1} - s_k"]),
    ("3.2 speeds of the interval before", ch03.check_lap_time,
     lambda s, v, length: _lap(s, v, length, v_next=np.roll(v, 1)), ["v_k and v_{k+1}"]),
    ("3.2 harmonic mean of the speeds", ch03.check_lap_time,
     lambda s, v, length: float(np.sum(np.diff(np.append(s, s[0] + length))
                                       * 0.5 * (1 / v + 1 / np.roll(v, -1)))),
     ["too long"]),
    ("3.2 the time at every node", ch03.check_lap_time,
     lambda s, v, length: np.cumsum(2.0 * np.diff(np.append(s, s[0] + length))
                                    / (v + np.roll(v, -1))),
     ["one number"]),
    ("3.3 arcsine not divided by C", ch03.check_steady_cornering,
     lambda p, v, k: _steady(p, v, k, per_c=False), ["steady cornering needs", "v_y"]),
    ("3.3 friction coefficient forgotten", ch03.check_steady_cornering,
     lambda p, v, k: _steady(p, v, k, mu=1.0), ["steady cornering needs", "v_y"]),
    ("3.3 peak factor D forgotten", ch03.check_steady_cornering,
     lambda p, v, k: _steady(p, v, k, front=(p.B_f, p.C_f, 1.0)), ["delta"]),
    ("3.3 r = v / kappa", ch03.check_steady_cornering, _steady_radius, ["r = v kappa"]),
    ("3.3 sign of v alpha_r", ch03.check_steady_cornering,
     lambda p, v, k: _steady(p, v, k, vy_sign=-1.0), ["expected v_y"]),
    ("3.3 delta sign", ch03.check_steady_cornering, _steady_delta_sign, ["expected delta"]),
    ("3.3 front tyre with the rear's B", ch03.check_steady_cornering,
     lambda p, v, k: _steady(p, v, k, front=(p.B_r, p.C_f, p.D_f)), ["expected delta"]),
    ("3.3 every bend a left one", ch03.check_steady_cornering, _steady_abs,
     ["Cornering right", "v_y"]),
    ("3.3 delta in degrees", ch03.check_steady_cornering, _steady_degrees,
     ["in degrees", "radians"]),
    ("3.4 centerline curvature forgotten", ch03.check_min_curvature_qp,
     lambda oval, m: _qp(oval, m, centerline=False), ["the centerline", "kappa_c"]),
    ("3.4 second difference with the wrong sign", ch03.check_min_curvature_qp,
     lambda oval, m: _qp(oval, m, sign=-1.0), ["mirrored", "sign"]),
    ("3.4 divided by ds instead of ds^2", ch03.check_min_curvature_qp,
     lambda oval, m: _qp(oval, m, power=1), ["squared curvature", "1/m"]),
    ("3.4 margin forgotten", ch03.check_min_curvature_qp,
     lambda oval, m: _qp(oval, m, use_margin=False), ["half_width - margin"]),
    ("3.4 library through a helper", ch03.check_min_curvature_qp,
     lambda oval, m: _my_solver(oval, m), ["solve_curvature"]),
]  # fmt: skip


# --------------------------------------------------------------------------------------------------
# Chapter 04


def _s_dot(kappa, v_x, v_y, e_psi, e_y):
    return (v_x * np.cos(e_psi) - v_y * np.sin(e_psi)) / (1.0 - kappa * e_y)


def _t_left(ds, kappa, v_x, v_y, e_psi, e_y):  # rectangle rule: the speed at the interval's start
    return float(np.sum(ds / _s_dot(kappa, v_x, v_y, e_psi, e_y)))


def _t_back(ds, kappa, v_x, v_y, e_psi, e_y):  # trapezoid with the node before, not after
    inv = 1.0 / _s_dot(kappa, v_x, v_y, e_psi, e_y)
    return float(np.sum(0.5 * ds * (inv + np.roll(inv, 1))))


def _t_mean_speed(ds, kappa, v_x, v_y, e_psi, e_y):  # length over the mean speed
    return float(np.sum(ds) / np.mean(_s_dot(kappa, v_x, v_y, e_psi, e_y)))


def _t_times(ds, kappa, v_x, v_y, e_psi, e_y):  # s_dot times 1 - kappa e_y instead of divided
    inv = 1.0 / ((v_x * np.cos(e_psi) - v_y * np.sin(e_psi)) * (1.0 - kappa * e_y))
    return float(np.sum(0.5 * ds * (inv + np.roll(inv, -1))))


def _t_plus(ds, kappa, v_x, v_y, e_psi, e_y):  # 1 + kappa e_y
    return S4["lap_time"](ds, -kappa, v_x, v_y, e_psi, e_y)


def _t_segments(ds, kappa, v_x, v_y, e_psi, e_y):  # the time of each interval, not their sum
    inv = 1.0 / _s_dot(kappa, v_x, v_y, e_psi, e_y)
    return 0.5 * ds * (inv + np.roll(inv, -1))


def _nlp(oval, grip, v_top, *, lateral=True, top=True, objective="trapezoid"):
    n = oval.s.size
    opti = ca.Opti()
    v, a = opti.variable(n), opti.variable(n)
    v_next = ca.vertcat(v[1:], v[0])
    lap = 2 * oval.ds / (v + v_next) if objective == "trapezoid" else oval.ds / v
    opti.minimize(ca.sum1(lap))
    opti.subject_to(v_next**2 == v**2 + 2 * a * oval.ds)
    lat = (v**2 * oval.kappa / grip) ** 2 if lateral else 0
    opti.subject_to((a / grip) ** 2 + lat <= 1)
    opti.subject_to(opti.bounded(1.0, v, v_top) if top else v >= 1.0)
    opti.set_initial(v, 10.0)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "sb": "yes"})
    return opti.solve().value(v)


def _speed_limit(oval, grip, v_top):
    from racing_lib.model import ModelParams
    from racing_lib.planning.speed import speed_profile as profile

    return profile(oval.s, oval.kappa, ModelParams(mu=grip / 9.81), v_top=v_top).v


CH04 = [
    ("4.1 rectangle rule", ch04.check_spatial_lap_time, _t_left, ["NLP's objective gives"]),
    ("4.1 trapezoid with the previous node", ch04.check_spatial_lap_time, _t_back,
     ["uneven spacing"]),
    ("4.1 length over the mean speed", ch04.check_spatial_lap_time, _t_mean_speed,
     ["NLP's objective gives"]),
    ("4.1 times 1 - kappa e_y", ch04.check_spatial_lap_time, _t_times, ["weaving"]),
    ("4.1 1 + kappa e_y", ch04.check_spatial_lap_time, _t_plus, ["weaving"]),
    ("4.1 segment times, not summed", ch04.check_spatial_lap_time, _t_segments, ["one number"]),
    ("4.2 arctan instead of tan", ch04.check_peak_slip_angle,
     lambda B, C: math.atan(math.pi / (2.0 * C)) / B, ["peaks at", "pi / 2"]),
    ("4.2 times B", ch04.check_peak_slip_angle,
     lambda B, C: B * math.tan(math.pi / (2.0 * C)), ["peaks at"]),
    ("4.2 pi C / 2", ch04.check_peak_slip_angle,
     lambda B, C: math.tan(math.pi * C / 2.0) / B, ["peaks at"]),
    ("4.2 B forgotten", ch04.check_peak_slip_angle,
     lambda B, C: math.tan(math.pi / (2.0 * C)), ["peaks at"]),
    ("4.2 90 degrees in the tangent", ch04.check_peak_slip_angle,
     lambda B, C: math.tan(90.0 / C) / B, ["peaks at"]),
    ("4.3 friction circle without cornering", ch04.check_min_time_nlp,
     lambda oval, grip, v_top: _nlp(oval, grip, v_top, lateral=False), ["alone exceeds"]),
    ("4.3 no top speed", ch04.check_min_time_nlp,
     lambda oval, grip, v_top: _nlp(oval, grip, v_top, top=False), ["above v_top"]),
    ("4.3 library speed profile under another name", ch04.check_min_time_nlp, _speed_limit,
     ["speed_profile", "casadi"]),
]  # fmt: skip


# --------------------------------------------------------------------------------------------------
# Chapter 05


def _blend(xi0, xi_ref, lam, offset=None):
    offset = (xi0 - xi_ref[0])[None, :] if offset is None else offset
    return xi_ref + lam[:, None] * offset


def _h_short(xi0, xi_ref):  # N values of lambda for N + 1 stages: raises
    return _blend(xi0, xi_ref, np.linspace(1.0, 0.0, xi_ref.shape[0] - 1))


def _h_rising(xi0, xi_ref):  # lambda rising from 0 to 1: starts on the plan, ends off it
    n = xi_ref.shape[0] - 1
    return _blend(xi0, xi_ref, np.arange(n + 1) / n)


def _h_moving_offset(xi0, xi_ref):  # the offset from each stage of the plan, not from stage 0
    n = xi_ref.shape[0] - 1
    return _blend(xi0, xi_ref, 1.0 - np.arange(n + 1) / n, xi0[None, :] - xi_ref)


def _h_in_place(xi0, xi_ref):  # the plan changed in place and returned
    n = xi_ref.shape[0] - 1
    xi_ref += (1.0 - np.arange(n + 1) / n)[:, None] * (xi0 - xi_ref[0])[None, :]
    return xi_ref


def _pedal(pedal_map, a_x, xi, *, coasting=None, clip=(-1.0, 1.0), swap=False):
    base = pedal_map.m_0 + float(np.dot(pedal_map.m_xi, xi)) if coasting is None else coasting
    excess = a_x - base
    thr, brk = (pedal_map.m_brk, pedal_map.m_thr) if swap else (pedal_map.m_thr, pedal_map.m_brk)
    u = excess / thr if excess >= 0 else excess / brk
    return float(np.clip(u, *clip)) if clip else float(u)


def _my_pedal(pedal_map, a_x, xi):
    return pedal_map.pedal(a_x, xi)


def _mpc(problem, *, bound=True, curve=True, rate=True):
    n = problem.d.shape[0]
    x, u = cp.Variable((n + 1, 2)), cp.Variable(n)
    steps = cp.hstack([u[:1] - problem.delta_prev, u[1:] - u[:-1]])
    cost = cp.sum(cp.square(x[1:]) @ problem.q)
    cost += problem.r * cp.sum_squares(steps) if rate else 0
    d = problem.d if curve else np.zeros_like(problem.d)
    model = [x[0] == problem.x0]
    model += [x[k + 1] == problem.A @ x[k] + problem.B * u[k] + d[k] for k in range(n)]
    limits = [cp.abs(u) <= problem.delta_max] if bound else []
    cp.Problem(cp.Minimize(cost), model + limits).solve()
    return u.value


def _mpc_library(problem):
    from racing_lib.control.mpc import TrackingQP as QP

    return QP(problem).solve()


def _mpc_qp(step, *, x0=True, d_sign=1.0, blocks=-1.0, transpose=False, soft=True, rate_limit=True,
        from_zero=False, two=2.0, x0_variable=False, eps_rows=True, lower=False,
        input_major=False, bounds=True, slack_price=True, band_state=None):  # fmt: skip
    """Exercise 5.5's QP in OSQP's form, as the solution builds it, with one mistake."""
    N, n, m = step.B.shape
    nx, nu = N * n, N * m
    nz = nx + nu + N
    X, U, E = slice(0, nx), slice(nx, nx + nu), slice(nx + nu, nz)
    P, q = np.zeros((nz, nz)), np.zeros(nz)
    P[X, X] = np.diag(two * step.state_weights.ravel())
    q[X] = -2.0 * (step.state_weights * step.x_ref).ravel()
    D = np.eye(nu) - np.eye(nu, k=-m)
    P[U, U] = two * D.T @ np.diag(np.tile(step.rate_weights, N)) @ D
    q[nx : nx + m] = 0.0 if from_zero else -2.0 * step.rate_weights * step.u_prev
    P[E, E] = two * step.slack_quadratic * np.eye(N)
    q[E] = step.slack_linear if slack_price else 0.0
    A_k = np.transpose(step.A, (0, 2, 1)) if transpose else step.A
    model = np.zeros((nx, nz))
    model[:, X] = np.eye(nx)
    for k in range(N):
        if k > 0:
            model[k * n : (k + 1) * n, (k - 1) * n : k * n] = blocks * A_k[k]
        model[k * n : (k + 1) * n, nx + k * m : nx + (k + 1) * m] = blocks * step.B[k]
    rhs = d_sign * step.d.copy()
    rhs[0] -= blocks * A_k[0] @ step.x0 if x0 else 0.0
    rhs = rhs.ravel()
    e_y = np.zeros((N, nz))
    e_y[
        np.arange(N), np.arange(N) * n + (step.band_index if band_state is None else band_state)
    ] = 1
    eps = np.zeros((N, nz))
    eps[:, E] = np.eye(N)
    inputs, changes = np.zeros((nu, nz)), np.zeros((nu, nz))
    inputs[:, U], changes[:, U] = np.eye(nu), D
    limit, first = np.tile(step.rate_limits, N), np.zeros(nu)
    first[:m] = step.u_prev
    inf = np.full(N, np.inf)
    rows = [(model, rhs, rhs), (e_y + soft * eps, step.band_min, inf),
            (e_y - soft * eps, -inf, step.band_max)]  # fmt: skip
    rows += [(eps, np.zeros(N), inf)] if eps_rows else []
    rows += [(inputs, step.u_min.ravel(), step.u_max.ravel())] if bounds else []
    rows += [(changes, first - limit, first + limit)] if rate_limit else []
    A = np.vstack([r[0] for r in rows])
    lo, up = np.concatenate([r[1] for r in rows]), np.concatenate([r[2] for r in rows])
    if input_major:  # the inputs' block ordered input by input: all steering, then all a_x
        order = np.arange(nz)
        order[U] = nx + np.arange(nu).reshape(N, m).T.ravel()
        P, q, A = P[np.ix_(order, order)], q[order], A[:, order]
    if x0_variable:  # room for x_0 at the front of z
        P, q, A = np.pad(P, ((n, 0), (n, 0))), np.pad(q, (n, 0)), np.pad(A, ((0, 0), (n, 0)))
    return (np.tril(P) if lower else P), q, A, lo, up


def _capstone_library(step):
    from racing_lib.control.mpc import TrackingQP as QP

    return QP(step).solve()


CH05 = [
    ("5.1 N values of lambda", ch05.check_heuristic_trajectory, _h_short, ["ValueError"]),
    ("5.1 lambda rising", ch05.check_heuristic_trajectory, _h_rising, ["k = 0", "car's own state"]),
    ("5.1 offset from each stage of the plan", ch05.check_heuristic_trajectory,
     _h_moving_offset, ["xi_0 - xi_ref_0"]),
    ("5.1 the plan changed in place", ch05.check_heuristic_trajectory, _h_in_place,
     ["changed xi_ref", "copy"]),
    ("5.1 transposed", ch05.check_heuristic_trajectory,
     lambda xi0, xi_ref: S5["heuristic_trajectory"](xi0, xi_ref).T, ["transposed"]),
    ("5.2 exp(-tau / dt)", ch05.check_steering_lag,
     lambda tau, dt: (math.exp(-tau / dt), tau / dt * (1 - math.exp(-tau / dt))),
     ["of the way", "exactly"]),
    ("5.2 exp(+dt / tau)", ch05.check_steering_lag,
     lambda tau, dt: (math.exp(dt / tau), tau / dt * (1 - math.exp(dt / tau))), ["of the way"]),
    ("5.2 a as the fraction covered", ch05.check_steering_lag,
     lambda tau, dt: (1 - math.exp(-dt / tau), tau / dt * math.exp(-dt / tau)), ["of the way"]),
    ("5.2 w = 1 - a", ch05.check_steering_lag,
     lambda tau, dt: (math.exp(-dt / tau), 1 - math.exp(-dt / tau)), ["mean steering angle",
                                                                      "Average the exponential"]),
    ("5.2 w with dt / tau", ch05.check_steering_lag,
     lambda tau, dt: (math.exp(-dt / tau), dt / tau * (1 - math.exp(-dt / tau))),
     ["Average the exponential"]),
    ("5.2 trapezoid mean", ch05.check_steering_lag,
     lambda tau, dt: (math.exp(-dt / tau), 0.5 * (1 + math.exp(-dt / tau))),
     ["Average the exponential"]),
    ("5.3 no clipping", ch05.check_pedal_inversion,
     lambda pm, a_x, xi: _pedal(pm, a_x, xi, clip=None), ["clip"]),
    ("5.3 slopes swapped", ch05.check_pedal_inversion,
     lambda pm, a_x, xi: _pedal(pm, a_x, xi, swap=True), ["the map needs"]),
    ("5.3 clipped to [0, 1]", ch05.check_pedal_inversion,
     lambda pm, a_x, xi: _pedal(pm, a_x, xi, clip=(0.0, 1.0)), ["the map needs"]),
    ("5.3 m_xi . xi forgotten", ch05.check_pedal_inversion,
     lambda pm, a_x, xi: _pedal(pm, a_x, xi, coasting=pm.m_0), ["m_xi . xi", "speed"]),
    ("5.3 library through a helper", ch05.check_pedal_inversion,
     lambda pm, a_x, xi: _my_pedal(pm, a_x, xi), ["pedal", "yourself"]),
    ("5.4 no steering bound", ch05.check_lateral_mpc,
     lambda p: _mpc(p, bound=False), ["beyond the bound", "delta_max"]),
    ("5.4 curvature term d_k forgotten", ch05.check_lateral_mpc,
     lambda p: _mpc(p, curve=False), ["d_k"]),
    ("5.4 steering-rate term forgotten", ch05.check_lateral_mpc,
     lambda p: _mpc(p, rate=False), ["steering-rate term"]),
    ("5.4 the library QP under another name", ch05.check_lateral_mpc, _mpc_library,
     ["TrackingQP"]),
    ("5.5 x_0 left out of the model rows", ch05.check_mpc_lap, lambda st: _mpc_qp(st, x0=False),
     ["x_0 is measured", "A_0 x_0"]),
    ("5.5 d_k with the wrong sign", ch05.check_mpc_lap, lambda st: _mpc_qp(st, d_sign=-1.0),
     ["d_k with the wrong sign"]),
    ("5.5 +A_k and +B_k in the model rows", ch05.check_mpc_lap, lambda st: _mpc_qp(st, blocks=1.0),
     ["+A_k and +B_k", "-A_k, -B_k"]),
    ("5.5 A_k transposed", ch05.check_mpc_lap, lambda st: _mpc_qp(st, transpose=True),
     ["A_k transposed"]),
    ("5.5 a hard band", ch05.check_mpc_lap, lambda st: _mpc_qp(st, soft=False),
     ["beyond the band", "no solution", "soften it"]),
    ("5.5 no slew-rate limit", ch05.check_mpc_lap, lambda st: _mpc_qp(st, rate_limit=False),
     ["slew rate allows 0.120 rad per period"]),
    ("5.5 first rate term from zero", ch05.check_mpc_lap, lambda st: _mpc_qp(st, from_zero=True),
     ["u_0 - u_prev", "-2 W_du u_prev"]),
    ("5.5 P without OSQP's factor 2", ch05.check_mpc_lap, lambda st: _mpc_qp(st, two=1.0),
     ["1/2 z'Pz", "2 w on P's diagonal"]),
    ("5.5 x_0 among the variables", ch05.check_mpc_lap, lambda st: _mpc_qp(st, x0_variable=True),
     ["231 variables", "x_0 is measured"]),
    ("5.5 slack without eps >= 0", ch05.check_mpc_lap, lambda st: _mpc_qp(st, eps_rows=False),
     ["negative slack", "eps_k >= 0"]),
    ("5.5 only P's lower triangle", ch05.check_mpc_lap, lambda st: _mpc_qp(st, lower=True),
     ["lower triangle", "upper one"]),
    ("5.5 inputs ordered input by input", ch05.check_mpc_lap,
     lambda st: _mpc_qp(st, input_major=True), ["input by input", "stage by stage"]),
    ("5.5 no input bounds", ch05.check_mpc_lap, lambda st: _mpc_qp(st, bounds=False),
     ["a_x", "outside its bounds"]),
    ("5.5 the slack without its price rho_1", ch05.check_mpc_lap,
     lambda st: _mpc_qp(st, slack_price=False), ["slack_linear"]),
    ("5.5 the band on e_psi", ch05.check_mpc_lap, lambda st: _mpc_qp(st, band_state=3),
     ["beyond the band", "band_index"]),
    ("5.5 the library's QP under another name", ch05.check_mpc_lap, _capstone_library,
     ["TrackingQP", "yourself"]),
]  # fmt: skip


# --------------------------------------------------------------------------------------------------
# Chapter 06


def _objective(log, metrics, track_length, w_t, w_s, *, lap=None, ey=abs, vx=abs, mean=np.mean,
               t_c=None, d_sign=-1.0):  # fmt: skip
    lap = np.asarray(log.in_lap, dtype=bool) if lap is None else lap
    e = ey(log.ey[lap])
    steps = np.diff(log.s_track)
    steps = (steps + 0.5 * track_length) % track_length - 0.5 * track_length
    distance = np.sum(steps[lap[:-1] & lap[1:]])
    t_c = metrics.wall_contact_time_s + metrics.offtrack_time_s if t_c is None else t_c(metrics)
    vx_err = vx(log.vx[lap] - log.vx_ref[lap])
    return e.max() + mean(e) + mean(vx_err) + w_t * t_c + d_sign * w_s * distance


def _obj_all_steps(log, metrics, track_length, w_t, w_s):  # the run-up and run-out included
    lap = np.ones(log.ey.size, dtype=bool)
    return _objective(log, metrics, track_length, w_t, w_s, lap=lap)


def _obj_rms(log, metrics, track_length, w_t, w_s):  # RMS errors instead of mean absolute
    return _objective(log, metrics, track_length, w_t, w_s, mean=lambda e: np.sqrt(np.mean(e**2)))


def _params(space, x, *, base=10.0, lo=None, hi=None):
    lo = np.log10(np.asarray(space.lower, float)) if lo is None else lo
    hi = np.log10(np.asarray(space.upper, float)) if hi is None else hi
    x = np.clip(np.asarray(x, dtype=float), lo, hi)
    return {name: float(base**v) for name, v in zip(space.names, x, strict=True)}


def _cma_off_by_one(f, x0, sigma0, budget, seed):  # `while used <= budget`: one generation more
    return S6["cma_es"](f, x0, sigma0, budget + 9, seed)


def _cma_library(f, x0, sigma0, budget, seed):
    from racing_lib.optim.cmaes import tune as search

    return search(f, x0, sigma0, budget, seed)


def _tune(evaluate, space, seeds, budget, *, use=None, params=None, scale=1.0, sign=1.0,
          give="best"):  # fmt: skip
    """Exercise 6.4 as the solution writes it, with one mistake."""
    params = params or S6["to_params"]
    last = {}

    def f(x):
        weights = params(space, x)
        last["x"] = np.array(x, dtype=float)
        return sign * float(np.mean([evaluate(weights, s) for s in (use or tuple)(seeds)]))

    x_best = S6["cma_es"](f, space.x0(), 0.5, int(budget * scale), 0)
    chosen = {"best": x_best, "last": last.get("x"), "start": space.x0()}.get(give, x_best)
    return x_best if give == "point" else S6["to_params"](space, chosen)


def _tune_library(evaluate, space, seeds, budget):
    from racing_lib.experiments.tuning import tune_weights as tune_them

    return tune_them(evaluate, seeds)


CH06 = [
    ("6.1 the run-up included", ch06.check_tuning_objective, _obj_all_steps,
     ["only the steps of the lap"]),
    ("6.1 signed e_y", ch06.check_tuning_objective,
     lambda *args: _objective(*args, ey=lambda e: e), ["objective scores"]),
    ("6.1 distance added", ch06.check_tuning_objective,
     lambda *args: _objective(*args, d_sign=1.0), ["subtracted"]),
    ("6.1 signed speed error", ch06.check_tuning_objective,
     lambda *args: _objective(*args, vx=lambda e: e), ["objective scores"]),
    ("6.1 RMS errors", ch06.check_tuning_objective, _obj_rms, ["objective scores"]),
    ("6.1 wall time only", ch06.check_tuning_objective,
     lambda *args: _objective(*args, t_c=lambda m: m.wall_contact_time_s),
     ["time off track", "missing"]),
    ("6.1 w_t and w_s swapped", ch06.check_tuning_objective,
     lambda log, metrics, length, w_t, w_s: _objective(log, metrics, length, w_s, w_t),
     ["objective scores"]),
    ("6.2 natural exponential", ch06.check_search_space,
     lambda space, x: _params(space, x, base=math.e), ["the tuner uses"]),
    ("6.2 clipped to the weights' own bounds", ch06.check_search_space,
     lambda space, x: _params(space, x, lo=space.lower, hi=space.upper), ["the tuner uses"]),
    ("6.2 a list of weights", ch06.check_search_space,
     lambda space, x: list(_params(space, x).values()), ["dict"]),
    ("6.2 keyed by index", ch06.check_search_space,
     lambda space, x: dict(enumerate(_params(space, x).values())), ["dict with the keys"]),
    ("6.2 natural logarithm of the box", ch06.check_search_space,
     lambda space, x: _params(space, x, lo=np.log(space.lower), hi=np.log(space.upper)),
     ["the tuner uses"]),
    ("6.3 one generation over the budget", ch06.check_cma_es, _cma_off_by_one, ["the budget is"]),
    ("6.3 the library's tuner under another name", ch06.check_cma_es, _cma_library,
     ["tune", "yourself"]),
    ("6.4 the first seed only", ch06.check_mpc_tuning,
     lambda *a: _tune(*a, use=lambda seeds: seeds[:1]), ["on the seeds [1]", "all the seeds"]),
    ("6.4 seeds of its own", ch06.check_mpc_tuning,
     lambda *a: _tune(*a, use=lambda seeds: range(len(seeds))), ["seed 0", "the seeds given"]),
    ("6.4 the log10 point as weights", ch06.check_mpc_tuning,
     lambda *a: _tune(*a, params=lambda space, x: dict(zip(space.names, x, strict=True))),
     ["log10 of the starting weights", "to_params"]),
    ("6.4 budget times the seeds", ch06.check_mpc_tuning, lambda *a: _tune(*a, scale=3.0),
     ["the budget is 13", "not single runs"]),
    ("6.4 budget over the seeds", ch06.check_mpc_tuning, lambda *a: _tune(*a, scale=1 / 3),
     ["only 1 candidate", "not single runs"]),
    ("6.4 maximized", ch06.check_mpc_tuning, lambda *a: _tune(*a, sign=-1.0),
     ["worst candidate", "CMA-ES minimizes"]),
    ("6.4 returns the log10 point", ch06.check_mpc_tuning, lambda *a: _tune(*a, give="point"),
     ["log10 space", "to_params(space, x_best)"]),
    ("6.4 returns the last candidate", ch06.check_mpc_tuning, lambda *a: _tune(*a, give="last"),
     ["not the last one"]),
    ("6.4 returns the start", ch06.check_mpc_tuning, lambda *a: _tune(*a, give="start"),
     ["starting weights", "not the one it started from"]),
    ("6.4 the library's tuner under another name", ch06.check_mpc_tuning, _tune_library,
     ["tune_weights", "yourself"]),
]  # fmt: skip

CASES = CH01 + CH02 + CH03 + CH04 + CH05 + CH06


@pytest.mark.parametrize(
    ("case_id", "check", "wrong", "fragments"), CASES, ids=[case[0] for case in CASES]
)
def test_a_plausible_wrong_answer_is_named(case_id, check, wrong, fragments):
    result = check(wrong)
    raises = any(word.endswith("Error") for word in fragments)
    assert result.status == ("error" if raises else "wrong"), f"{case_id}: {result}"
    for fragment in fragments:
        assert fragment in str(result), f"{case_id}: {fragment!r} not in {str(result)!r}"


def test_the_campaign_covers_every_check_with_seventy_answers():
    checks = {case[1] for case in CASES}
    modules = (ch01, ch02, ch03, ch04, ch05, ch06)
    every = {getattr(m, n) for m in modules for n in m.__all__ if n.startswith("check_")}
    assert every <= checks
    assert len(CASES) >= 70 and len({case[0] for case in CASES}) == len(CASES)
