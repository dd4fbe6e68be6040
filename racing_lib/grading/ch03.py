"""Checks of the exercises of chapter 03 (the speed profile and the curvature-optimal QP).

Exercise notebook: ``exercises/03_curvature.ipynb``. Every check compares the reader's function
with :mod:`racing_lib.planning` on the same cases.

* 3.1 :func:`check_cornering_speed`: the friction limit on speed in a corner (paper Eq. MaxV).
* 3.2 :func:`check_lap_time`: the time to drive a speed profile.
* 3.3 :func:`check_steady_cornering`: the linearization point of each QP iteration.
* 3.4 :func:`check_min_curvature_qp`: the minimum-curvature line of an oval, a QP the reader
  writes in cvxpy (:func:`oval_track` gives the oval).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from racing_lib.grading.grader import (
    CheckResult,
    Wrong,
    as_array,
    as_float,
    as_tuple,
    call,
    differs,
    every_case,
    grade,
    refuse_degrees,
    refuse_library,
)
from racing_lib.model import ModelOptions, ModelParams
from racing_lib.planning import solve_curvature
from racing_lib.planning.curvature import steady_cornering
from racing_lib.planning.speed import segment_times, speed_profile
from racing_lib.tracks import load_track

__all__ = [
    "OvalTrack",
    "check_cornering_speed",
    "check_lap_time",
    "check_min_curvature_qp",
    "check_steady_cornering",
    "line_curvature",
    "oval_track",
]

_DEG = 180.0 / math.pi
_SPACING = 5.0  # [m] node spacing of the exercise grid


@functools.lru_cache(maxsize=1)
def _grid() -> tuple[np.ndarray, np.ndarray, float]:
    """Arc length (m), centerline curvature (1/m) and length (m) of the expressway on a 5 m grid."""
    path = load_track("expressway").centerline
    s = path.sample(ds=_SPACING)
    return s, np.asarray(path.curvature(s), dtype=float), path.length


def _radius(kappa: float) -> str:
    return "a straight" if abs(kappa) < 1e-6 else f"a radius of {1.0 / abs(kappa):.0f} m"


def check_cornering_speed(cornering_speed) -> CheckResult:
    """Exercise 3.1: ``cornering_speed(kappa, mu, g, v_top) -> v_max`` (m/s), one per node.

    ``kappa`` is an array of curvatures (1/m). Compared with ``v_max`` of
    :func:`racing_lib.planning.speed.speed_profile` (a level road, relative 1e-9) along the
    expressway's centerline.
    """

    def body() -> str:
        s, kappa, length = _grid()
        p = ModelParams()
        v_top = 50.0
        expected = speed_profile(s, kappa, p, v_top=v_top, length=length).v_max
        with np.errstate(all="ignore"):
            raw = call(cornering_speed, kappa.copy(), p.mu, p.g, v_top)
        arr = np.asarray(raw, dtype=float)
        if arr.shape == kappa.shape and not np.all(np.isfinite(arr)):
            k = int(np.flatnonzero(~np.isfinite(arr))[0])
            if np.isnan(arr[k]) and kappa[k] < 0:
                raise Wrong(
                    f"at s = {s[k]:.0f} m ({_radius(kappa[k])}, kappa = {kappa[k]:.2g} 1/m) your "
                    f"speed limit is {arr[k]}: the square root of a negative number. Right-hand "
                    "bends (and the round-off on straights) have kappa < 0: use |kappa|."
                )
            raise Wrong(
                f"at s = {s[k]:.0f} m ({_radius(kappa[k])}, kappa = {kappa[k]:.2g} 1/m) your "
                f"speed limit is {arr[k]}: on straights the car is limited by its top speed "
                f"v_top = {v_top:.0f} m/s, not by its tyres."
            )
        got = as_array(raw, kappa.shape, "cornering_speed(kappa)")
        off = np.abs(got - expected) > 1e-9 * expected + 1e-9
        if np.any(off):
            k = int(np.argmax(np.abs(got - expected) * off))
            g, e = float(got[k]), float(expected[k])
            verb = "faster" if g > e else "slower"
            msg = (
                f"at s = {s[k]:.0f} m ({_radius(kappa[k])}) your car corners at {g:.2f} m/s, "
                f"{abs(g - e):.2f} m/s {verb} than its tyres allow (expected v_max = {e:.2f} m/s, "
                f"got {g:.2f} m/s)."
            )
            if e == v_top and g > v_top:
                msg += f" On straights the top speed {v_top:.0f} m/s is the limit."
            elif kappa[k] < 0 and not np.isfinite(g):
                msg += " Right-hand bends have kappa < 0: use |kappa|."
            raise Wrong(msg)
        return (
            f"the cornering limit agrees with speed_profile at all {s.size} nodes, left and right "
            "bends and straights."
        )

    return grade("3.1 Cornering speed limit", body, weight=1.0)


def check_lap_time(lap_time) -> CheckResult:
    """Exercise 3.2: ``lap_time(s, v, length) -> T`` (s) of a speed profile on a closed loop.

    Compared with ``lap_time`` of :func:`racing_lib.planning.speed.speed_profile` (1e-6 s) on two
    profiles of the expressway (with and without drag).
    """

    def body() -> str:
        s, kappa, length = _grid()
        p = ModelParams()
        with_drag = speed_profile(s, kappa, p, length=length)
        no_drag = speed_profile(s, kappa, p, options=ModelOptions(drag=False), length=length)
        # Every third node dropped, the first one too: the spacing is uneven and the loop closes
        # at s_0 + length, not at length (the grid's own nodes hide both).
        keep = np.arange(s.size) % 3 != 0
        s_odd, v_odd = s[keep], with_drag.v[keep]
        odd_time = float(
            np.sum(segment_times(np.diff(np.append(s_odd, s_odd[0] + length)), v_odd,
                                 np.roll(v_odd, -1)))
        )  # fmt: skip
        cases = [
            ("the expressway's speed profile", s, with_drag.v, with_drag.lap_time),
            ("the expressway's profile without drag", s, no_drag.v, no_drag.lap_time),
            ("the profile on unevenly spaced nodes from s = 5 m", s_odd, v_odd, odd_time),
        ]
        for what, s, v, expected in cases:
            got = as_float(call(lap_time, s.copy(), v.copy(), length), "lap_time")
            if differs(got, expected, tol=1e-6):
                msg = (
                    f"for {what} your car needs {got:.3f} s for the lap; driving it takes "
                    f"{expected:.3f} s ({abs(got - expected):.3f} s "
                    f"{'too long' if got > expected else 'too short'})."
                )
                ds = np.diff(np.append(s, s[0] + length))
                # (intervals, speeds at their ends, what the mistake is) of tempting mistakes
                mistakes = [
                    (
                        np.diff(np.append(s, length)),
                        np.roll(v, -1),
                        "The last interval ends at s_0 + length, where the loop closes, not at "
                        "length (the first node need not be at s = 0).",
                    ),
                    (
                        np.full(s.size, length / s.size),
                        np.roll(v, -1),
                        "The nodes are unevenly spaced here: use the actual intervals "
                        "s_{k+1} - s_k, not length / N.",
                    ),
                    (
                        ds,
                        np.roll(v, 1),
                        "Each interval runs from node k to node k+1: use the speeds at its own "
                        "two ends, v_k and v_{k+1}.",
                    ),
                ]
                for ds_m, v_next, hint in mistakes:
                    if not differs(got, float(np.sum(2.0 * ds_m / (v + v_next))), tol=1e-6):
                        raise Wrong(f"{msg} {hint}")
                if not differs(got, float(np.sum(ds / v)), tol=1e-6):
                    msg += (
                        " You divided each interval by the speed at its start: use the mean "
                        "speed of its two ends (uniform acceleration)."
                    )
                elif abs(got - expected) < 2.0 * ds[-1] / min(v[-1], v[0]):
                    msg += " Did you forget the last interval, from the last node back to s = 0?"
                raise Wrong(msg)
        return "the lap time agrees with speed_profile to the microsecond."

    return grade("3.2 Lap time of a speed profile", body, weight=1.0)


def check_steady_cornering(steady_state) -> CheckResult:
    """Exercise 3.3: ``steady_state(params, v, kappa) -> (v_y, r, delta)`` of steady cornering.

    Compared with :func:`racing_lib.planning.curvature.steady_cornering` (relative 1e-9) for
    corners of both directions below the friction limit.
    """
    cases = [(30.0, 1 / 200.0), (25.0, -1 / 80.0), (15.0, 1 / 30.0), (40.0, -1 / 400.0)]
    # r first: v_y and delta are built on it, so a wrong r is named as such.
    names = (("r", "rad/s", 1.0), ("v_y", "m/s", 1.0), ("delta", "deg", _DEG))
    # The default car has D = 1 on both axles; a car on worn tyres (D < 1) needs D in the formula.
    worn = ModelParams(D_f=0.9, D_r=0.85)

    def body() -> str:
        for p, v, kappa in [(ModelParams(), v, k) for v, k in cases] + [(worn, 20.0, 1 / 60.0)]:
            v_y, r, delta = (float(x) for x in steady_cornering(np.array(v), np.array(kappa), p))
            expected = (r, v_y, delta)
            got = as_tuple(call(steady_state, p, v, kappa), 3, "steady_state")
            got = (got[1], got[0], got[2])
            a_y = v * v * abs(kappa)
            tyres = " on worn tyres" if p is worn else ""
            where = (
                f"cornering {'left' if kappa > 0 else 'right'} at {v:.0f} m/s on {_radius(kappa)} "
                f"({a_y / p.g:.2f} g){tyres}"
            )
            for (name, unit, scale), value, e in zip(names, got, expected, strict=True):
                g = as_float(value, name)
                if differs(g, e, tol=1e-9, rel=1e-9):
                    if name == "delta":
                        refuse_degrees(g, e, f"steering angle {where}")
                    msg = (
                        f"{where}, your car has {name} = {g * scale:.4f} {unit}; steady cornering "
                        f"needs {e * scale:.4f} {unit} (expected {name} = {e:.6f}, got {g:.6f})."
                    )
                    if name == "r":
                        msg += " In steady cornering the car turns with the road: r = v kappa."
                    raise Wrong(msg)
        return "v_y, r and delta of steady cornering agree with the library, left and right."

    return grade("3.3 Steady cornering", body, weight=2.0)


class OvalTrack(NamedTuple):
    """An oval (two straights joined by two half circles) sampled for exercises 3.4 and 4.3.

    Attributes
    ----------
    s : ndarray (N,)
        Arc length of the nodes, m (uniform spacing ``ds``; the last node is ``ds`` before the
        first, round the loop).
    kappa : ndarray (N,)
        Curvature of the centerline at the nodes, 1/m (0 on the straights, 1/radius in the
        bends, counter-clockwise).
    ds : float
        Node spacing, m.
    length : float
        Lap length, m.
    half_width : float
        Distance from the centerline to either edge, m.
    """

    s: np.ndarray
    kappa: np.ndarray
    ds: float
    length: float
    half_width: float


def oval_track(
    straight: float = 200.0, radius: float = 60.0, half_width: float = 4.0, ds: float = 2.0
) -> OvalTrack:
    """The exercise oval: straights of ``straight`` m, bends of ``radius`` m, nodes ``ds`` apart."""
    length = 2.0 * straight + 2.0 * math.pi * radius
    n = int(round(length / ds))
    ds = length / n
    s = ds * np.arange(n)
    along_half = s % (straight + math.pi * radius)
    kappa = np.where(along_half < straight, 0.0, 1.0 / radius)
    return OvalTrack(s, kappa, float(ds), float(length), float(half_width))


def line_curvature(oval: OvalTrack, n: np.ndarray) -> np.ndarray:
    """Curvature (1/m) of the line ``n`` (m, left of the centerline), linearized for small n.

    ``kappa_c + (n_{k+1} - 2 n_k + n_{k-1}) / ds^2``, with the indices wrapping round the loop.
    """
    return oval.kappa + (np.roll(n, -1) - 2.0 * n + np.roll(n, 1)) / oval.ds**2


def _curvature_cost(oval: OvalTrack, n: np.ndarray) -> float:
    """The QP's objective: the integral of the squared line curvature, 1/m."""
    return float(np.sum(line_curvature(oval, n) ** 2) * oval.ds)


