"""Checks of the exercises of chapter 02 (the bicycle model, tyres, load transfer, spatial domain).

Exercise notebook: ``exercises/02_dynamics.ipynb``. Every check compares the reader's function with
:mod:`racing_lib.vehicle` or :mod:`racing_lib.model` on the same cases.

* 2.1 :func:`check_slip_angles`: front and rear slip angles (paper Eq. 11).
* 2.2 :func:`check_tyre_force`: the simplified Pacejka lateral force (Eq. 9-10).
* 2.3 :func:`check_axle_loads`: axle loads with longitudinal load transfer (Eq. 12-14).
* 2.4 :func:`check_spatial_dynamics`: the spatial-domain transform dxi/ds = xi_dot / s_dot.
"""

from __future__ import annotations

import math

import numpy as np

from racing_lib.grading.grader import (
    CheckResult,
    Wrong,
    as_array,
    as_float,
    as_tuple,
    call,
    differs,
    grade,
    refuse_degrees,
)
from racing_lib.model import Model, ModelParams
from racing_lib.vehicle import longitudinal_load_transfer, pacejka_lateral, static_axle_loads

__all__ = [
    "check_axle_loads",
    "check_slip_angles",
    "check_spatial_dynamics",
    "check_tyre_force",
]

_DEG = 180.0 / math.pi

# (v_x, v_y, r, delta): straight, left and right corners, a slide, a slow hairpin
_MOTIONS = [
    (30.0, 0.0, 0.0, 0.0),
    (25.0, -0.4, 0.5, 0.06),
    (35.0, 0.6, -0.3, -0.03),
    (20.0, 1.5, 0.2, -0.05),
    (12.0, -0.3, 0.8, 0.25),
]


def check_slip_angles(slip_angles) -> CheckResult:
    """Exercise 2.1: ``slip_angles(params, v_x, v_y, r, delta) -> (alpha_f, alpha_r)`` in rad.

    Compared with ``alpha_f`` and ``alpha_r`` of :meth:`racing_lib.model.Model.terms` to 1e-5 rad
    (all cases at v_x >= 12 m/s, where the model's standstill guard changes less than that).
    """

    def body() -> str:
        params = ModelParams()
        model = Model(params)
        for v_x, v_y, r, delta in _MOTIONS:
            terms = model.terms(np.array([v_x, v_y, r, 0.0, 0.0, 0.0]), np.array([delta, 0.0]))
            got = as_tuple(call(slip_angles, params, v_x, v_y, r, delta), 2, "slip_angles")
            state = (
                f"at v_x = {v_x:.0f} m/s, v_y = {v_y:.1f} m/s, r = {r:.2f} rad/s and "
                f"steering delta = {delta * _DEG:.1f} deg"
            )
            for axle, key, value in (("front", "alpha_f", got[0]), ("rear", "alpha_r", got[1])):
                g, e = as_float(value, key), float(terms[key])
                if differs(g, e, tol=1e-5):
                    refuse_degrees(g, e, f"{axle} slip angle {state}")
                    msg = (
                        f"{state}, your {axle} tyres see a slip angle of {g * _DEG:.2f} deg; "
                        f"they see {e * _DEG:.2f} deg (expected {key} = {e:.5f} rad, got {g:.5f})."
                    )
                    other = float(terms["alpha_r" if key == "alpha_f" else "alpha_f"])
                    if not differs(-g, e, tol=1e-5):
                        msg += " The sign is reversed: positive slip makes a force to the left."
                    elif not differs(g, other, tol=1e-5):
                        msg += (
                            " That is the other axle's: you returned them in the wrong order; "
                            "return (alpha_f, alpha_r), front first."
                        )
                    raise Wrong(msg)
        return "front and rear slip angles agree with the model in straights, corners and slides."

    return grade("2.1 Slip angles", body, weight=1.0)


def check_tyre_force(tyre_force) -> CheckResult:
    """Exercise 2.2: ``tyre_force(alpha, F_z, mu, B, C, D) -> F_y`` in N.

    The simplified Pacejka law, compared with :func:`racing_lib.vehicle.pacejka_lateral` (relative
    1e-9), on both sides of the force peak and for negative slip.
    """

    def body() -> str:
        p = ModelParams()
        F_zf, F_zr = p.static_loads()
        # The default car has D = 1 on both axles: a worn tyre (D < 1, other B and C) shows
        # whether D is in the formula at all.
        axles = (
            ("front", F_zf, p.B_f, p.C_f, p.D_f),
            ("rear", F_zr, p.B_r, p.C_r, p.D_r),
            ("worn rear", F_zr, 10.0, 1.6, 0.85),
        )
        for name, F_z, B, C, D in axles:
            for alpha_deg in (0.5, 2.0, -4.0, 8.0, 15.0):
                alpha = alpha_deg / _DEG
                expected = float(pacejka_lateral(alpha, F_z, p.mu, B, C, D))
                got = as_float(call(tyre_force, alpha, F_z, p.mu, B, C, D), "tyre_force")
                if not differs(got, expected, tol=1e-6, rel=1e-9):
                    continue
                msg = (
                    f"at a slip angle of {alpha_deg:.1f} deg with {F_z / 1000:.2f} kN on the "
                    f"{name} axle (B = {B:.1f}, C = {C:.2f}, D = {D:.2f}) your tyres push "
                    f"sideways with {got:.0f} N; they push with {expected:.0f} N (expected F_y = "
                    f"{expected:.1f} N, got {got:.1f} N)."
                )
                if not differs(-got, expected, tol=1e-6, rel=1e-9):
                    msg += (
                        " The force has the sign of the slip angle: a negative alpha pushes to the "
                        "right (keep the sign of alpha, no abs)."
                    )
                raise Wrong(msg)
        return "the tyre force agrees with pacejka_lateral below and beyond its peak."

    return grade("2.2 Pacejka tyre force", body, weight=1.0)


