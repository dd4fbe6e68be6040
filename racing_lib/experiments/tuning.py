"""CMA-ES tuning of controller weights over closed-loop laps.

Paper Section "Hyperparameter Optimization"; taught in notebook 06.

The paper tunes the six weights of its MPC cost (v_x, v_y, yaw rate, e_psi, e_y, steering rate)
with CMA-ES, minimizing a score of closed-loop laps (:func:`tuning_objective`). The optimizer is the
generic one of :mod:`racing_lib.optim.cmaes`; this module is the racing layer on top:
:func:`evaluate_weights` (the picklable "weights -> objective" of one lap specification),
:func:`tune_weights` (the MPC weights) and :func:`tune_nominal_gains` (the nominal controller's
gains, the same machinery on a controller that needs no QP). The tuned weights shipped with the
package are in :mod:`racing_lib.experiments.configs`.

Examples
--------
Tuning the MPC weights of one configuration on two worker processes, first the lap to tune on:

>>> from racing_lib.experiments.lap import LapSpec
>>> from racing_lib.planning import plan
>>> from racing_lib.tracks import load_track
>>> track = load_track("expressway")
>>> reference = plan(track, method="time-optimal").trajectory
>>> spec = LapSpec(track=track, trajectory=reference, controller="coupled-mpc")

then the tuning, which drives hundreds of closed-loop laps (minutes, so skipped by the tests):

>>> res = tune_weights(spec, seeds=(0,), workers=2, out_dir="tuning/main")  # doctest: +SKIP
>>> res.best_weights  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor
from typing import TYPE_CHECKING, Any

import numpy as np

from racing_lib.control.mpc import MPCSettings
from racing_lib.control.nominal import NominalController, NominalSettings
from racing_lib.errors import ControlError, RacingLibError
from racing_lib.experiments.lap import (
    LapLog,
    LapMetrics,
    LapSpec,
    make_car,
    make_controller,
    run_lap,
)
from racing_lib.interfaces import Controller
from racing_lib.optim.cmaes import SearchSpace, TuningResult, TuningSettings, tune

if TYPE_CHECKING:
    # Only named in annotations: dask is an optional dependency (racing-lib[distributed]).
    from distributed import Client

__all__ = [
    "FAILED_EVALUATION",
    "INCOMPLETE_PENALTY",
    "MPC_WEIGHT_NAMES",
    "W_S",
    "W_T",
    "evaluate_nominal_gains",
    "evaluate_weights",
    "mpc_weight_space",
    "nominal_gain_space",
    "seed_tuple",
    "tune_nominal_gains",
    "tune_weights",
    "tuning_objective",
]

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
    log: LapLog,
    metrics: LapMetrics,
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

    mask = log.lap_steps
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


def seed_tuple(seeds: int | Iterable[int] | None) -> tuple[int | None, ...]:
    """Seeds as a tuple of ints (one None: the car's per-trial randomness off)."""
    if seeds is None or isinstance(seeds, int | np.integer):
        return (None if seeds is None else int(seeds),)
    out = tuple(int(s) for s in seeds)
    if not out:
        raise ControlError("evaluate_weights needs at least one seed; pass seeds=(0,) for example.")
    return out


def evaluate_weights(
    spec: LapSpec | Sequence[LapSpec],
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
    if isinstance(spec, (list, tuple)):
        return float(np.mean([evaluate_weights(one, weights, seeds, w_t=w_t, w_s=w_s)
                              for one in spec]))  # fmt: skip
    merged = {**(spec.weights or {}), **{k: float(v) for k, v in weights.items()}}
    lap_spec = dataclasses.replace(spec, weights=merged)
    return _mean_objective(lap_spec, lambda: make_controller(lap_spec), seeds, w_t, w_s)


def _mean_objective(
    spec: LapSpec,
    build_controller: Callable[[], Controller],
    seeds: int | Iterable[int] | None,
    w_t: float,
    w_s: float,
) -> float:
    """Mean tuning objective over seeded laps of ``spec``, one new controller per lap.

    A lap whose simulation raises a RacingLibError scores :data:`FAILED_EVALUATION`.
    """
    length = float(spec.track.length)
    values = []
    for seed in seed_tuple(seeds):
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
    spec: LapSpec,
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
    _check_fields(gains, NominalSettings)
    settings = NominalSettings(**{k: float(v) for k, v in gains.items()})
    return _mean_objective(
        spec, lambda: NominalController.from_trajectory(spec.trajectory, settings), seeds, w_t, w_s
    )


#: The six MPC weights the paper tunes, by their ``MPCSettings`` field names: v_x, v_y, yaw rate,
#: heading error, lateral error, steering rate.
MPC_WEIGHT_NAMES = ("w_vx", "w_vy", "w_r", "w_epsi", "w_ey", "w_ddelta")
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
    defaults = MPCSettings()
    start = {n: float(getattr(defaults, n)) for n in MPC_WEIGHT_NAMES}
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


# --------------------------------------------------------------------------------------------------
# The racing layer


def tune_weights(
    spec: LapSpec | Sequence[LapSpec],
    seeds: int | Iterable[int] = (0,),
    *,
    space: SearchSpace | None = None,
    settings: TuningSettings | None = None,
    evaluator: Callable[..., float] = evaluate_weights,
    w_t: float = W_T,
    w_s: float = W_S,
    executor: Executor | Client | None = None,
    workers: int | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    resume: bool = False,
    progress: bool = True,
) -> TuningResult:
    """Tune the MPC weights of a lap specification with CMA-ES (the paper's procedure).

    Parameters
    ----------
    spec : LapSpec or sequence of LapSpec
        Track, plan, controller (``"coupled-mpc"`` or ``"decoupled-mpc"``) and options; several
        specs are scored together (see :func:`evaluate_weights`).
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
        As for :meth:`~racing_lib.optim.cmaes.CmaTuner.run`; here ``workers=None`` (default) means
        one process per CPU.

    Returns
    -------
    TuningResult
        ``success`` means the best candidate completed its laps.
    """
    f = functools.partial(evaluator, spec, seeds=seed_tuple(seeds), w_t=w_t, w_s=w_s)
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


def tune_nominal_gains(
    spec: LapSpec,
    seeds: int | Iterable[int] = (0,),
    # Any: forwarded to tune_weights, whose keywords have different types.
    **kwargs: Any,
) -> TuningResult:
    """:func:`tune_weights` for the nominal controller's gains (:func:`nominal_gain_space`)."""
    kwargs.setdefault("space", nominal_gain_space())
    return tune_weights(spec, seeds, evaluator=evaluate_nominal_gains, **kwargs)
