"""Checks of the exercises of chapter 04 (the minimum-lap-time NLP).

Exercise notebook: ``exercises/04_time_optimal.ipynb``. Every check compares the reader's function
with :mod:`racing_lib.planning.time_optimal` or :mod:`racing_lib.model` on the same cases.

* 4.1 :func:`check_spatial_lap_time`: the NLP's objective, the lap time as an integral over s.
* 4.2 :func:`check_peak_slip_angle`: where the tyre force peaks (the NLP's slip-angle bound).
* 4.3 :func:`check_min_time_nlp`: a minimum-lap-time NLP of a point mass round the exercise oval,
  which the reader writes in CasADi and solves with IPOPT.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from racing_lib.grading.ch03 import oval_track
from racing_lib.grading.grader import (
    CheckResult,
    Wrong,
    as_array,
    as_float,
    call,
    differs,
    every_case,
    grade,
    refuse_degrees,
    refuse_library,
)
from racing_lib.model import ModelParams
from racing_lib.planning import plan, solve_time_optimal
from racing_lib.planning.grid import TrackGrid
from racing_lib.planning.speed import segment_times, speed_profile
from racing_lib.planning.time_optimal import lap_time_with_model
from racing_lib.tracks import load_track

__all__ = ["check_min_time_nlp", "check_peak_slip_angle", "check_spatial_lap_time"]

_DEG = 180.0 / math.pi


@functools.lru_cache(maxsize=1)
def _grid():
    """The expressway on a 5 m planning grid."""
    return TrackGrid.from_track(load_track("expressway"), spacing=5.0)


def _lines(grid) -> list[tuple[str, tuple[np.ndarray, ...]]]:
    """(description, (v_x, v_y, e_psi, e_y)) of a few drives along the grid."""
    prof = speed_profile(grid.s, grid.kappa, ModelParams(), length=grid.length)
    n = grid.n
    phase = 2.0 * np.pi * grid.s / grid.length
    zero = np.zeros(n)
    weave = 0.8 * np.clip(grid.ey_max, 0, None) * np.sin(40 * phase)
    return [
        ("the centerline at its speed profile", (prof.v, zero, zero, zero)),
        (
            "a line weaving across the track, sliding a little",
            (prof.v, 0.3 * np.sin(17 * phase), 0.05 * np.cos(40 * phase), weave),
        ),
        ("the centerline at a constant 20 m/s", (np.full(n, 20.0), zero, zero, zero)),
    ]


def check_spatial_lap_time(lap_time) -> CheckResult:
    """Exercise 4.1: ``lap_time(ds, kappa, v_x, v_y, e_psi, e_y) -> T`` (s) on a closed grid.

    Compared with :func:`racing_lib.planning.time_optimal.lap_time_with_model` (1e-6 s).
    """

    def body() -> str:
        grid = _grid()
        lines = _lines(grid)
        cases = [(what, grid, line) for what, line in lines]
        # The grid is evenly spaced, where a rectangle rule or a trapezoid paired with the wrong
        # neighbour sums to the same: drop two nodes of every five to make the spacing uneven
        # (5, 10 and 10 m; alternating 5 and 10 m would still hide the neighbour).
        keep = np.isin(np.arange(grid.n) % 5, (1, 3, 4))
        s = grid.s[keep]
        uneven = dataclasses.replace(
            grid, s=s, ds=np.diff(np.append(s, s[0] + grid.length)), kappa=grid.kappa[keep],
            theta=grid.theta[keep], ey_min=grid.ey_min[keep], ey_max=grid.ey_max[keep],
        )  # fmt: skip
        what, line = lines[1]
        cases.append((f"{what}, on a grid of uneven spacing", uneven, [a[keep] for a in line]))
        for what, grid, (v_x, v_y, e_psi, e_y) in cases:
            expected = lap_time_with_model(grid, v_x, v_y, e_psi, e_y)
            args = (grid.ds.copy(), grid.kappa.copy(), v_x.copy(), v_y.copy(), e_psi, e_y)
            got = as_float(call(lap_time, *args), "lap_time")
            if differs(got, expected, tol=1e-6):
                msg = (
                    f"driving {what}, your lap takes {got:.3f} s; the NLP's objective gives "
                    f"{expected:.3f} s ({abs(got - expected):.3f} s "
                    f"{'too long' if got > expected else 'too short'})."
                )
                s_dot_plain = v_x * np.cos(e_psi) - v_y * np.sin(e_psi)
                plain = float(
                    np.sum(0.5 * grid.ds * (1 / s_dot_plain + 1 / np.roll(s_dot_plain, -1)))
                )
                if np.any(e_y) and not differs(got, plain, tol=1e-6):
                    msg += (
                        " Off the centerline the car's path is longer or shorter than the "
                        "centerline's: divide by 1 - kappa e_y as in s_dot."
                    )
                raise Wrong(msg)
        return "the lap time agrees with the NLP's objective on and off the centerline."

    return grade("4.1 Lap time in the spatial domain", body, weight=2.0)


def check_peak_slip_angle(peak_slip_angle) -> CheckResult:
    """Exercise 4.2: ``peak_slip_angle(B, C) -> alpha_peak`` (rad) of the simplified Pacejka law.

    Compared with :meth:`racing_lib.model.ModelParams.peak_slip_angle` (relative 1e-9) for the
    default car and two other tyres.
    """

    def body() -> str:
        tyres = [ModelParams(), ModelParams(B_f=8.0, C_f=1.3, B_r=14.0, C_r=1.6)]
        for p in tyres:
            expected = p.peak_slip_angle()
            for axle, B, C, e in (
                ("front", p.B_f, p.C_f, expected[0]),
                ("rear", p.B_r, p.C_r, expected[1]),
            ):
                g = as_float(call(peak_slip_angle, B, C), "peak_slip_angle")
                if differs(g, e, tol=0.0, rel=1e-9):
                    refuse_degrees(g, e, f"peak slip angle of the {axle} tyre")
                    raise Wrong(
                        f"for a {axle} tyre with B = {B:.1f} 1/rad and C = {C:.2f} your force "
                        f"peaks at a slip angle of {g * _DEG:.2f} deg; it peaks at "
                        f"{e * _DEG:.2f} deg "
                        f"(expected alpha_peak = {e:.5f} rad, got {g:.5f}). The sine is largest "
                        "where its argument C arctan(B alpha) is pi / 2."
                    )
        return "the peak slip angles agree with ModelParams.peak_slip_angle for four tyres."

    return grade("4.2 Peak slip angle", body, weight=1.0)


def _point_mass_lap_time(ds: float, v: np.ndarray) -> float:
    """Lap time (s) of node speeds v (m/s), uniform acceleration between nodes ``ds`` apart."""
    return float(np.sum(segment_times(ds, v, np.roll(v, -1))))


@functools.lru_cache(maxsize=4)
def _min_time_reference(grip: float, v_top: float) -> tuple[np.ndarray, float]:
    """The optimum of exercise 4.3 by another method: a convex program in w = v^2 (cvxpy).

    With w_k = v_k^2 the dynamics w_{k+1} - w_k = 2 a_k ds are linear, the friction circle is a
    second-order cone, and each interval's time 2 ds / (sqrt(w_k) + sqrt(w_{k+1})) is convex in
    w: the problem has one optimum, which a conic solver finds to high accuracy.
    """
    import cvxpy as cp

    oval = oval_track()
    n = oval.s.size
    w, a = cp.Variable(n), cp.Variable(n)
    w_next = cp.hstack([w[1:], w[:1]])
    cost = cp.sum(2.0 * oval.ds * cp.inv_pos(cp.sqrt(w) + cp.sqrt(w_next)))
    constraints = [
        w_next - w == 2.0 * oval.ds * a,
        cp.square(a / grip) + cp.square(cp.multiply(oval.kappa, w) / grip) <= 1.0,
        w <= v_top**2,
        w >= 1.0,
    ]
    cp.Problem(cp.Minimize(cost), constraints).solve(solver=cp.CLARABEL)
    v = np.sqrt(np.maximum(w.value, 0.0))
    return v, _point_mass_lap_time(oval.ds, v)


def check_min_time_nlp(min_time_speeds) -> CheckResult:
    """Exercise 4.3: ``min_time_speeds(oval, grip, v_top) -> v`` (m/s), the minimum-time speeds.

    A point mass drives the oval's centerline (:func:`racing_lib.grading.ch03.oval_track`) with
    node speeds v_k, accelerating uniformly between nodes: ``v_{k+1}^2 = v_k^2 + 2 a_k ds``. Its
    tyres give ``(a_k / grip)^2 + (v_k^2 kappa_k / grip)^2 <= 1`` and it tops out at ``v_top``.
    Checked for two grip levels: the speeds are feasible (1e-4) and the lap time is the optimum
    to 1e-4 (relative), found by a convex reformulation in v^2. The library's speed profile and
    planners are refused.
    """

    def check_case(case: tuple[float, float]) -> None:
        grip, v_top = case
        oval = oval_track()
        v_ref, t_ref = _min_time_reference(grip, v_top)
        what = f"with grip {grip:.1f} m/s^2"
        got = as_array(call(min_time_speeds, oval, grip, v_top), v_ref.shape, "min_time_speeds")
        if np.min(got) <= 0.0:
            raise Wrong(f"{what} your car stands still or reverses (min v = {np.min(got):.2f}).")
        a = (np.roll(got, -1) ** 2 - got**2) / (2.0 * oval.ds)
        a_y = got**2 * oval.kappa
        use = (a / grip) ** 2 + (a_y / grip) ** 2
        if np.max(use) > 1.0 + 1e-4:
            k = int(np.argmax(use))
            hint = "Bound every node by the circle (a_k/grip)^2 + (v_k^2 kappa_k/grip)^2 <= 1."
            if np.max(np.abs(a_y)) > grip * (1.0 + 1e-4):
                hint = "The lateral acceleration v^2 kappa alone exceeds the grip: bound it too."
            raise Wrong(
                f"{what} your car needs {np.sqrt(use[k]):.2f} times its grip at s = "
                f"{oval.s[k]:.0f} m (a_x = {a[k]:+.2f} m/s^2, a_y = {a_y[k]:.2f} m/s^2 at "
                f"{got[k]:.1f} m/s): the tyres cannot do that.",
                2.0,
                hint,
            )
        if np.max(got) > v_top + 1e-4:
            raise Wrong(f"{what} your car reaches {np.max(got):.2f} m/s, above v_top {v_top}.")
        lap = _point_mass_lap_time(oval.ds, got)
        if lap > t_ref * (1.0 + 1e-4):
            k = int(np.argmax(v_ref - got))
            raise Wrong(
                f"{what} your lap takes {lap:.3f} s, the fastest {t_ref:.3f} s "
                f"({lap - t_ref:.3f} s slower); your car is slowest against the best at s = "
                f"{oval.s[k]:.0f} m ({got[k]:.2f} m/s against {v_ref[k]:.2f} m/s).",
                1.0,
                "Minimize the lap time itself, sum of 2 ds / (v_k + v_{k+1}), and check that "
                "IPOPT reports 'Solve_Succeeded'.",
            )

    def body() -> str:
        refuse_library(
            min_time_speeds,
            {
                "speed_profile": speed_profile,
                "solve_time_optimal": solve_time_optimal,
                "plan": plan,
            },  # fmt: skip
            "write the NLP with casadi.Opti: speeds and accelerations per node, the lap time, the "
            "dynamics and the friction circle.",
        )
        every_case(((9.0, 50.0), (12.0, 40.0)), check_case)
        _, t_ref = _min_time_reference(9.0, 50.0)
        return (
            f"your NLP finds the fastest lap for both grip levels ({t_ref:.2f} s with 9 m/s^2), "
            "within the friction circle at every node."
        )

    return grade("4.3 A minimum-time NLP", body, weight=3.0)
