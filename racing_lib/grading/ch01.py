"""Checks of the exercises of chapter 01 (tracks, the Frenet frame, the kinematic equations).

Exercise notebook: ``exercises/01_frenet.ipynb``. Every check compares the reader's function with
:mod:`racing_lib.geometry` or :mod:`racing_lib.model` on the same cases.

* 1.1 :func:`check_frenet_projection`: Cartesian point (x, y) -> Frenet (s, e_y).
* 1.2 :func:`check_frenet_to_cartesian`: Frenet (s, e_y) -> Cartesian (x, y).
* 1.3 :func:`check_frenet_rates`: the kinematic equations (paper Eq. 2-4).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from racing_lib.grading.grader import (
    CheckResult,
    Wrong,
    as_float,
    as_tuple,
    call,
    differs,
    every_case,
    expect_close,
    grade,
    refuse_library,
)
from racing_lib.model import Model, X
from racing_lib.tracks import load_track

__all__ = ["check_frenet_projection", "check_frenet_rates", "check_frenet_to_cartesian"]

_TRACK = "expressway"


@functools.lru_cache(maxsize=1)
def _track():
    return load_track(_TRACK)


def _cases(path, track) -> list[tuple[float, float]]:
    """(s, e_y) points on the track: straights, corners, both sides, across the start line."""
    rng = np.random.default_rng(1)
    s = np.concatenate([[5.0, path.length - 3.0, 0.4], rng.uniform(0.0, path.length, 8)])
    side = np.where(np.arange(s.size) % 2 == 0, 1.0, -1.0)
    width = np.where(side > 0, track.width_left(s), track.width_right(s))
    e_y = side * rng.uniform(0.2, 0.8, s.size) * width
    return list(zip(s.tolist(), e_y.tolist(), strict=True))


#: What exercises 1.1 and 1.2 rebuild (methods of Path and the tracker); an answer using them is
#: refused.
_FRENET_LIBRARY = {
    "to_frenet": None,
    "to_frenet_along": None,
    "to_cartesian": None,
    "FrenetTracker": None,
}
_FRENET_TASK = (
    "find the nearest point of the centerline with path.sample, path.position and path.heading."
)
_CARTESIAN_TASK = "start from path.position(s) and add e_y along the left normal."


def _side(d: float) -> str:
    return "left" if d > 0 else "right"


def check_frenet_projection(frenet_projection) -> CheckResult:
    """Exercise 1.1: ``frenet_projection(path, x, y) -> (s, e_y)``.

    ``s`` (m, in [0, length)) is the arc length of the centerline point closest to (x, y) and
    ``e_y`` (m) the signed distance to it, positive to the left. Compared with
    :meth:`racing_lib.geometry.Path.to_frenet` on eleven points of the expressway to 1 mm.
    """

    def check_case(case: tuple[float, float]) -> None:
        track = _track()
        path = track.centerline
        s0, e0 = case
        x, y, _ = path.to_cartesian(s0, e0)
        s_exp, ey_exp, _ = path.to_frenet(x, y)
        where = f"at (x, y) = ({x:.1f}, {y:.1f}) m"
        s_got, ey_got = as_tuple(call(frenet_projection, path, x, y), 2, "frenet_projection")
        s_got = as_float(s_got, "s")
        ey_got = as_float(ey_got, "e_y")

        if max(abs(s_got - ey_exp), abs(ey_got - s_exp)) < 1e-3 and abs(s_exp - ey_exp) > 1e-3:
            raise Wrong(
                f"{where} your projection gives s = {s_got:.2f} m and e_y = {ey_got:.2f} m: "
                f"those are e_y and s (expected s = {s_exp:.2f} m, e_y = {ey_exp:.2f} m).",
                3.0,
                "You returned (e_y, s): return s first, then e_y.",
            )
        # s is compared modulo the lap: 0 m and the lap length are the same point.
        length = path.length
        ds = (s_got - s_exp + 0.5 * length) % length - 0.5 * length
        if abs(ds) > 1e-3:
            ahead = "further along the track than" if ds > 0 else "behind"
            msg = (
                f"{where} your projection puts the car {abs(ds):.2f} m {ahead} where it is "
                f"(expected s = {s_exp:.2f} m, got {s_got:.2f} m)."
            )
            near_line = min(s_exp, length - s_exp) < 20.0
            telling, hint = 0.0, ""
            if near_line and min(abs(s_got), abs(s_got - length)) < 1e-3 + abs(ds):
                telling = 2.0
                hint = (
                    "This point is near the start line, where s wraps from the lap length back "
                    "to 0: let the search cross the line (take s modulo the lap length instead "
                    "of clipping it to [0, length])."
                )
            elif abs(ds) > 20.0:
                telling = 1.0
                hint = "That is another part of the track: search the whole lap first."
            elif abs(ds) > 0.01:
                hint = "Close: refine s so that (x, y) - r(s) is normal to the track."
            raise Wrong(msg, telling, hint)
        if differs(ey_got, ey_exp, tol=1e-3):
            d = ey_got - ey_exp
            msg = (
                f"{where} your projection puts the car {abs(d):.2f} m {_side(d)} of where it "
                f"is (expected e_y = {ey_exp:.2f} m, got {ey_got:.2f} m)."
            )
            if not differs(-ey_got, ey_exp, tol=1e-3):
                hint = "Only the sign is off: e_y is positive LEFT of the direction of travel."
                raise Wrong(msg, 2.0, hint)
            if abs(ey_got) < 1e-3:
                hint = (
                    "Your e_y is the component of (x, y) - r(s) along the track, zero at the "
                    "nearest point: take its component along the left normal (-sin psi, cos psi)."
                )
                raise Wrong(msg, 2.0, hint)
            raise Wrong(msg)

    def body() -> str:
        track = _track()
        refuse_library(frenet_projection, _FRENET_LIBRARY, _FRENET_TASK)
        every_case(_cases(track.centerline, track), check_case)
        return "all eleven points projected to within 1 mm, across the start line and in corners."

    return grade("1.1 Frenet projection", body, weight=2.0)


def check_frenet_to_cartesian(frenet_to_cartesian) -> CheckResult:
    """Exercise 1.2: ``frenet_to_cartesian(path, s, e_y) -> (x, y)``.

    Compared with :meth:`racing_lib.geometry.Path.to_cartesian` on eleven points to 1 mm.
    """

    def check_case(case: tuple[float, float]) -> None:
        path = _track().centerline
        s0, e0 = case
        x_exp, y_exp, _ = path.to_cartesian(s0, e0)
        got = as_tuple(call(frenet_to_cartesian, path, s0, e0), 2, "frenet_to_cartesian")
        x_got, y_got = as_float(got[0], "x"), as_float(got[1], "y")
        miss = math.hypot(x_got - x_exp, y_got - y_exp)
        if miss > 1e-3:
            msg = (
                f"for s = {s0:.1f} m, e_y = {e0:.2f} m your point lies {miss:.2f} m from where "
                f"the car is (expected (x, y) = ({x_exp:.2f}, {y_exp:.2f}) m, got "
                f"({x_got:.2f}, {y_got:.2f}) m)."
            )
            x_c, y_c = path.position(s0)
            psi = float(path.heading(s0))
            psi_twice = math.radians(psi)  # radians converted once more
            # (point a tempting mistake gives, what the mistake is)
            mistakes = [
                (
                    path.to_cartesian(s0, -e0)[:2],
                    "It is on the wrong side: the normal (-sin psi, cos psi) points left.",
                ),
                ((x_c, y_c), "That is the centerline point: add e_y times the left normal."),
                (
                    (x_c + e0 * math.cos(psi), y_c + e0 * math.sin(psi)),
                    "You moved e_y along the track, on the tangent (cos psi, sin psi): move it "
                    "across, along the left normal (-sin psi, cos psi).",
                ),
                ((y_exp, x_exp), "You returned (y, x): return x first, then y."),
                (
                    (x_c - e0 * math.sin(psi_twice), y_c + e0 * math.cos(psi_twice)),
                    "path.heading is already in radians: do not convert it again.",
                ),
            ]
            for (x_m, y_m), hint in mistakes:
                if math.hypot(x_got - x_m, y_got - y_m) < 1e-3:
                    raise Wrong(msg, 2.0, hint)
            raise Wrong(msg)

    def body() -> str:
        track = _track()
        refuse_library(frenet_to_cartesian, _FRENET_LIBRARY, _CARTESIAN_TASK)
        every_case(_cases(track.centerline, track), check_case)
        return "all eleven points placed to within 1 mm."

    return grade("1.2 Frenet to Cartesian", body, weight=1.0)


_RATES = ("s_dot", "e_y_dot", "e_psi_dot")
_RATE_UNITS = {"s_dot": "m/s", "e_y_dot": "m/s", "e_psi_dot": "rad/s"}
_RATE_MEANING = {
    "s_dot": "the car advances along the road at",
    "e_y_dot": "the car drifts sideways (left positive) at",
    "e_psi_dot": "the car turns relative to the road at",
}


def check_frenet_rates(frenet_rates) -> CheckResult:
    """Exercise 1.3: the kinematic equations, ``frenet_rates``.

    ``frenet_rates(v_x, v_y, r, e_psi, e_y, kappa) -> (s_dot, e_y_dot, e_psi_dot)``: paper
    Eq. 2-4, compared with the kinematic rows of
    :meth:`racing_lib.model.Model.xi_dot` (relative 1e-9).
    """
    cases = [
        # v_x, v_y, r, e_psi, e_y, kappa: straight, inside and outside of bends, drifting
        (30.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        (30.0, 0.5, 0.6, 0.05, 4.0, 1.0 / 50.0),
        (25.0, -0.8, -0.3, -0.1, 3.0, -1.0 / 40.0),
        (40.0, 1.2, 0.2, 0.15, -5.0, 1.0 / 200.0),
        (15.0, 0.3, 0.4, -0.3, 2.5, 1.0 / 20.0),
    ]
    index = {"s_dot": X.S, "e_y_dot": X.EY, "e_psi_dot": X.EPSI}

    def body() -> str:
        model = Model()
        for v_x, v_y, r, e_psi, e_y, kappa in cases:
            xi = np.array([v_x, v_y, r, e_psi, e_y, 0.0])
            expected = model.xi_dot(xi, np.zeros(2), kappa=kappa)
            got = as_tuple(call(frenet_rates, v_x, v_y, r, e_psi, e_y, kappa), 3, "frenet_rates")
            bend = "a straight" if kappa == 0 else f"a bend of radius {1 / abs(kappa):.0f} m"
            where = (
                f"with v_x = {v_x:.0f} m/s, v_y = {v_y:.1f} m/s, r = {r:.2f} rad/s, "
                f"e_psi = {e_psi:.2f} rad, e_y = {e_y:.1f} m on {bend} "
                f"({'left' if kappa >= 0 else 'right'}-hand)"
            )
            for name, value in zip(_RATES, got, strict=True):
                g = as_float(value, name)
                e = float(expected[index[name]])
                unit = _RATE_UNITS[name]
                expect_close(
                    g,
                    e,
                    tol=1e-9,
                    rel=1e-9,
                    message=f"{where}, your {name} says {_RATE_MEANING[name]} {g:.3f} {unit}; "
                    f"it is {e:.3f} {unit} (expected {name} = {e:.4f}, got {g:.4f}).",
                )
        return "The rates s_dot, e_y_dot and e_psi_dot agree with the model in bends and drifts."

    return grade("1.3 Frenet kinematics", body, weight=1.0)
