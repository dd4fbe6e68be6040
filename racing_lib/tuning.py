"""CMA-ES tuning of controller weights over closed-loop laps (paper Section "Hyperparameter
Optimization"; taught in the tuning chapter, notebook 06).

The paper tunes the six weights of its MPC cost (v_x, v_y, yaw rate, e_psi, e_y, steering rate)
with CMA-ES, minimizing a score of closed-loop laps (:func:`tuning_objective`). This module has two
layers:

* a generic one, :class:`CmaTuner` / :func:`tune`: CMA-ES (pycma) over positive parameters
  searched in log10 space inside a box (:class:`SearchSpace`), for any evaluation function
  ``f(params: dict) -> float``. Candidates of a generation are evaluated through any
  ``concurrent.futures.Executor`` (a process pool, or a Dask client's executor), every generation
  is checkpointed atomically, and an interrupted run resumes to exactly the result of an
  uninterrupted one;
* a thin racing layer on top: :func:`evaluate_weights` (the picklable "weights -> objective" of
  one lap specification), :func:`tune_weights` (the MPC weights), :func:`tune_nominal_gains` (the
  nominal controller's gains, the same machinery on a controller that needs no QP), and the tuned
  weights shipped with the package (:func:`tuned_weights`).

Examples
--------
The generic machinery on a function whose minimum is known (at p = 10 and q = 0.1):

>>> import math
>>> def f(p):
...     return (math.log10(p["p"]) - 1.0) ** 2 + (math.log10(p["q"]) + 1.0) ** 2
>>> space = SearchSpace.from_bounds({"p": (1e-3, 1.0, 1e3), "q": (1e-3, 1.0, 1e3)})
>>> res = tune(f, space, TuningSettings(max_generations=60, seed=1), progress=False)
>>> round(res.best_weights["p"], 1), round(res.best_weights["q"], 2)
(10.0, 0.1)

Tuning the MPC weights of one configuration on two worker processes (minutes):

>>> from racing_lib.experiment import LapSpec  # doctest: +SKIP
>>> spec = LapSpec(track=track, trajectory=plan, controller="coupled-mpc")  # doctest: +SKIP
>>> res = tune_weights(spec, seeds=(0,), workers=2, out_dir="tuning/main")  # doctest: +SKIP
>>> res.best_weights  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pickle
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path as FilePath
from typing import Any

import numpy as np

from racing_lib.config import fast_mode
from racing_lib.errors import ControlError, RacingLibError
from racing_lib.io import atomic_write_bytes, atomic_write_json, jsonable

# --------------------------------------------------------------------------------------------------
# The objective of a closed-loop lap

#: Weight of the time spent in collision with the track boundary, per s (the paper's w_t).
W_T = 10.0
#: Weight of the distance travelled, per m (the paper's w_s).
W_S = 0.001
#: Base score of a lap that was not completed: every incomplete lap scores in
#: ``(INCOMPLETE_PENALTY, 2 INCOMPLETE_PENALTY]``, above any reasonable completed lap.
INCOMPLETE_PENALTY = 1000.0
#: Score of an evaluation in which the simulation itself failed (a ``RacingLibError``, such as a
#: plant that diverged): worse than any incomplete lap, but finite so CMA-ES can rank it.
FAILED_EVALUATION = 3.0 * INCOMPLETE_PENALTY
#: What a non-finite value returned by an evaluation function is replaced with (CMA-ES ranks).
NONFINITE_VALUE = 1e30


def _progress(s_track: np.ndarray, track_length: float | None) -> np.ndarray:
    """Distance along the track between consecutive logged steps, m (wraps at the line undone).

    ``s_track`` jumps back by one track length where the car crosses the start/finish line; a
    step that moves by more than half a lap is such a wrap. Without ``track_length`` the length is
    estimated from the log itself (the largest ``s`` seen plus one step), which is exact enough to
    rank incomplete laps.
    """
    s = np.asarray(s_track, dtype=float)
    if s.size < 2:
        return np.zeros(0)
    ds = np.diff(s)
    if track_length is None or not track_length > 0:
        forward = ds[ds > 0]
        track_length = float(s.max()) + (float(forward.max()) if forward.size else 0.0)
    half = 0.5 * track_length
    # Wrap every step into [-L/2, L/2): a crossing forward (s: L -> 0) becomes a small step.
    return (ds + half) % track_length - half


def tuning_objective(
    log: Any,
    metrics: Any,
    w_t: float = W_T,
    w_s: float = W_S,
    *,
    track_length: float | None = None,
    distance: str = "sum",
    incomplete_penalty: float = INCOMPLETE_PENALTY,
) -> float:
    """The paper's CMA-ES objective of one closed-loop lap (Eq. "CMA"), lower is better.

    For a completed lap, over the N_f control steps between the two crossings of the line::

        J = max_k |e_y,k| + mean_k |e_y,k| + mean_k |v_x,k - v_x,ref,k|
            + w_t * t_c - w_s * D

    with t_c the time in collision with the track boundary, s (wall contact on walled tracks plus
    time beyond the edge on open tracks, the open track's "boundary"), and D the distance
    travelled along the track, m.

    How the last two terms are read. The paper writes them after the averaged bracket with a step
    index k (``w_t t_c,k - w_s Delta s_k``) and calls Delta s_k "distance traveled at each time"; we
    read both as summed over the steps, like the collision time: t_c is the total collision time
    and D = sum_k Delta s_k the total distance (``distance="sum"``, the default). Over a flying lap
    timed from line to line D is about the lap length for every candidate, so w_s D is then a
    constant offset (-4.4 for the expressway) that leaves the ranking of completed laps to the
    error and collision terms (a slow lap already pays through |v_x - v_x,ref|); the paper's
    evaluation windows were presumably of fixed duration, where D rewards speed. The alternative
    reading, the mean distance per step (``distance="mean"``, D = L / N_f, which grows with speed),
    is available; with w_s = 0.001 it changes J by about 0.004.

    An incomplete lap (``metrics.completed`` False) scores
    ``incomplete_penalty * (1 + exp(-P / L))``, where P is the distance covered over the whole log
    (run-up included) and L the track length: finite, above every completed lap, and lower the
    further the car got, so CMA-ES can still rank failed candidates.

    Parameters
    ----------
    log : LapLog
        The lap's log (uses ``ey`` (m), ``vx`` and ``vx_ref`` (m/s), ``s_track`` (m), ``in_lap``).
    metrics : LapMetrics
        The lap's metrics (uses ``completed``, ``wall_contact_time_s`` and ``offtrack_time_s``, s).
    w_t : float
        Weight of the collision time, 1/s (paper: 10).
    w_s : float
        Weight of the distance, 1/m (paper: 0.001).
    track_length : float, optional
        Length of the track centerline, m, used to undo the wrap of ``s_track`` at the line
        (estimated from the log when omitted).
    distance : {'sum', 'mean'}
        Reading of the distance term, see above.
    incomplete_penalty : float
        Base score of an incomplete lap.

    Returns
    -------
    float
        The objective; always finite.
    """
    if distance not in ("sum", "mean"):
        raise ControlError(f"tuning_objective: distance must be 'sum' or 'mean', got {distance!r}.")
    steps = _progress(log.s_track, track_length)
    if not bool(metrics.completed):
        length = track_length
        if length is None or not length > 0:
            length = max(float(np.max(log.s_track, initial=0.0)), 1.0)
        covered = float(np.sum(steps)) if steps.size else 0.0
        # exp keeps the score in (P, 2P] for any forward progress, monotone in the distance.
        return float(incomplete_penalty * (1.0 + math.exp(-max(covered, -10.0 * length) / length)))

    in_lap = np.asarray(log.in_lap, dtype=bool)
    mask = in_lap if in_lap.any() else np.ones_like(in_lap)
    ey = np.abs(np.asarray(log.ey, dtype=float)[mask])
    vx_err = np.abs(np.asarray(log.vx, dtype=float)[mask] - np.asarray(log.vx_ref, float)[mask])
    if ey.size == 0:
        return float(2.0 * incomplete_penalty)
    # Distance between consecutive in-lap steps (the last one's step leaves the lap window).
    lap_steps = steps[mask[:-1] & mask[1:]] if steps.size else steps
    if distance == "sum":
        dist = float(np.sum(lap_steps))
    else:
        dist = float(np.mean(lap_steps)) if lap_steps.size else 0.0
    collision = float(metrics.wall_contact_time_s) + float(metrics.offtrack_time_s)
    value = float(ey.max() + ey.mean() + vx_err.mean() + w_t * collision - w_s * dist)
    if not math.isfinite(value):
        return float(2.0 * incomplete_penalty)
    return value


def _seed_tuple(seeds: int | Iterable[int] | None) -> tuple[int | None, ...]:
    if seeds is None or isinstance(seeds, int | np.integer):
        return (None if seeds is None else int(seeds),)
    out = tuple(int(s) for s in seeds)
    if not out:
        raise ControlError("evaluate_weights needs at least one seed; pass seeds=(0,) for example.")
    return out


def evaluate_weights(
    spec: Any,
    weights: Mapping[str, float],
    seeds: int | Iterable[int] | None = (0,),
    *,
    w_t: float = W_T,
    w_s: float = W_S,
) -> float:
    """The tuning objective of a controller with ``weights``: the mean over seeded laps.

    A module-level function of plain data, so that process pools and Dask can ship it.

    Parameters
    ----------
    spec : LapSpec or sequence of LapSpec
        The lap (track, plan, controller, options); ``weights`` update its own ``weights`` (the
        ones not tuned keep the spec's values, or the controller's defaults). Several specs (one
        per circuit, say) score the weights on all of them: the objective is then the mean over
        specs and seeds, so weights are tuned for circuits in general rather than for one.
    weights : dict
        Controller weights, for the MPCs the fields of ``MPCSettings`` such as ``w_ey``.
    seeds : int or iterable of int
        One lap per seed (the car's per-trial randomness); the objective is their mean.
    w_t, w_s : float
        Weights of the collision time and distance terms (see :func:`tuning_objective`).

    Returns
    -------
    float
        Mean of :func:`tuning_objective`; :data:`FAILED_EVALUATION` for a lap whose simulation
        raised a ``RacingLibError`` (for example a car that diverged).

    Raises
    ------
    ControlError
        The controller cannot be built (unknown name, a weight that is not a field of
        ``MPCSettings``, a negative weight).
    """
    from racing_lib.experiment import make_controller

    if isinstance(spec, (list, tuple)):
        return float(np.mean([evaluate_weights(one, weights, seeds, w_t=w_t, w_s=w_s)
                              for one in spec]))  # fmt: skip
    merged = {**(spec.weights or {}), **{k: float(v) for k, v in weights.items()}}
    lap_spec = dataclasses.replace(spec, weights=merged)
    return _mean_objective(lap_spec, lambda: make_controller(lap_spec), seeds, w_t, w_s)


def _mean_objective(
    spec: Any, build_controller: Callable[[], Any], seeds: Any, w_t: float, w_s: float
) -> float:
    """Mean tuning objective over seeded laps of ``spec``, one new controller per lap.

    A lap whose simulation raises a RacingLibError scores :data:`FAILED_EVALUATION`.
    """
    from racing_lib.experiment import make_car, run_lap

    length = float(spec.track.length)
    values = []
    for seed in _seed_tuple(seeds):
        # Built outside the try: a controller that cannot be built (unknown name, bad weight) is
        # a mistake to report, not a bad candidate.
        car, ctrl = make_car(spec), build_controller()
        try:
            res = run_lap(car, ctrl, spec.trajectory, track=spec.track, seed=seed)
        except RacingLibError:
            values.append(FAILED_EVALUATION)
            continue
        values.append(tuning_objective(res.log, res.metrics, w_t, w_s, track_length=length))
    return float(np.mean(values))


def _check_fields(values: Mapping[str, float], settings_class: type) -> None:
    known = {f.name for f in dataclasses.fields(settings_class)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ControlError(
            f"unknown {settings_class.__name__} field(s) {', '.join(map(repr, unknown))}; "
            f"tune fields of it such as {', '.join(sorted(known)[:6])}."
        )


def evaluate_nominal_gains(
    spec: Any,
    gains: Mapping[str, float],
    seeds: int | Iterable[int] | None = (0,),
    *,
    w_t: float = W_T,
    w_s: float = W_S,
) -> float:
    """Like :func:`evaluate_weights` for the nominal controller, whose "weights" are its gains.

    ``gains`` are fields of :class:`~racing_lib.control.nominal.NominalSettings` (for example
    ``lookahead_time``, ``kp``); the others keep their defaults. ``spec.controller`` is ignored.
    """
    from racing_lib.control.nominal import NominalController, NominalSettings

    _check_fields(gains, NominalSettings)
    settings = NominalSettings(**{k: float(v) for k, v in gains.items()})
    return _mean_objective(
        spec, lambda: NominalController.from_trajectory(spec.trajectory, settings), seeds, w_t, w_s
    )


# --------------------------------------------------------------------------------------------------
# Search space and settings


@dataclass(frozen=True)
class SearchSpace:
    """Positive parameters searched by CMA-ES in log10 space, inside a box.

    Weights of a quadratic cost matter by their ratios, over orders of magnitude: searching
    log10(w) makes a step of 0.5 mean "about three times larger" for every weight alike.

    Attributes
    ----------
    names : tuple of str
        Parameter names (the keys of the dicts given to the evaluation function).
    initial : tuple of float
        Starting values (the CMA-ES mean at generation 0), in the parameters' own units, > 0.
    lower, upper : tuple of float
        The box, in the parameters' own units, 0 < lower <= initial <= upper.
    """

    names: tuple[str, ...]
    initial: tuple[float, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def __post_init__(self) -> None:
        n = len(self.names)
        if n == 0 or len(set(self.names)) != n:
            raise ControlError(
                f"SearchSpace needs at least one parameter and unique names, got {self.names}."
            )
        for attr in ("initial", "lower", "upper"):
            if len(getattr(self, attr)) != n:
                raise ControlError(
                    f"SearchSpace.{attr} has {len(getattr(self, attr))} values for {n} names; "
                    "give one value per parameter."
                )
        for name, lo, x0, hi in zip(self.names, self.lower, self.initial, self.upper, strict=True):
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= x0 <= hi):
                raise ControlError(
                    f"SearchSpace parameter {name!r}: need 0 < lower <= initial <= upper (finite), "
                    f"got {lo}, {x0}, {hi}; the search is in log10 space, so values must be > 0."
                )
            if not lo < hi:
                raise ControlError(
                    f"SearchSpace parameter {name!r}: the box [{lo}, {hi}] is empty; widen it."
                )

    @classmethod
    def from_bounds(cls, bounds: Mapping[str, tuple[float, float, float]]) -> SearchSpace:
        """Build from ``{name: (lower, initial, upper)}``."""
        names = tuple(bounds)
        return cls(
            names=names,
            initial=tuple(float(bounds[n][1]) for n in names),
            lower=tuple(float(bounds[n][0]) for n in names),
            upper=tuple(float(bounds[n][2]) for n in names),
        )

    @property
    def dimension(self) -> int:
        """Number of parameters."""
        return len(self.names)

    def x0(self) -> np.ndarray:
        """The starting point in log10 space."""
        return np.log10(np.asarray(self.initial, dtype=float))

    def log_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The box in log10 space."""
        return np.log10(np.asarray(self.lower, float)), np.log10(np.asarray(self.upper, float))

    def to_params(self, x: Sequence[float]) -> dict[str, float]:
        """Parameters (own units) of a point ``x`` in log10 space, clipped into the box."""
        lo, hi = self.log_bounds()
        xc = np.clip(np.asarray(x, dtype=float), lo, hi)
        return {name: float(10.0**v) for name, v in zip(self.names, xc, strict=True)}

    def to_x(self, params: Mapping[str, float]) -> np.ndarray:
        """The log10-space point of a parameter dict."""
        return np.log10(np.asarray([float(params[n]) for n in self.names]))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description."""
        return {
            "names": list(self.names),
            "initial": list(self.initial),
            "lower": list(self.lower),
            "upper": list(self.upper),
        }


#: The six MPC weights the paper tunes, by their ``MPCSettings`` field names: v_x, v_y, yaw rate,
#: heading error, lateral error, steering rate.
MPC_WEIGHT_NAMES = ("w_vx", "w_vy", "w_r", "w_epsi", "w_ey", "w_ddelta")
#: Starting values if ``racing_lib.control.mpc`` cannot be imported (its defaults otherwise).
_FALLBACK_MPC_WEIGHTS = {
    "w_vx": 1.0,
    "w_vy": 1.0,
    "w_r": 10.0,
    "w_epsi": 50.0,
    "w_ey": 5.0,
    "w_ddelta": 100.0,
}
#: The box for every MPC weight: four decades either side of 1 .. 100; wide enough that CMA-ES
#: rarely sits on it, narrow enough that no weight dwarfs the others by more than ~1e6 (beyond
#: which the QP is badly conditioned).
MPC_WEIGHT_BOX = (1e-2, 1e4)


def mpc_weight_space(
    initial: Mapping[str, float] | None = None,
    box: tuple[float, float] = MPC_WEIGHT_BOX,
) -> SearchSpace:
    """The search space of the six MPC weights.

    Parameters
    ----------
    initial : dict, optional
        Starting weights (default: the defaults of ``MPCSettings``).
    box : (float, float)
        Lower and upper bound of every weight.
    """
    start = dict(_FALLBACK_MPC_WEIGHTS)
    try:
        from racing_lib.control.mpc import MPCSettings

        defaults = MPCSettings()
        start = {n: float(getattr(defaults, n)) for n in MPC_WEIGHT_NAMES}
    except (ImportError, AttributeError):  # the MPC module is optional for the machinery
        pass
    if initial:
        start.update({k: float(v) for k, v in initial.items()})
    lo, hi = box
    return SearchSpace(
        names=MPC_WEIGHT_NAMES,
        initial=tuple(min(max(start[n], lo), hi) for n in MPC_WEIGHT_NAMES),
        lower=(float(lo),) * len(MPC_WEIGHT_NAMES),
        upper=(float(hi),) * len(MPC_WEIGHT_NAMES),
    )


def nominal_gain_space(initial: Mapping[str, float] | None = None) -> SearchSpace:
    """Search space of the nominal controller's pure-pursuit and speed gains.

    ``lookahead_min`` (m), ``lookahead_time`` (s) and ``kp`` (pedal per m/s), from the defaults
    of ``NominalSettings`` (or ``initial``), each within a factor 10-30 of its default.
    """
    from racing_lib.control.nominal import NominalSettings

    d = NominalSettings()
    start = {"lookahead_min": d.lookahead_min, "lookahead_time": d.lookahead_time, "kp": d.kp}
    if initial:
        start.update({k: float(v) for k, v in initial.items()})
    return SearchSpace.from_bounds(
        {
            "lookahead_min": (0.5, start["lookahead_min"], 30.0),
            "lookahead_time": (0.02, start["lookahead_time"], 3.0),
            "kp": (0.02, start["kp"], 5.0),
        }
    )


@dataclass(frozen=True)
class TuningSettings:
    """Settings of the CMA-ES search.

    Attributes
    ----------
    sigma0 : float
        Initial step size in log10 units (0.5: a typical first step changes a weight by ~3x).
    popsize : int or None
        Candidates per generation (None: pycma's default 4 + floor(3 ln n), 9 for six weights).
    max_generations : int
        Budget in generations (the run also stops at pycma's own criteria, such as ``tolfun``).
    seed : int
        Seed of the CMA-ES sampling (a private ``numpy`` generator; the global one is untouched).
    tolfun : float
        Stop when the objective values of the recent generations differ by less than this.
    tolx : float
        Stop when the search steps are below this, log10 units.
    """

    sigma0: float = 0.5
    popsize: int | None = None
    max_generations: int = 30
    seed: int = 0
    tolfun: float = 1e-4
    tolx: float = 1e-4

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sigma0) and self.sigma0 > 0):
            raise ControlError(
                f"TuningSettings.sigma0 must be > 0 (log10 units), got {self.sigma0}."
            )
        if self.popsize is not None and int(self.popsize) < 2:
            raise ControlError(f"TuningSettings.popsize must be >= 2, got {self.popsize}.")
        if int(self.max_generations) < 0:
            raise ControlError(
                f"TuningSettings.max_generations must be >= 0, got {self.max_generations}."
            )

    @classmethod
    def default(cls, **overrides: Any) -> TuningSettings:
        """The default settings, shrunk in fast mode (6 candidates x 3 generations).

        Fast mode (``RACING_LIB_FAST=1``) only lowers the budget; the algorithm is the same.
        """
        values: dict[str, Any] = {}
        if fast_mode():
            values.update(popsize=6, max_generations=3)
        values.update(overrides)
        return cls(**values)

    def identity(self) -> dict[str, Any]:
        """The settings that must match for a run to be resumed (all but the budget)."""
        out = dataclasses.asdict(self)
        out.pop("max_generations")
        return out


# --------------------------------------------------------------------------------------------------
# Result


@dataclass
class TuningResult:
    """What a tuning run returns.

    Attributes
    ----------
    best_weights : dict
        The best parameters evaluated (own units).
    best_objective : float
        Their objective.
    history : list of dict
        One entry per generation: ``generation``, ``candidates`` (dicts), ``x`` (log10),
        ``objectives``, ``best_objective`` and ``best_weights`` so far, ``sigma``, ``mean``
        (log10), ``elapsed`` (s since the start, across resumes).
    generations : int
        Generations completed.
    evaluations : int
        Evaluation-function calls made.
    success : bool
        At least one finite evaluation below the success threshold (for lap tuning: a completed
        lap) and no error.
    status : str
        Why the run stopped: ``'max_generations'`` or pycma's criteria (``'tolfun'``, ...).
    elapsed : float
        Wall time, s (summed over resumed parts).
    """

    best_weights: dict[str, float]
    best_objective: float
    history: list[dict[str, Any]] = field(repr=False)
    generations: int
    evaluations: int
    success: bool
    status: str
    elapsed: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (non-finite numbers become None)."""
        return jsonable(dataclasses.asdict(self))


# --------------------------------------------------------------------------------------------------
# The generic CMA-ES machinery


class _Randn:
    """pycma's ``randn`` option backed by a private, picklable ``numpy`` generator.

    pycma draws its samples from the global ``np.random`` unless given a ``randn``; a private
    generator makes runs independent of anything else that uses the global state and travels
    with the pickled optimizer, which is what makes a resumed run identical to a straight one.
    """

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def __call__(self, *shape: int) -> np.ndarray:
        return self.rng.standard_normal(shape)


STATE_FILE = "cma_state.pkl"
HISTORY_FILE = "history.json"
_FORMAT = 1


class CmaTuner:
    """CMA-ES over a :class:`SearchSpace` for an evaluation function ``f(params) -> float``.

    Parameters
    ----------
    evaluate : callable
        ``f(params: dict[str, float]) -> float``, lower is better. Must be deterministic for a
        resumed run to equal a straight one, and picklable (a module-level function or a
        ``functools.partial`` of one) when run through a process pool or Dask.
    space : SearchSpace
        Parameters, starting point and box.
    settings : TuningSettings, optional
        Defaults: :meth:`TuningSettings.default` (fast mode shrinks the budget).
    success_threshold : float
        ``success`` requires the best objective to be below this (lap tuning:
        :data:`INCOMPLETE_PENALTY`, i.e. a completed lap).
    """

    def __init__(
        self,
        evaluate: Callable[[dict[str, float]], float],
        space: SearchSpace,
        settings: TuningSettings | None = None,
        *,
        success_threshold: float = math.inf,
    ) -> None:
        if not callable(evaluate):
            raise ControlError("CmaTuner needs a callable evaluate(params) -> float.")
        self.evaluate = evaluate
        self.space = space
        self.settings = settings or TuningSettings.default()
        self.success_threshold = float(success_threshold)

    # -- CMA-ES set-up ------------------------------------------------------------------------
    def _new_strategy(self):
        import cma

        st = self.settings
        lo, hi = self.space.log_bounds()
        opts: dict[str, Any] = {
            "bounds": [lo.tolist(), hi.tolist()],
            "randn": _Randn(st.seed),
            "seed": float("nan"),  # pycma seeds the global generator otherwise; ours is private
            "verbose": -9,
            "verb_log": 0,
            "verb_disp": 0,
            "tolfun": st.tolfun,
            "tolx": st.tolx,
            "maxiter": math.inf,  # the budget is counted here, so it can grow on resume
        }
        if st.popsize is not None:
            opts["popsize"] = int(st.popsize)
        return cma.CMAEvolutionStrategy(self.space.x0().tolist(), st.sigma0, opts)

    def _identity(self) -> dict[str, Any]:
        return {"space": self.space.to_dict(), "settings": self.settings.identity()}

    # -- checkpoints --------------------------------------------------------------------------
    def _load(self, out_dir: FilePath) -> dict[str, Any] | None:
        path = out_dir / STATE_FILE
        if not path.exists():
            return None
        try:
            # Only ever our own checkpoint, written by _save below (pickle trusts its input).
            state = pickle.loads(path.read_bytes())
        except Exception as exc:  # a foreign or damaged file
            raise ControlError(
                f"cannot read the tuning checkpoint {path} ({exc}); delete it or pass "
                "resume=False to start afresh."
            ) from exc
        if state.get("format") != _FORMAT or state.get("identity") != self._identity():
            raise ControlError(
                f"the checkpoint in {out_dir} belongs to a tuning run with another search space "
                "or other settings (only max_generations may change on resume); use another "
                "out_dir, or resume=False to overwrite it."
            )
        return state

    def _save(self, out_dir: FilePath, state: dict[str, Any], status: str) -> None:
        # The pickle is the one source of truth for resuming (one atomic write: optimizer,
        # history and counters always agree); the JSON next to it is for people and plots.
        atomic_write_bytes(out_dir / STATE_FILE, pickle.dumps(state))
        atomic_write_json(
            out_dir / HISTORY_FILE,
            jsonable(
                {
                    "format": _FORMAT,
                    "space": self.space.to_dict(),
                    "settings": dataclasses.asdict(self.settings),
                    "status": status,
                    "generations": state["generation"],
                    "evaluations": state["evaluations"],
                    "best_weights": state["best_params"],
                    "best_objective": state["best_value"],
                    "elapsed": state["elapsed"],
                    "history": state["history"],
                }
            ),
        )

    # -- the loop -----------------------------------------------------------------------------
    def run(
        self,
        *,
        executor: Any = None,
        workers: int | None = 1,
        out_dir: str | os.PathLike[str] | None = None,
        resume: bool = False,
        progress: bool = True,
    ) -> TuningResult:
        """Run CMA-ES until the budget or a stopping criterion.

        Parameters
        ----------
        executor : concurrent.futures.Executor or dask Client, optional
            Where the candidates of a generation are evaluated (``executor.map``). A Dask
            ``distributed.Client`` is accepted and used through ``client.get_executor()``. The
            caller owns it (it is not shut down here).
        workers : int or None
            Without ``executor``: 1 evaluates serially in this process, N > 1 in a
            ``ProcessPoolExecutor`` of N processes made for this run, None one per CPU.
        out_dir : path, optional
            Folder for the checkpoint (``cma_state.pkl``) and the history (``history.json``),
            both rewritten atomically after every generation.
        resume : bool
            Continue from the checkpoint in ``out_dir`` if there is one (it must come from the
            same space and settings; ``max_generations`` may differ). The result equals that of
            an uninterrupted run.
        progress : bool
            Show a progress bar over the generations.

        Returns
        -------
        TuningResult
        """
        out = FilePath(out_dir) if out_dir is not None else None
        if resume and out is None:
            raise ControlError("resume=True needs out_dir, the folder of the run to continue.")
        state = self._load(out) if (resume and out is not None) else None
        if state is None:
            state = {
                "format": _FORMAT,
                "identity": self._identity(),
                "es": self._new_strategy(),
                "generation": 0,
                "evaluations": 0,
                "history": [],
                "best_params": None,
                "best_value": math.inf,
                "elapsed": 0.0,
                "status": "",
            }
        es = state["es"]
        max_gen = int(self.settings.max_generations)

        own_pool = None
        if executor is None and (workers is None or workers > 1):
            own_pool = ProcessPoolExecutor(max_workers=workers)
            executor = own_pool
        elif executor is not None and not isinstance(executor, Executor):
            if hasattr(executor, "get_executor"):  # a dask.distributed Client
                executor = executor.get_executor()
            elif not hasattr(executor, "map"):
                raise ControlError(
                    f"executor must be a concurrent.futures.Executor or a Dask Client, got "
                    f"{type(executor).__name__}."
                )

        from tqdm.auto import tqdm

        bar = tqdm(
            total=max_gen,
            initial=min(state["generation"], max_gen),
            disable=not progress,
            desc="CMA-ES",
            unit="gen",
            leave=False,
        )
        t_run = time.perf_counter()
        elapsed0 = float(state["elapsed"])
        status = state.get("status") or ""
        try:
            while True:
                if state["generation"] >= max_gen:
                    status = "max_generations"
                    break
                stop = es.stop()
                if stop:
                    status = ",".join(sorted(str(k) for k in stop))
                    break
                xs = es.ask()
                params = [self.space.to_params(x) for x in xs]
                if executor is None:
                    raw = [self.evaluate(p) for p in params]
                else:
                    raw = list(executor.map(self.evaluate, params))
                values = [float(v) if math.isfinite(float(v)) else NONFINITE_VALUE for v in raw]
                es.tell(xs, values)

                gen = state["generation"] + 1
                i_best = int(np.argmin(values))
                if values[i_best] < state["best_value"]:
                    state["best_value"] = values[i_best]
                    state["best_params"] = params[i_best]
                state["generation"] = gen
                state["evaluations"] += len(values)
                state["elapsed"] = elapsed0 + time.perf_counter() - t_run
                state["history"].append(
                    {
                        "generation": gen,
                        "candidates": params,
                        "x": [np.asarray(x, float).tolist() for x in xs],
                        "objectives": [float(v) for v in raw],
                        "best_objective": state["best_value"],
                        "best_weights": state["best_params"],
                        "sigma": float(es.sigma),
                        "mean": np.asarray(es.mean, float).tolist(),
                        "elapsed": state["elapsed"],
                    }
                )
                state["status"] = "running"
                if out is not None:
                    self._save(out, state, "running")
                bar.update(1)
                bar.set_postfix(best=f"{state['best_value']:.4g}")
        finally:
            bar.close()
            if own_pool is not None:
                own_pool.shutdown(cancel_futures=True)

        state["status"] = status
        state["elapsed"] = elapsed0 + time.perf_counter() - t_run
        if out is not None:
            self._save(out, state, status)
        best = state["best_params"] or self.space.to_params(self.space.x0())
        best_value = float(state["best_value"])
        return TuningResult(
            best_weights=dict(best),
            best_objective=best_value,
            history=state["history"],
            generations=int(state["generation"]),
            evaluations=int(state["evaluations"]),
            success=bool(math.isfinite(best_value) and best_value < self.success_threshold),
            status=status,
            elapsed=float(state["elapsed"]),
        )


def tune(
    evaluate: Callable[[dict[str, float]], float],
    space: SearchSpace,
    settings: TuningSettings | None = None,
    *,
    executor: Any = None,
    workers: int | None = 1,
    out_dir: str | os.PathLike[str] | None = None,
    resume: bool = False,
    progress: bool = True,
    success_threshold: float = math.inf,
) -> TuningResult:
    """Minimize ``evaluate(params)`` over ``space`` with CMA-ES (see :meth:`CmaTuner.run`)."""
    tuner = CmaTuner(evaluate, space, settings, success_threshold=success_threshold)
    return tuner.run(
        executor=executor, workers=workers, out_dir=out_dir, resume=resume, progress=progress
    )


# --------------------------------------------------------------------------------------------------
# The racing layer


def tune_weights(
    spec: Any,
    seeds: int | Iterable[int] = (0,),
    *,
    space: SearchSpace | None = None,
    settings: TuningSettings | None = None,
    evaluator: Callable[..., float] = evaluate_weights,
    w_t: float = W_T,
    w_s: float = W_S,
    executor: Any = None,
    workers: int | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    resume: bool = False,
    progress: bool = True,
) -> TuningResult:
    """Tune the MPC weights of a lap specification with CMA-ES (the paper's procedure).

    Parameters
    ----------
    spec : LapSpec
        Track, plan, controller (``"coupled-mpc"`` or ``"decoupled-mpc"``) and options.
    seeds : int or iterable of int
        Seeds of the laps each candidate is scored on (the objective is their mean).
    space : SearchSpace, optional
        Default :func:`mpc_weight_space` (the six weights, from the MPC's defaults).
    settings : TuningSettings, optional
        Default :meth:`TuningSettings.default`.
    evaluator : callable
        Module-level ``f(spec, params, seeds, w_t=, w_s=) -> float``; default
        :func:`evaluate_weights`.
    w_t, w_s : float
        Weights of the objective's collision and distance terms.
    executor, workers, out_dir, resume, progress
        As for :meth:`CmaTuner.run`; here ``workers=None`` (default) means one process per CPU.

    Returns
    -------
    TuningResult
        ``success`` means the best candidate completed its laps.
    """
    import functools

    f = functools.partial(evaluator, spec, seeds=_seed_tuple(seeds), w_t=w_t, w_s=w_s)
    return tune(
        f,
        space or mpc_weight_space(),
        settings,
        executor=executor,
        workers=workers,
        out_dir=out_dir,
        resume=resume,
        progress=progress,
        success_threshold=INCOMPLETE_PENALTY,
    )


def tune_nominal_gains(spec: Any, seeds: int | Iterable[int] = (0,), **kwargs: Any) -> TuningResult:
    """:func:`tune_weights` for the nominal controller's gains (:func:`nominal_gain_space`)."""
    kwargs.setdefault("space", nominal_gain_space())
    return tune_weights(spec, seeds, evaluator=evaluate_nominal_gains, **kwargs)


# --------------------------------------------------------------------------------------------------
# Tuned weights shipped with the package

#: The configurations of the paper's ablation table for which weights are tuned: the plan
#: (``method`` and model ``options``) and the controller.
TUNING_CONFIGS: dict[str, dict[str, Any]] = {
    "main": {"method": "time-optimal", "options": {}, "controller": "coupled-mpc"},
    "no-drag": {"method": "time-optimal", "options": {"drag": False}, "controller": "coupled-mpc"},
    "no-longitudinal-weight-transfer": {
        "method": "time-optimal",
        "options": {"longitudinal_weight_transfer": False},
        "controller": "coupled-mpc",
    },
    "lateral-weight-transfer": {
        "method": "time-optimal",
        "options": {"lateral_weight_transfer": True},
        "controller": "coupled-mpc",
    },
    "curvature-plan": {"method": "curvature", "options": {}, "controller": "coupled-mpc"},
    "decoupled": {"method": "time-optimal", "options": {}, "controller": "decoupled-mpc"},
    "no-smooth-transition": {
        "method": "time-optimal",
        "options": {},
        "controller": "coupled-mpc",
        "smooth_transition": False,
    },
}

TUNED_WEIGHTS_FILE = "tuned_weights.json"


def configuration_name(
    controller: str, method: str, options: Any = None, smooth_transition: bool = True
) -> str | None:
    """The :data:`TUNING_CONFIGS` entry a lap set-up corresponds to, or None if there is none.

    Used to pick the shipped tuned weights that fit a command line's choices.
    """
    opts = {}
    if options is not None:
        default = type(options)()
        opts = {
            f.name: getattr(options, f.name)
            for f in dataclasses.fields(options)
            if getattr(options, f.name) != getattr(default, f.name)
        }
    for name, cfg in TUNING_CONFIGS.items():
        if (
            cfg["controller"] == controller
            and cfg["method"] == method
            and cfg["options"] == opts
            and cfg.get("smooth_transition", True) == smooth_transition
        ):
            return name
    return None


def _read_tuned_file() -> dict[str, Any]:
    try:
        text = resources.files("racing_lib").joinpath("data", TUNED_WEIGHTS_FILE).read_text()
    except (FileNotFoundError, OSError):
        return {}
    data = json.loads(text)
    return data.get("configs", {}) if isinstance(data, dict) else {}


def _start_label(initial: str | Mapping[str, float] | None) -> str:
    """Where a tuning run started, for the shipped file."""
    if initial is None:
        return "defaults"
    return f"tuned '{initial}'" if isinstance(initial, str) else "given weights"


def history_summary(history: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Condense a tuning history to what is plotted and shipped, one dict per generation.

    Parameters
    ----------
    history : sequence of dict
        ``TuningResult.history`` (or ``tune(...).history``): per generation the objectives of
        every candidate, the best so far, the step size and the elapsed time.

    Returns
    -------
    list of dict
        ``generation``, ``best_objective`` (best so far), ``median_objective`` (of that
        generation's candidates), ``sigma`` (step size, log10 units) and ``elapsed_s`` (s), the
        same fields as :func:`tuning_history`.
    """
    return [
        {
            "generation": int(h["generation"]),
            "best_objective": float(h["best_objective"]),
            "median_objective": float(np.median(h["objectives"])),
            "sigma": float(h["sigma"]),
            "elapsed_s": float(h["elapsed"]),
        }
        for h in history
    ]


def tuning_history(config: str = "main") -> list[dict[str, float]]:
    """The convergence history of the shipped tuning run of ``config``.

    Returns
    -------
    list of dict
        One entry per CMA-ES generation with ``generation``, ``best_objective`` (best so far),
        ``median_objective`` (of that generation's candidates), ``sigma`` (step size, log10
        units) and ``elapsed_s`` (s); empty when no history is shipped for ``config``.
    """
    entry = _read_tuned_file().get(config) or {}
    return [dict(h) for h in entry.get("history", [])]


def tuned_configurations() -> list[str]:
    """Names of the configurations with tuned weights shipped in ``racing_lib/data``."""
    return sorted(_read_tuned_file())


def tuned_weights(config: str = "main") -> dict[str, float] | None:
    """The MPC weights tuned for a configuration, as shipped with the package.

    Parameters
    ----------
    config : str
        A name of :data:`TUNING_CONFIGS` (``'main'``, ``'decoupled'``, ``'no-smooth-transition'``,
        ...).

    Returns
    -------
    dict or None
        ``{'w_vx': ..., ...}`` to pass as ``LapSpec.weights``, or None when no tuned weights are
        shipped for ``config`` (the MPC then uses its defaults).
    """
    entry = _read_tuned_file().get(config)
    if not entry:
        return None
    return {str(k): float(v) for k, v in entry["weights"].items()}


def _config(config: str) -> dict[str, Any]:
    if config not in TUNING_CONFIGS:
        raise ControlError(
            f"unknown tuning configuration {config!r}; choose one of {', '.join(TUNING_CONFIGS)}."
        )
    return TUNING_CONFIGS[config]


def config_plan(config: str, track: Any, params: Any = None, **plan_kwargs: Any) -> Any:
    """The plan of a configuration of :data:`TUNING_CONFIGS`: its method and model options.

    About 20 s for the time-optimal planner on the expressway.

    Parameters
    ----------
    config : str
        A name of :data:`TUNING_CONFIGS`.
    track : Track
        The track.
    params : ModelParams, optional
        Planning parameters (default: the identified set,
        ``racing_lib.model.identified.identified_params``).
    **plan_kwargs
        Passed on to :func:`racing_lib.planning.plan`.

    Returns
    -------
    PlanResult
        A converged plan.

    Raises
    ------
    ControlError
        Unknown configuration, or a plan that did not converge.
    """
    from racing_lib.model import ModelOptions
    from racing_lib.model.identified import identified_params
    from racing_lib.planning import plan

    cfg = _config(config)
    if params is None:
        params = identified_params()
    options = ModelOptions(**cfg["options"])
    planned = plan(track, method=cfg["method"], params=params, options=options, **plan_kwargs)
    if not planned.success:
        raise ControlError(
            f"the {cfg['method']} plan of configuration {config!r} failed ({planned.status}); "
            "tune on a plan that converged (see racing_lib.planning.plan)."
        )
    return planned


def config_spec(
    config: str,
    track: Any,
    params: Any = None,
    *,
    trajectory: Any = None,
    weights: dict[str, float] | None = None,
    **plan_kwargs: Any,
) -> Any:
    """The :class:`~racing_lib.experiment.LapSpec` of a configuration of :data:`TUNING_CONFIGS`.

    Plans ``track`` with :func:`config_plan` unless a ``trajectory`` is given.

    Parameters
    ----------
    config : str
        A name of :data:`TUNING_CONFIGS`.
    track : Track
        The track.
    params : ModelParams, optional
        Planning parameters (default: the identified set,
        ``racing_lib.model.identified.identified_params``).
    trajectory : Trajectory, optional
        A plan already made for this configuration (for example loaded from a cache): no planning.
    weights : dict, optional
        MPC weights of the spec (default: the MPC's defaults).
    **plan_kwargs
        Passed on to :func:`racing_lib.planning.plan`.
    """
    from racing_lib.experiment import LapSpec
    from racing_lib.model import ModelOptions

    cfg = _config(config)
    if trajectory is None:
        trajectory = config_plan(config, track, params, **plan_kwargs).trajectory
    return LapSpec(
        track=track,
        trajectory=trajectory,
        controller=cfg["controller"],
        smooth_transition=bool(cfg.get("smooth_transition", True)),
        options=ModelOptions(**cfg["options"]),
        weights=weights,
    )


def main_tuning_tracks() -> list[Any]:
    """The circuits the shipped weights of ``'main'`` are tuned on, all made by the package.

    The expressway (walls, the paper's main track), the shortcut (open, sharper corners) and a
    figure-eight with a bridge (walls, two slow lobes): weights that score well on the mean of
    the three are not tuned to one layout, and every real circuit stays unseen for testing them
    (``benchmarks/bench_circuits.py``).
    """
    from racing_lib.tracks import figure_eight_track, load_track

    return [load_track("expressway"), load_track("shortcut"), figure_eight_track(80.0, 12.0)]


def generate_tuned_weights(
    configs: Iterable[str] = ("main",),
    *,
    track: Any = "expressway",
    seeds: int | Iterable[int] = (0,),
    settings: TuningSettings | None = None,
    executor: Any = None,
    workers: int | None = None,
    out: str | os.PathLike[str] | None = None,
    work_dir: str | os.PathLike[str] | None = None,
    progress: bool = True,
    initial: str | Mapping[str, float] | None = None,
) -> dict[str, TuningResult]:
    """Tune the weights of configurations and write them to the shipped JSON file.

    Entries for other configurations already in the file are kept. Run this (for example from a
    maintainer's shell) after a change to the MPC or the simulated car, then commit the file.

    Parameters
    ----------
    configs : iterable of str
        Names of :data:`TUNING_CONFIGS`.
    track : str, Track or sequence of them
        The track tuned on (the paper tunes on its main track), or several (names, CSV files,
        Tracks): the objective is then their mean, for weights that carry over to other circuits.
    seeds : int or iterable of int
        Seeds of the laps scoring every candidate.
    settings : TuningSettings, optional
        CMA-ES settings (default :meth:`TuningSettings.default`).
    executor, workers
        Where laps run (see :meth:`CmaTuner.run`).
    out : path, optional
        The JSON file written (default: ``racing_lib/data/tuned_weights.json`` of the source
        tree this module was imported from).
    work_dir : path, optional
        Folder for the per-configuration checkpoints, so that an interrupted generation resumes.
    progress : bool
        Progress bars.
    initial : str or dict, optional
        Where CMA-ES starts: the MPC's default weights (None), the shipped tuned weights of another
        configuration (its name, e.g. ``'main'``: the ablations start from the main result, so a
        shorter budget suffices), or explicit weights.
    """
    from racing_lib.geometry import Track
    from racing_lib.tracks import load_track

    start = tuned_weights(initial) if isinstance(initial, str) else initial
    if isinstance(initial, str) and start is None:
        raise ControlError(
            f"no tuned weights shipped for {initial!r} to start from; tune it first or pass "
            "initial=None."
        )

    track_list = list(track) if isinstance(track, (list, tuple)) else [track]
    tracks = [t if isinstance(t, Track) else load_track(str(t)) for t in track_list]
    target = (
        FilePath(out)
        if out is not None
        else FilePath(__file__).parent / "data" / TUNED_WEIGHTS_FILE
    )
    data: dict[str, Any] = {"format": _FORMAT, "configs": {}}
    if target.exists():
        data = json.loads(target.read_text())
        data.setdefault("configs", {})
    results: dict[str, TuningResult] = {}
    for name in configs:
        specs = [config_spec(name, trk) for trk in tracks]
        spec = specs[0] if len(specs) == 1 else specs
        res = tune_weights(
            spec,
            seeds,
            space=mpc_weight_space(start),
            settings=settings,
            executor=executor,
            workers=workers,
            out_dir=None if work_dir is None else FilePath(work_dir) / name,
            resume=work_dir is not None,
            progress=progress,
        )
        results[name] = res
        # The defaults' score on the same laps, so a reader sees what tuning bought.
        at_defaults = evaluate_weights(spec, {}, _seed_tuple(seeds))
        data["configs"][name] = jsonable(
            {
                "weights": res.best_weights,
                "objective": res.best_objective,
                "objective_at_defaults": at_defaults,
                "success": res.success,
                "track": tracks[0].name if len(tracks) == 1 else [t.name for t in tracks],
                "plan": TUNING_CONFIGS[name]["method"],
                "planned_lap_time_s": float(specs[0].trajectory.lap_time)
                if len(specs) == 1
                else [float(one.trajectory.lap_time) for one in specs],
                "model_params": "identified",
                "options": TUNING_CONFIGS[name]["options"],
                "controller": specs[0].controller,
                "smooth_transition": specs[0].smooth_transition,
                "seeds": list(_seed_tuple(seeds)),
                "generations": res.generations,
                "evaluations": res.evaluations,
                "started_from": _start_label(initial),
                "history": history_summary(res.history),
                "settings": dataclasses.asdict(settings or TuningSettings.default()),
                "created_utc": time.strftime("%Y-%m-%dT%H:%MZ", time.gmtime()),
            }
        )
        atomic_write_json(target, data)  # after each configuration: a crash keeps the others
    return results


__all__ = [
    "FAILED_EVALUATION",
    "INCOMPLETE_PENALTY",
    "MPC_WEIGHT_NAMES",
    "TUNING_CONFIGS",
    "W_S",
    "W_T",
    "CmaTuner",
    "SearchSpace",
    "TuningResult",
    "TuningSettings",
    "config_plan",
    "config_spec",
    "evaluate_nominal_gains",
    "evaluate_weights",
    "generate_tuned_weights",
    "main_tuning_tracks",
    "history_summary",
    "mpc_weight_space",
    "nominal_gain_space",
    "tune",
    "tune_nominal_gains",
    "tune_weights",
    "tuned_configurations",
    "tuned_weights",
    "tuning_history",
    "tuning_objective",
]
