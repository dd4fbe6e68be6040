"""Checks of the exercises of chapter 04 (the minimum-lap-time NLP).

Exercise notebook: ``exercises/04_time_optimal.ipynb``. Every check compares the reader's function
with :mod:`racing_lib.planning.time_optimal` or :mod:`racing_lib.model` on the same cases.

* 4.1 :func:`check_spatial_lap_time`: the NLP's objective, the lap time as an integral over s.
* 4.2 :func:`check_peak_slip_angle`: where the tyre force peaks (the NLP's slip-angle bound).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from racing_lib.grading.grader import (
    CheckResult,
    Wrong,
    as_float,
    call,
    differs,
    grade,
)

__all__ = ["check_peak_slip_angle", "check_spatial_lap_time"]

_DEG = 180.0 / math.pi


@functools.lru_cache(maxsize=1)
def _grid():
    """The expressway on a 5 m planning grid."""
    from racing_lib.planning.curvature import TrackGrid
    from racing_lib.tracks import load_track

    return TrackGrid.from_track(load_track("expressway"), spacing=5.0)


def _lines(grid) -> list[tuple[str, tuple[np.ndarray, ...]]]:
    """(description, (v_x, v_y, e_psi, e_y)) of a few drives along the grid."""
    from racing_lib.model import ModelParams
    from racing_lib.planning.speed import speed_profile

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
    from racing_lib.planning.time_optimal import lap_time_with_model

    def body() -> str:
        grid = _grid()
        for what, (v_x, v_y, e_psi, e_y) in _lines(grid):
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
    from racing_lib.model import ModelParams

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
                    raise Wrong(
                        f"for a {axle} tyre with B = {B:.1f} 1/rad and C = {C:.2f} your force "
                        f"peaks at a slip angle of {g * _DEG:.2f} deg; it peaks at "
                        f"{e * _DEG:.2f} deg "
                        f"(expected alpha_peak = {e:.5f} rad, got {g:.5f}). The sine is largest "
                        "where its argument C arctan(B alpha) is pi / 2."
                    )
        return "the peak slip angles agree with ModelParams.peak_slip_angle for four tyres."

    return grade("4.2 Peak slip angle", body, weight=1.0)
