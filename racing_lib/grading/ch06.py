"""Checks of the exercises of chapter 06 (tuning the MPC with CMA-ES).

Exercise notebook: ``exercises/06_tuning.ipynb``. Every check compares the reader's function with
:mod:`racing_lib.experiments.tuning` on the same cases.

* 6.1 :func:`check_tuning_objective`: the score of one completed closed-loop lap (paper Eq. CMA).
* 6.2 :func:`check_search_space`: from a CMA-ES point in log10 space to the MPC weights.
* 6.3 :func:`check_cma_es`: a CMA-ES loop of the reader's own, on an ill-conditioned, rotated
  ellipsoid that a search without covariance adaptation cannot solve on the same budget.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from racing_lib.experiments.lap import LapLog, LapMetrics
from racing_lib.experiments.tuning import W_S, W_T, mpc_weight_space, tuning_objective
from racing_lib.grading.grader import (
    CheckResult,
    Wrong,
    as_array,
    as_float,
    call,
    differs,
    every_case,
    grade,
    refuse_library,
)
from racing_lib.optim import cmaes as library_cmaes

__all__ = [
    "CMA_BUDGET",
    "check_cma_es",
    "check_search_space",
    "check_tuning_objective",
    "rotated_ellipsoid",
    "synthetic_lap",
]

_LENGTH = 4392.9  # [m] track length of the synthetic laps (about the expressway's)


def synthetic_lap(
    seed: int, wall_time: float = 0.0, offtrack_time: float = 0.0, ey_scale: float = 0.5
) -> tuple:
    """A made-up but consistent completed lap: ``(log, metrics, track_length)``.

    The car runs about 45 m/s from 150 m before the line, once round the loop and a little
    beyond, logged every 0.1 s; ``ey_scale`` (m) sets its lateral errors, ``wall_time`` and
    ``offtrack_time`` (s) its collision times.
    """
    rng = np.random.default_rng(seed)
    dt = 0.1
    n = int((_LENGTH + 300.0) / (45.0 * dt))
    vx_ref = 45.0 + 8.0 * np.sin(np.linspace(0.0, 12.0, n))
    vx = vx_ref + rng.normal(0.0, 0.6, n)
    s_track = (_LENGTH - 150.0 + np.cumsum(vx * dt)) % _LENGTH
    crossings = np.flatnonzero(np.diff(s_track) < -0.5 * _LENGTH) + 1
    in_lap = np.zeros(n, dtype=bool)
    in_lap[crossings[0] : crossings[1]] = True
    ey = ey_scale * np.sin(np.linspace(0.0, 40.0, n)) + rng.normal(0.0, 0.1 * ey_scale, n)
    zeros = np.zeros(n)
    log = LapLog(
        t=dt * np.arange(n),
        x=zeros,
        y=zeros,
        psi=zeros,
        vx=vx,
        vy=zeros,
        r=zeros,
        steer=zeros,
        pedal=zeros,
        s_ref=s_track,
        ey=ey,
        vx_ref=vx_ref,
        s_track=s_track,
        solve_ms=zeros,
        in_lap=in_lap,
    )
    err = np.abs(vx - vx_ref)[in_lap]
    metrics = LapMetrics(
        seed=seed,
        completed=True,
        lap_time_s=float(dt * in_lap.sum()),
        vx_mae_mps=float(err.mean()),
        vx_max_err_mps=float(err.max()),
        ey_mae_m=float(np.abs(ey[in_lap]).mean()),
        ey_max_m=float(np.abs(ey[in_lap]).max()),
        wall_contacts=int(wall_time > 0),
        wall_contact_time_s=wall_time,
        offtrack_time_s=offtrack_time,
        solve_time_ms_median=0.0,
        solve_time_ms_p99=0.0,
    )
    return log, metrics, _LENGTH


def check_tuning_objective(objective) -> CheckResult:
    """Exercise 6.1: ``objective(log, metrics, track_length, w_t, w_s) -> J`` of a completed lap.

    Compared with :func:`racing_lib.experiments.tuning.tuning_objective` (1e-9) on three laps: a
    clean one, one that touches a wall, and one that leaves an open track.
    """
    laps = [
        ("a clean lap", synthetic_lap(0)),
        ("a lap with 0.8 s against the wall", synthetic_lap(1, wall_time=0.8, ey_scale=1.5)),
        ("a lap with 1.5 s beyond the edge", synthetic_lap(2, offtrack_time=1.5, ey_scale=2.0)),
    ]

    def body() -> str:
        for what, (log, metrics, length) in laps:
            expected = tuning_objective(log, metrics, W_T, W_S, track_length=length)
            got = as_float(call(objective, log, metrics, length, W_T, W_S), "objective")
            if differs(got, expected, tol=1e-9, rel=1e-9):
                msg = (
                    f"for {what} your objective scores {got:.4f}; CMA-ES would see {expected:.4f} "
                    f"(off by {got - expected:+.4f})."
                )
                lap = np.asarray(log.in_lap)
                d = got - expected
                collision = metrics.wall_contact_time_s + metrics.offtrack_time_s
                ey = np.abs(log.ey[lap])
                # w_s D of the lap, from the library's own objective (no second unwrapping of s).
                distance_term = (
                    tuning_objective(log, metrics, W_T, 0.0, track_length=length) - expected
                )
                everything = dataclasses.replace(log, in_lap=np.ones(lap.size, dtype=bool))
                whole_log = tuning_objective(everything, metrics, W_T, W_S, track_length=length)
                if collision and not differs(d, -W_T * collision, tol=1e-6):
                    msg += " The collision time t_c (wall contact plus time off track) is missing."
                elif not differs(d, 2.0 * distance_term, tol=1e-6):
                    msg += (
                        " The distance term has the wrong sign: w_s D is subtracted (a lap that "
                        "covers more track scores lower)."
                    )
                elif not differs(abs(d), W_S * length, tol=0.05 * W_S * length):
                    msg += (
                        " The distance term is off by about one lap times w_s: D is the distance "
                        "travelled along the track in the lap (undo the jump of s_track at the "
                        "line), and it is subtracted."
                    )
                elif not differs(abs(d), ey.max(), tol=1e-6) or not differs(
                    abs(d), ey.mean(), tol=1e-6
                ):
                    msg += " Both the largest and the mean lateral error |e_y| belong in J."
                elif not differs(got, whole_log, tol=1e-6):
                    msg += " Use only the steps of the lap itself (log.in_lap)."
                raise Wrong(msg)
        return (
            "the objective agrees with racing_lib.experiments.tuning on clean laps, walls and "
            "off-track."
        )

    return grade("6.1 Tuning objective", body, weight=2.0)


def check_search_space(to_params) -> CheckResult:
    """Exercise 6.2: ``to_params(space, x) -> {name: weight}`` from a CMA-ES point in log10 space.

    Compared with :meth:`racing_lib.optim.cmaes.SearchSpace.to_params` (relative 1e-9) on the six
    MPC weights, with points inside and outside the box.
    """
    space = mpc_weight_space()
    lo, hi = space.log_bounds()
    rng = np.random.default_rng(3)
    points = [space.x0(), space.x0() + 0.5, rng.uniform(lo - 1.0, hi + 1.0)]

    def body() -> str:
        for x in points:
            expected = space.to_params(x)
            got = call(to_params, space, x.copy())
            if not isinstance(got, dict) or set(got) != set(expected):
                raise Wrong(
                    f"to_params should return a dict with the keys {sorted(expected)}, got {got!r}."
                )
            for i, name in enumerate(space.names):
                g, e = as_float(got[name], name), expected[name]
                if differs(g, e, tol=0.0, rel=1e-9):
                    msg = (
                        f"at the CMA-ES point log10({name}) = {x[i]:.3f} your weight is {g:.4g}; "
                        f"the tuner uses {e:.4g} (expected {name} = {e:.6g}, got {g:.6g})."
                    )
                    if not differs(g, 10.0 ** x[i], tol=0.0, rel=1e-9):
                        msg += (
                            f" The point lies outside the box [{space.lower[i]:g}, "
                            f"{space.upper[i]:g}]: clip it there first."
                        )
                    raise Wrong(msg)
        return "your map from log10 space to weights agrees with SearchSpace.to_params."

    return grade("6.2 Search space", body, weight=1.0)


#: Evaluations the reader's CMA-ES may spend per run in exercise 6.3.
CMA_BUDGET = 3000
#: Cost a run must reach: the optimum is 0.
_CMA_TARGET = 1e-8


def rotated_ellipsoid(dim: int = 6, condition: float = 1e4, seed: int = 42) -> Callable:
    """f(x) = sum_i condition^(i/(dim-1)) y_i^2, y = Q (x - 3): a valley along a tilted axis.

    The axes' lengths differ by sqrt(condition) (100 times at the default) and are rotated by a
    random orthogonal Q, so no coordinate-wise or isotropic search suits it; the minimum is 0 at
    x = (3, ..., 3). Its evaluations are counted in ``f.calls``.
    """
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
    scales = condition ** (np.arange(dim) / (dim - 1))
    optimum = np.full(dim, 3.0)

    def f(x) -> float:
        f.calls += 1
        y = q @ (np.asarray(x, dtype=float) - optimum)
        return float(np.sum(scales * y * y))

    f.calls = 0
    return f


def check_cma_es(cma_es) -> CheckResult:
    """Exercise 6.3: ``cma_es(f, x0, sigma0, budget, seed) -> x_best``, a CMA-ES loop.

    Three runs (seeds 0, 1, 2) from x0 = 0 with sigma0 = 1 on :func:`rotated_ellipsoid` must each
    reach f < 1e-8 within :data:`CMA_BUDGET` evaluations. A (mu/mu_w, lambda) search with step-size
    adaptation but without the covariance update ends at f = 10-200 on that budget. pycma and the
    library's tuner are refused.
    """

    def check_case(seed: int) -> None:
        f = rotated_ellipsoid()
        x0 = np.zeros(6)
        x_best = as_array(call(cma_es, f, x0.copy(), 1.0, CMA_BUDGET, seed), (6,), "cma_es")
        used = f.calls
        f_best = f(x_best)
        if used > CMA_BUDGET + 1:
            raise Wrong(
                f"with seed {seed} your search evaluated f {used} times; the budget is "
                f"{CMA_BUDGET}.",
                1.0,
                "Stop before a generation would exceed the budget.",
            )
        if f_best < _CMA_TARGET:
            return
        hint = (
            "Check the covariance update: C' = (1 - c_1 - c_mu) C + c_1 p_c p_c^T + c_mu "
            "sum_i w_i y_i y_i^T, with the steps y_i = (x_i - m) / sigma of the mu best."
        )
        if f_best > 1.0:
            hint = (
                "A valley this narrow and tilted is only solved by learning its shape: sample "
                "m + sigma B D z with C = B D^2 B^T, and update C from the selected steps."
            )
        raise Wrong(
            f"with seed {seed} your best point has f = {f_best:.3g} after {used} evaluations "
            f"(it should reach {_CMA_TARGET:g}; the minimum is 0 at x = (3, ..., 3)).",
            1.0 if f_best > 1.0 else 0.0,
            hint,
        )

    def body() -> str:
        refuse_library(
            cma_es,
            {
                "cma": None,
                "CMAEvolutionStrategy": None,
                "fmin": None,
                "fmin2": None,
                "CmaTuner": library_cmaes.CmaTuner,
                "tune": library_cmaes.tune,
            },  # fmt: skip
            "write the sampling, selection and the updates of m, p_sigma, sigma, p_c and C.",
        )
        every_case((0, 1, 2), check_case)
        return (
            f"your CMA-ES reaches f < {_CMA_TARGET:g} on the rotated ellipsoid (axes 100 times "
            f"apart) with all three seeds, within {CMA_BUDGET} evaluations each."
        )

    return grade("6.3 A CMA-ES loop", body, weight=3.0)