@functools.lru_cache(maxsize=4)
def _min_curvature_reference(margin: float) -> tuple[np.ndarray, float]:
    """The optimum of exercise 3.4 by another method: bounded least squares (SciPy's BVLS).

    A few seconds of dense linear algebra per margin, so each margin is solved once per process
    (the arrays returned are shared: read them, never write to them).
    """
    from scipy.optimize import lsq_linear

    oval = oval_track()
    n = oval.s.size
    eye = np.eye(n)
    d2 = (np.roll(eye, -1, axis=1) - 2.0 * eye + np.roll(eye, 1, axis=1)) / oval.ds**2
    bound = oval.half_width - margin
    scale = math.sqrt(oval.ds)
    res = lsq_linear(d2 * scale, -oval.kappa * scale, bounds=(-bound, bound), method="bvls")
    return res.x, _curvature_cost(oval, res.x)


def check_min_curvature_qp(min_curvature_line) -> CheckResult:
    """Exercise 3.4: ``min_curvature_line(oval, margin) -> n`` (m), the minimum-curvature line.

    The line's lateral offsets n (N,) minimize the integral of the squared curvature
    (:func:`line_curvature`) subject to ``|n_k| <= half_width - margin``. Checked for two margins:
    the line stays on the track, and its cost is the optimum to 1e-4 (relative), found by a
    different method (bounded least squares). Calling the library's curvature QP is refused.
    """

    def check_case(margin: float) -> None:
        oval = oval_track()
        # The student's line first: an unfinished exercise is reported without the reference's cost.
        got = as_array(call(min_curvature_line, oval, margin), oval.s.shape, "min_curvature_line")
        n_ref, cost_ref = _min_curvature_reference(margin)
        bound = oval.half_width - margin
        over = np.abs(got) - bound
        if np.max(over) > 1e-4:
            k = int(np.argmax(over))
            side = "left" if got[k] > 0 else "right"
            raise Wrong(
                f"with a margin of {margin:.1f} m your line passes {abs(got[k]):.2f} m {side} of "
                f"the centerline at s = {oval.s[k]:.0f} m, {over[k]:.2f} m beyond the "
                f"{bound:.1f} m it may use.",
                1.0,
                "Bound every offset: -(half_width - margin) <= n_k <= half_width - margin.",
            )
        cost = _curvature_cost(oval, got)
        if cost > cost_ref * (1.0 + 1e-4) + 1e-9:
            k = int(np.argmax(np.abs(got - n_ref)))
            msg = (
                f"with a margin of {margin:.1f} m your line's squared curvature integrates to "
                f"{cost:.5f} 1/m, the best line's to {cost_ref:.5f} 1/m ({cost / cost_ref:.2f} "
                f"times); the lines differ most at s = {oval.s[k]:.0f} m (yours n = "
                f"{got[k]:+.2f} m, the best n = {n_ref[k]:+.2f} m)."
            )
            if min(oval.s[k], oval.length - oval.s[k]) < 10.0:
                raise Wrong(
                    msg,
                    2.0,
                    "That is where the loop closes: the second difference of n_0 uses n_{N-1} and "
                    "that of n_{N-1} uses n_0.",
                )
            if np.max(np.abs(got + n_ref)) < 1e-2 * bound:
                raise Wrong(
                    msg,
                    2.0,
                    "Your line is the best one mirrored, outside where it should be inside: check "
                    "the sign of the second difference, kappa_c + (n_{k+1} - 2 n_k + n_{k-1}) / "
                    "ds^2 with n positive to the left.",
                )
            if np.max(np.abs(got)) < 1e-6:
                raise Wrong(msg, 2.0, "Your line is the centerline: include kappa_c in the cost.")
            raise Wrong(msg, 0.0, "Minimize the sum of squares of the line curvature, times ds.")

    def body() -> str:
        refuse_library(
            min_curvature_line,
            {"solve_curvature": solve_curvature},
            "write the QP in cvxpy: a variable per node, the curvature cost, the bounds.",
        )
        every_case((0.5, 1.5), check_case)
        oval = oval_track()
        n_ref, _ = _min_curvature_reference(0.5)
        return (
            f"your QP finds the minimum-curvature line for both margins: on the {oval.s.size}-node "
            f"oval it swings from {n_ref.min():+.1f} m to {n_ref.max():+.1f} m, apex inside."
        )

    return grade("3.4 The minimum-curvature QP", body, weight=3.0)