def check_axle_loads(axle_loads) -> CheckResult:
    """Exercise 2.3: ``axle_loads(params, a_x) -> (F_zf, F_zr)`` in N on a level road.

    Static loads plus the longitudinal load transfer Delta W = m a_x h_c / L (Eq. 12-14),
    compared with :func:`racing_lib.vehicle.static_axle_loads` and
    :func:`racing_lib.vehicle.longitudinal_load_transfer` (to 0.01 N).
    """

    def body() -> str:
        p = ModelParams()
        for a_x in (0.0, 3.0, -8.0, -12.0):
            F_zf0, F_zr0 = static_axle_loads(p.m, p.l_f, p.l_r, p.g)
            dW = longitudinal_load_transfer(p.m, a_x, p.h_c, p.l_f, p.l_r)
            expected = (F_zf0 - dW, F_zr0 + dW)
            got = as_tuple(call(axle_loads, p, a_x), 2, "axle_loads")
            doing = (
                "cruising"
                if a_x == 0
                else f"{'accelerating' if a_x > 0 else 'braking'} at {abs(a_x):.0f} m/s^2"
            )
            static = (F_zf0, F_zr0)
            for i, (axle, key) in enumerate((("front", "F_zf"), ("rear", "F_zr"))):
                g, e = as_float(got[i], key), float(expected[i])
                if differs(g, e, tol=1e-2):
                    msg = (
                        f"{doing}, your {axle} axle carries {g / 1000:.2f} kN; it carries "
                        f"{e / 1000:.2f} kN (expected {key} = {e:.1f} N, got {g:.1f} N)."
                    )
                    swapped = (F_zr0 - dW, F_zf0 + dW) if a_x == 0 else expected[::-1]
                    if not differs(g, swapped[i], tol=1e-2):
                        msg += (
                            " Front and rear are swapped: the axle nearer the centre of gravity "
                            "carries more, F_zf0 = m g l_r / L, and the function returns "
                            "(F_zf, F_zr), front first."
                        )
                    elif a_x != 0 and not differs(g - static[i], static[i] - e, tol=1.0):
                        msg += (
                            " The transfer goes the wrong way: accelerating moves load to the "
                            "rear axle, braking to the front."
                        )
                    raise Wrong(msg)
        return "the axle loads agree with the library when cruising, accelerating and braking."

    return grade("2.3 Axle loads with load transfer", body, weight=1.0)


_STATE_NAMES = ("v_x", "v_y", "r", "e_psi", "e_y", "s")
_STATE_UNITS = ("m/s", "m/s", "rad/s", "rad", "m", "m")


def check_spatial_dynamics(spatial_dynamics) -> CheckResult:
    """Exercise 2.4: ``spatial_dynamics(model, xi, u, kappa) -> dxi/ds`` (shape (6,), per m).

    The spatial-domain transform of the time-domain model, compared with
    :meth:`racing_lib.model.Model.dxi_ds` (relative 1e-9).
    """
    cases = [
        # xi = [v_x, v_y, r, e_psi, e_y, s], u = [delta, a_x], kappa
        ([30.0, 0.0, 0.0, 0.0, 0.0, 100.0], [0.0, 2.0], 0.0),
        ([25.0, -0.4, 0.5, 0.05, 3.0, 250.0], [0.06, -4.0], 1.0 / 50.0),
        ([35.0, 0.6, -0.3, -0.08, -2.0, 900.0], [-0.03, 1.0], -1.0 / 120.0),
        ([15.0, 0.3, 0.7, 0.2, -4.0, 1500.0], [0.2, -6.0], 1.0 / 25.0),
    ]

    def body() -> str:
        model = Model()
        for xi, u, kappa in cases:
            xi = np.array(xi)
            u = np.array(u)
            expected = model.dxi_ds(xi, u, kappa=kappa)
            got = as_array(call(spatial_dynamics, model, xi, u, kappa), (6,), "dxi/ds")
            bend = "a straight" if kappa == 0 else f"a bend of radius {1 / abs(kappa):.0f} m"
            for i, (name, unit) in enumerate(zip(_STATE_NAMES, _STATE_UNITS, strict=True)):
                g, e = float(got[i]), float(expected[i])
                if differs(g, e, tol=1e-9, rel=1e-9):
                    msg = (
                        f"at v_x = {xi[0]:.0f} m/s, e_y = {xi[4]:.1f} m on {bend}, your model "
                        f"says {name} changes by {g:.5f} {unit} per metre of track; it changes by "
                        f"{e:.5f} {unit} per metre (expected d{name}/ds = {e:.6f}, got {g:.6f})."
                    )
                    if name == "s":
                        msg += " s advances by exactly one metre per metre of track."
                    raise Wrong(msg)
        return "The derivative dxi/ds agrees with the model's spatial form on straights and bends."

    return grade("2.4 Spatial-domain dynamics", body, weight=2.0)
