"""Checks of the exercises of chapter 06 (tuning the MPC with CMA-ES).

Exercise notebook: ``exercises/06_tuning.ipynb``. Every check compares the reader's function with
:mod:`racing_lib.experiments.tuning` on the same cases.

* 6.1 :func:`check_tuning_objective`: the score of one completed closed-loop lap (paper Eq. CMA).
* 6.2 :func:`check_search_space`: from a CMA-ES point in log10 space to the MPC weights.
* 6.3 :func:`check_cma_es`: a CMA-ES loop of the reader's own, on an ill-conditioned, rotated
  ellipsoid that a search without covariance adaptation cannot solve on the same budget.
* 6.4 :func:`check_mpc_tuning`: the reader's CMA-ES tunes two MPC weights on a short closed-loop
  objective over a few seeds (:func:`stretch_objective`); the tuned weights must score no worse
  than the start, the search must spend its budget and score every candidate on every seed.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from racing_lib.experiments.lap import (
    LapLog,
    LapMetrics,
    LapSpec,
    make_car,
    make_controller,
    run_lap,
)
from racing_lib.experiments.tuning import (
    MPC_WEIGHT_BOX,
    W_S,
    W_T,
    evaluate_weights,
    mpc_weight_space,
    tune_weights,
    tuning_objective,
)
from racing_lib.grading.ch05 import capstone_lap
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
from racing_lib.optim.cmaes import SearchSpace

__all__ = [
    "CMA_BUDGET",
    "TUNING_BUDGET",
    "TUNING_SEEDS",
    "check_cma_es",
    "check_mpc_tuning",
    "check_search_space",
    "check_tuning_objective",
    "rotated_ellipsoid",
    "stretch_objective",
    "synthetic_lap",
    "tuning_space",
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


# --------------------------------------------------------------------------------------------------
# 6.4 Tuning the MPC with the reader's CMA-ES

#: Seeds of the car's per-trial randomness (friction, actuation noise) the weights of exercise
#: 6.4 are tuned on: the objective of a candidate is its mean over them. Not 0, 1, 2, so that a
#: loop that makes up its own seeds (``range(len(seeds))``) shows.
TUNING_SEEDS = (1, 2, 3)
#: Evaluations of the mean objective the reader's search may spend in exercise 6.4: the start
#: and two generations of 6 candidates (CMA-ES's default population for two parameters), each
#: scored on the three seeds: 39 closed-loop runs of 8 s, about 3 s in all.
TUNING_BUDGET = 13
#: The MPC weights tuned in exercise 6.4: the lateral error's and the steering rate's, the pair
#: that trades tracking against smoothness.
_TUNED = ("w_ey", "w_ddelta")
#: Simulated time of one run of :func:`stretch_objective`, s, and where it starts: this far
#: before the figure-eight's crossing, on the plan, so that the run covers the straight and the
#: entry of the right-hand loop.
_STRETCH_SECONDS = 8.0
_STRETCH_RUN_UP = 60.0


def tuning_space() -> SearchSpace:
    """The search space of exercise 6.4: ``w_ey`` and ``w_ddelta`` from the MPC's defaults.

    In log10 space (:class:`~racing_lib.optim.cmaes.SearchSpace`), inside the library's box for
    every MPC weight (1e-2 .. 1e4).
    """
    start = mpc_weight_space()
    lo, hi = MPC_WEIGHT_BOX
    return SearchSpace.from_bounds(
        {name: (lo, start.initial[start.names.index(name)], hi) for name in _TUNED}
    )


@functools.lru_cache(maxsize=256)
def _stretch(weights: tuple[tuple[str, float], ...], seed: int) -> float:
    track, plan = capstone_lap()
    spec = LapSpec(track=track, trajectory=plan, controller="coupled-mpc", weights=dict(weights),
                   run_up=_STRETCH_RUN_UP)  # fmt: skip
    car = make_car(spec)
    result = run_lap(car, make_controller(spec), plan, track=track, seed=seed,
                     max_time=_STRETCH_SECONDS)  # fmt: skip
    # The lap objective over the whole window: every step counts, the collisions are the car's.
    window = dataclasses.replace(result.log, in_lap=np.ones(result.log.t.size, dtype=bool))
    metrics = dataclasses.replace(result.metrics, completed=True,
                                  wall_contact_time_s=car.wall_contact_time,
                                  offtrack_time_s=car.offtrack_time)  # fmt: skip
    return tuning_objective(window, metrics, W_T, W_S, track_length=track.length)


def stretch_objective(weights: Mapping[str, float], seed: int) -> float:
    """The tuning objective of exercise 6.4: a short closed-loop run of the coupled MPC.

    The objective of exercise 6.1 (:func:`racing_lib.experiments.tuning.tuning_objective`, lower
    is better), over a fixed 8 s window instead of a lap: the coupled MPC with ``weights`` (the
    others at their defaults) drives the figure-eight of exercise 5.5 from 60 m before the
    crossing, on the plan, along the straight and into the right-hand loop. Every step of the
    window counts; with a fixed duration the distance term rewards speed. A whole lap of the
    expressway costs about a dozen times more (0.9 s against 0.07 s, measured): 35 s for the 39
    runs the check scores, against 3 s.

    Parameters
    ----------
    weights : mapping
        MPC weights by ``MPCSettings`` name (``w_ey`` in 1/m^2, ``w_ddelta`` in 1/rad^2, ...).
    seed : int
        Seed of the car's friction variation and actuation noise.

    Returns
    -------
    float
        The objective (dimensionless); the same weights and seed always give the same value.
    """
    key = tuple(sorted((str(k), float(v)) for k, v in weights.items()))
    return _stretch(key, int(seed))


class _CountingObjective:
    """:func:`stretch_objective` as the reader's loop sees it, recording every call.

    A call it cannot score (not a dict of the space's weights, a seed not given) records the
    first such problem and returns a poor score: a :class:`Wrong` raised inside the reader's
    function would be reported as a crash of their code.
    """

    def __init__(self, space: SearchSpace, seeds: Sequence[int], budget: int) -> None:
        self.space, self.seeds, self.budget = space, tuple(seeds), int(budget)
        self.calls: list[tuple[tuple[float, ...], int, float]] = []
        #: Every candidate the loop asked for, also those beyond the budget (not driven).
        self.candidates: set[tuple[float, ...]] = set()
        self.problem: Wrong | None = None

    def _refuse(self, message: str) -> float:
        if self.problem is None:
            self.problem = Wrong(message)
        return 3000.0  # the library's score of a failed evaluation

    def __call__(self, weights: object, seed: object) -> float:
        if self.problem is not None:
            return 3000.0  # the verdict is decided: no more driving
        names = self.space.names
        if not isinstance(weights, Mapping) or set(weights) != set(names):
            shown = dict(weights) if isinstance(weights, Mapping) else np.asarray(weights).round(3)
            return self._refuse(
                f"your loop called evaluate({shown}, ...); it takes the weights as a dict "
                f"with the keys {list(names)}: turn a CMA-ES point x into weights with "
                "to_params(space, x)."
            )
        values = tuple(float(weights[n]) for n in names)
        if not all(math.isfinite(v) and v > 0 for v in values):
            return self._refuse(f"your loop called evaluate with the weights "
                                f"{_shown(self.space, values)}: weights are positive (10^x of "
                                "the CMA-ES point).")  # fmt: skip
        log_start = np.round(self.space.x0(), 9)
        if np.allclose(values, log_start) and not np.allclose(values, self.space.initial):
            return self._refuse(
                f"your loop called evaluate with {_shown(self.space, values)}: those are log10 "
                f"of the starting weights ({_shown(self.space, self.space.initial)}). CMA-ES "
                "searches log10 space; turn its point into weights with to_params(space, x)."
            )
        if seed not in self.seeds:
            return self._refuse(
                f"your loop scored a candidate on seed {seed!r}; the seeds to tune on are "
                f"{self.seeds}: use the seeds given."
            )
        self.candidates.add(values)
        if len(self.candidates) > self.budget:
            # Beyond the budget the verdict is decided: say so without driving (a loop that spends
            # three times its budget would otherwise take 20 s).
            return 3000.0
        value = stretch_objective(dict(zip(names, values, strict=True)), int(seed))
        self.calls.append((values, int(seed), value))
        return value

    def mean(self, values: tuple[float, ...]) -> float:
        """The objective of weights ``values`` (in the space's order) over the seeds."""
        weights = dict(zip(self.space.names, values, strict=True))
        return float(np.mean([stretch_objective(weights, seed) for seed in self.seeds]))


def _check_spending(evaluate: _CountingObjective, lam: int) -> dict:
    """Every candidate scored on every seed once, within the budget; returns {candidate: J}."""
    if evaluate.problem is not None:
        raise evaluate.problem
    budget = evaluate.budget
    if len(evaluate.candidates) > budget:
        raise Wrong(f"your search scored {len(evaluate.candidates)} candidates (or more); the "
                    f"budget is {budget} evaluations of the mean objective. Pass the budget to "
                    "cma_es as it is: it counts evaluations of f, each one the mean over the "
                    "seeds, not single runs.")  # fmt: skip
    seeds_of: dict[tuple[float, ...], list[int]] = {}
    for values, seed, _ in evaluate.calls:
        seeds_of.setdefault(values, []).append(seed)
    for values, used in seeds_of.items():
        if sorted(used) != sorted(evaluate.seeds):
            raise Wrong(
                f"your loop scored the candidate ({_shown(evaluate.space, values)}) on the seeds "
                f"{sorted(used)}; the "
                f"objective of a candidate is its mean over all the seeds {evaluate.seeds}, "
                "each once: weights tuned on one seed are tuned to its luck (its friction, its "
                "noise)."
            )
    n = len(seeds_of)
    if n < budget - lam + 1:
        raise Wrong(f"your search scored only {n} candidate(s) of its budget of {budget}: pass the "
                    "budget to cma_es as it is (it counts evaluations of f, the mean over the "
                    "seeds, not single runs).")  # fmt: skip
    return {values: evaluate.mean(values) for values in seeds_of}


def _shown(space: SearchSpace, values: Sequence[float]) -> str:
    """Weights in words: ``w_ey = 5, w_ddelta = 100``."""
    return ", ".join(f"{n} = {float(v):.4g}" for n, v in zip(space.names, values, strict=True))


def _judge_tuned(
    evaluate: _CountingObjective, scores: Mapping[tuple[float, ...], float], tuned: tuple
) -> tuple[float, float]:
    """``(J of the tuned weights, J of the start)`` over the seeds, when the tuned are the best.

    Raises :class:`Wrong`, with the likely reason, when they score worse than the start or than
    the best candidate the search scored.
    """
    start = evaluate.mean(tuple(evaluate.space.initial))
    value = scores.get(tuned)
    scored = value is not None
    if not scored:
        value = evaluate.mean(tuned) if all(v > 0 for v in tuned) else math.inf
    best_seen = min(scores.values(), default=start)
    if value <= min(start, best_seen) + 1e-9:
        return value, start
    shown = _shown(evaluate.space, tuned)
    msg = (f"your tuned weights ({shown}) score J = {value:.4f} over the seeds; the start scores "
           f"{start:.4f} and the best candidate your search scored {best_seen:.4f}.")  # fmt: skip
    if scored and len(scores) > 2 and value >= max(scores.values()) - 1e-9:
        raise Wrong(
            msg + " They are the worst candidate it scored: CMA-ES minimizes, and J is "
            "lower for better weights; does your f return +J, the mean itself?"
        )
    if np.allclose(tuned, evaluate.space.initial, rtol=1e-9, atol=0.0):
        raise Wrong(msg + " They are the starting weights: return the best point the search "
                    "found, not the one it started from.")  # fmt: skip
    if not scored:
        raise Wrong(msg + " Your search never scored them (the mean CMA-ES ended with?): return "
                    "the best point it scored.")  # fmt: skip
    raise Wrong(msg + " Return the best point your search scored, not the last one.")


def check_mpc_tuning(tune_mpc) -> CheckResult:
    """Exercise 6.4: ``tune_mpc(evaluate, space, seeds, budget) -> {name: weight}``.

    The reader's loop tunes ``w_ey`` and ``w_ddelta`` (:func:`tuning_space`) with their own
    CMA-ES of exercise 6.3, scoring a candidate by the mean of ``evaluate(weights, seed)``
    (:func:`stretch_objective`) over :data:`TUNING_SEEDS`, in at most :data:`TUNING_BUDGET`
    candidates. Checked: every candidate was scored on every seed once; the search spent its
    budget (no more, and no generation less); the returned weights score no worse than the start
    and no worse than the best candidate the search scored. The library's tuner and pycma are
    refused.
    """
    space = tuning_space()
    lam = 4 + int(3 * math.log(len(space.names)))  # the population of the reader's cma_es

    def body() -> str:
        refuse_library(
            tune_mpc,
            {
                "tune_weights": tune_weights,
                "evaluate_weights": evaluate_weights,
                "tune": library_cmaes.tune,
                "CmaTuner": library_cmaes.CmaTuner,
                "cma": None,
                "CMAEvolutionStrategy": None,
                "fmin": None,
                "fmin2": None,
            },  # fmt: skip
            "tune with your cma_es of exercise 6.3, scoring a point by the mean of evaluate over "
            "the seeds.",
        )
        evaluate = _CountingObjective(space, TUNING_SEEDS, TUNING_BUDGET)
        got = call(tune_mpc, evaluate, space, TUNING_SEEDS, TUNING_BUDGET)
        scores = _check_spending(evaluate, lam)
        if not isinstance(got, Mapping) and np.shape(got) == (len(space.names),):
            raise Wrong(f"tune_mpc returned {np.round(np.asarray(got, dtype=float), 3)}, a point "
                        "of CMA-ES's log10 space; return the weights themselves, as a dict: "
                        "to_params(space, x_best).")  # fmt: skip
        if not isinstance(got, Mapping) or set(got) != set(space.names):
            raise Wrong(f"tune_mpc should return the tuned weights as a dict with the keys "
                        f"{list(space.names)}: to_params(space, x_best); got {got!r}.")  # fmt: skip
        tuned = tuple(as_float(got[n], n) for n in space.names)
        value, start = _judge_tuned(evaluate, scores, tuned)
        # No measured number in the verdict: the notebook compares it (nbval), and a closed
        # loop's last digits may differ on another machine.
        better = "better than" if value < start - 1e-9 else "as good as"
        return (
            f"your CMA-ES scored {len(scores)} candidates, each on every seed of {TUNING_SEEDS}, "
            f"within its budget of {TUNING_BUDGET}, and returned the best of them: weights "
            f"{better} the start on the mean over the seeds."
        )

    return grade("6.4 Tuning the MPC with your CMA-ES", body, weight=3.0)
