"""Running the rows: plans made or reused, seeded laps in worker processes, one file per row."""

from __future__ import annotations

import functools
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path as FilePath
from typing import Any

import numpy as np

from racing_lib.config import fast_mode
from racing_lib.control.mpc import MPCSettings
from racing_lib.errors import ControlError, PlanningError, RacingLibError
from racing_lib.experiments.ablation.keys import (
    KeyInputs,
    code_digests,
    compact_json,
    digest,
    plan_key_inputs,
    plan_options,
    row_key_inputs,
)
from racing_lib.experiments.ablation.profiles import (
    PROFILE_SPACING,
    closed_loop_profile,
    plan_profile,
    profile_grid,
    rounded,
)
from racing_lib.experiments.ablation.rows import (
    AblationRow,
    TableRow,
    default_trials,
    row_summary,
    select_rows,
)
from racing_lib.experiments.configs import (
    TUNING_CONFIGS,
    config_plan,
    config_spec,
    tuned_weights,
)
from racing_lib.experiments.lap import (
    LapMetrics,
    LapSpec,
    drive_lap,
    run_trials,
    summarize,
)
from racing_lib.experiments.tuning import MPC_WEIGHT_NAMES
from racing_lib.geometry import Track
from racing_lib.io import atomic_write_text, jsonable
from racing_lib.planning.best_lap import BestLapSettings, solve_best_lap
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tracks import load_track

__all__ = ["DEFAULT_OUT", "resolve_tracks", "run_ablation"]
#: The cache folder used when none is given, relative to the working directory.
DEFAULT_OUT = "runs/ablation"


# --------------------------------------------------------------------------------------------------
# Plans (cached as plan CSVs: the best lap takes minutes)


def _make_plan(row: AblationRow, track: Track, spacing: float | None) -> tuple[Trajectory, dict]:
    """Plan a row (no cache): its configuration's planner, or the best possible lap."""
    if row.best_lap:
        settings = BestLapSettings() if spacing is None else BestLapSettings(spacing=spacing)
        tic = time.perf_counter()
        res = solve_best_lap(track, settings=settings)
        elapsed = time.perf_counter() - tic
        if res.trajectory is None:
            raise PlanningError(
                f"the best possible lap of {track.name!r} gave no trajectory ({res.status}); "
                "try another grid spacing (BestLapSettings.spacing)."
            )
        return res.trajectory, {
            "status": res.status,
            "iterations": res.iterations,
            "solve_time_s": elapsed,
            "success": res.success,
        }
    kwargs = {} if spacing is None else {"spacing": float(spacing)}
    res = config_plan(row.config, track, **kwargs)
    return res.trajectory, {
        "status": res.status,
        "iterations": res.iterations,
        "solve_time_s": res.solve_time,
        "success": res.success,
    }


def _get_plan(
    row: AblationRow,
    track: Track,
    spacing: float | None,
    folder: FilePath | None,
    memo: dict[str, tuple[Trajectory, dict]],
    log: Callable[[str], None],
    code: Mapping[str, str],
) -> tuple[Trajectory, dict[str, Any]]:
    """A row's plan from the memo, the cache folder, or the planner (then cached)."""
    inputs = plan_key_inputs(row, track, spacing, code)
    key = digest(inputs)
    if key in memo:
        return memo[key]
    base = f"{track.name}-{inputs['method']}-{key}"
    csv = folder / "plans" / f"{base}.csv" if folder is not None else None
    meta = csv.with_suffix(".json") if csv is not None else None
    info: dict[str, Any] | None = None
    # The sidecar JSON is written after the CSV: its presence marks a complete cached plan.
    if meta is not None and meta.exists() and csv is not None and csv.exists():
        try:
            info = json.loads(meta.read_text())
            traj = Trajectory.load_csv(csv, track=track)
            info["reused"] = True
        except (json.JSONDecodeError, RacingLibError):
            info = None  # damaged by hand: plan again
    if info is None:
        log(f"planning {row.name} on {track.name}: {inputs['method']} ...")
        traj, found = _make_plan(row, track, spacing)
        info = {
            "method": inputs["method"],
            "options": plan_options(row),
            "spacing_m": spacing,
            "key": key,
            **found,
        }
        if csv is not None and meta is not None:
            traj.save_csv(csv)
            atomic_write_text(meta, json.dumps(jsonable(info), indent=2, sort_keys=True) + "\n")
            # Drive the plan as stored, so that a rerun from the cache drives the same numbers.
            traj = Trajectory.load_csv(csv, track=track)
        info["reused"] = False
        log(f"  planned lap {traj.lap_time:.2f} s in {info['solve_time_s']:.1f} s")
    if csv is not None:
        info["file"] = str(csv)
    memo[key] = (traj, info)
    return traj, info


# --------------------------------------------------------------------------------------------------
# One trial (runs in worker processes) and the profiles


@dataclass(frozen=True)
class _TrialOutcome:
    """What a trial sends back: metrics, per-step errors for the pooled statistics, a profile."""

    metrics: LapMetrics
    vx_abs_err: np.ndarray  # |v_x - v_x,ref| at the in-lap control steps, m/s
    ey_abs: np.ndarray  # |e_y| at the in-lap control steps, m
    solve_ms: np.ndarray  # controller time of every step, ms
    wall_time_s: float  # wall time of the simulated lap, s
    profile: dict[str, Any] | None


def _trial(spec: LapSpec, seed: int, profile_seed: int | None = None) -> _TrialOutcome:
    """One seeded lap of ``spec`` (module level, so process pools can ship it)."""
    tic = time.perf_counter()
    res = drive_lap(spec, seed=seed)
    wall = time.perf_counter() - tic
    log = res.log
    # The steps between the two line crossings, as in the lap metrics.
    lap = log.lap_steps
    profile = None
    if seed == profile_seed:
        profile = {"seed": seed, "completed": res.metrics.completed}
        profile["closed_loop"] = closed_loop_profile(log, spec.track)
    return _TrialOutcome(
        metrics=res.metrics,
        vx_abs_err=np.abs(log.vx[lap] - log.vx_ref[lap]).astype(np.float32),
        ey_abs=np.abs(log.ey[lap]).astype(np.float32),
        solve_ms=np.asarray(log.solve_ms, dtype=np.float32),
        wall_time_s=wall,
        profile=profile,
    )


def _pooled(values: Sequence[np.ndarray]) -> tuple[float, float, float]:
    """Mean, std and max of |error| over the control steps of all trials (the paper's format)."""
    arr = np.concatenate([np.asarray(v, dtype=float) for v in values]) if values else np.zeros(0)
    if arr.size == 0:
        return math.nan, math.nan, math.nan
    return float(arr.mean()), float(arr.std()), float(arr.max())


def _effective_weights(weights: dict[str, float] | None) -> dict[str, float]:
    """The MPC weights actually used: the given ones over the MPC's defaults."""
    defaults = MPCSettings()
    return {
        **{n: float(getattr(defaults, n)) for n in MPC_WEIGHT_NAMES},
        **{k: float(v) for k, v in (weights or {}).items()},
    }


def _row_result(
    row: AblationRow,
    track: Track,
    trajectory: Trajectory,
    plan_info: dict[str, Any],
    weights: dict[str, float] | None,
    seeds: Sequence[int],
    outcomes: Sequence[_TrialOutcome],
    key: str,
    key_inputs: KeyInputs,
    wall_time: float,
) -> TableRow:
    """The JSON row of the table from a row's trials."""
    cfg = TUNING_CONFIGS[row.config]
    metrics = [o.metrics for o in outcomes]
    n = len(metrics)
    vx_mean, vx_std, vx_max = _pooled([o.vx_abs_err for o in outcomes])
    ey_mean, ey_std, ey_max = _pooled([o.ey_abs for o in outcomes])
    solve = np.concatenate([o.solve_ms for o in outcomes]).astype(float)
    stats: dict[str, float] = {}
    for m in metrics:
        for name, value in m.controller_stats.items():
            stats[name] = stats.get(name, 0.0) + float(value)
    fallbacks = sum(v for k, v in stats.items() if k.startswith("fallback"))
    walls = sum(m.wall_contacts for m in metrics)
    wall_time_contact = sum(m.wall_contact_time_s for m in metrics)
    profile = next((o.profile for o in outcomes if o.profile is not None), None)
    if profile is not None:
        profile = {
            "spacing_m": PROFILE_SPACING,
            "s_m": rounded(profile_grid(track), 1),
            **profile,
            "plan": plan_profile(trajectory, track),
        }
    row_dict: TableRow = {
        "name": row.name,
        "label": row.label,
        "table": row.table,
        "track": track.name,
        "track_checksum": track.checksum(),
        "boundary": track.boundary,
        "config": row.config,
        "controller": cfg["controller"],
        "smooth_transition": bool(cfg.get("smooth_transition", True)),
        "mpc_options": dict(cfg["options"]),
        "plan": {k: v for k, v in plan_info.items() if k not in ("reused", "file")},
        "planned_lap_time_s": float(trajectory.lap_time),
        "planning_time_s": float(plan_info.get("solve_time_s", math.nan)),
        "weights_source": "tuned" if weights else "defaults",
        "weights": _effective_weights(weights),
        "seeds": list(seeds),
        "trials": n,
        **summarize(metrics),
        "vx_mae_mps": vx_mean,
        "vx_mae_std_mps": vx_std,
        "vx_max_err_mps": vx_max,
        "ey_mae_m": ey_mean,
        "ey_mae_std_m": ey_std,
        "ey_max_m": ey_max,
        "wall_contacts": int(walls),
        "wall_contacts_per_lap": walls / n if n else math.nan,
        "wall_contact_time_s": wall_time_contact,
        "wall_contact_time_per_lap_s": wall_time_contact / n if n else math.nan,
        "offtrack_time_s": sum(m.offtrack_time_s for m in metrics),
        "qp_failures": int(stats.get("qp_failures", 0)),
        "qp_fallbacks": int(fallbacks),
        "controller_stats": stats,
        "solve_time_ms_median": float(np.median(solve)) if solve.size else math.nan,
        "solve_time_ms_p99": float(np.percentile(solve, 99)) if solve.size else math.nan,
        "lap_wall_time_mean_s": float(np.mean([o.wall_time_s for o in outcomes])),
        "trials_wall_time_s": wall_time,
        "trial_metrics": [m.to_dict() for m in metrics],
        "fast_mode": fast_mode(),
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "key": key,
        "key_inputs": key_inputs,
        "profile": profile,
    }
    return jsonable(row_dict)


# --------------------------------------------------------------------------------------------------
# The runner


def _row_file(folder: FilePath, name: str, key: str) -> FilePath:
    return folder / "rows" / f"{name}-{key}.json"


def _load_row(path: FilePath, key: str) -> TableRow | None:
    """A cached row if ``path`` holds one with this key (None if missing or damaged)."""
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) and data.get("key") == key else None


def resolve_tracks(
    rows: Sequence[AblationRow], tracks: Mapping[str, Track] | None
) -> dict[str, Track]:
    """The tracks of ``rows`` by name: the given ones, the others loaded from the registry."""
    given = dict(tracks or {})
    names = sorted({r.track for r in rows})
    return {name: given[name] if name in given else load_track(name) for name in names}


def _quiet(_message: str) -> None:
    """The default status log: silent (the progress bar says where the run is)."""


def run_ablation(
    rows: Iterable[str] | None = None,
    *,
    track: str | None = None,
    trials: int | None = None,
    seed: int = 0,
    out_dir: str | os.PathLike[str] | None = DEFAULT_OUT,
    executor: Executor | None = None,
    workers: int = 2,
    spacing: float | None = None,
    tracks: Mapping[str, Track] | None = None,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
    on_row: Callable[[TableRow, bool], None] | None = None,
    cached_only: bool = False,
) -> list[TableRow]:
    """Compute rows of the tables (or reuse them from the cache folder).

    Each row is planned once (plans are cached too), then driven for ``trials`` seeded laps
    (seeds ``seed, seed + 1, ...``) through :func:`racing_lib.experiments.lap.run_trials`; the row
    is written to ``out_dir`` as soon as its trials are done, so an interruption (Ctrl-C) keeps
    every finished row, and a rerun reuses every row whose cache key still matches.

    Parameters
    ----------
    rows : iterable of str, optional
        Row names (default: all; see :func:`select_rows`).
    track : str, optional
        Only the rows of this built-in track.
    trials : int, optional
        Seeded laps per row (default :func:`default_trials`: 10, or 2 in fast mode).
    seed : int
        Seed of the first trial.
    out_dir : path or None
        Cache folder (``rows/`` and ``plans/`` inside); None computes without caching.
    executor : Executor, optional
        Where the laps run (a process pool, a Dask client's executor, ...); it is not shut down.
    workers : int
        Without ``executor``: worker processes of the local pool made for this run (started
        only if some row needs computing); 1 or less drives the laps in this process.
    spacing : float, optional
        Node spacing of every plan, m (default: the planners' own, 3 m).
    tracks : mapping of str to Track, optional
        Tracks to use instead of the built-in ones of those names (for example to run the
        table's configurations on your own track).
    progress : bool
        A progress bar over the rows.
    log : callable, optional
        Receives one line of text per stage (planning, driving, reused).
    on_row : callable, optional
        Called as ``on_row(row, reused)`` after each row is finished or reused.
    cached_only : bool
        Only look: return the rows found in ``out_dir`` with a matching key, compute nothing.

    Returns
    -------
    list of TableRow
        One JSON-ready dict per row, in table order: ``name``, ``planned_lap_time_s``,
        ``lap_time_mean_s``, ``lap_time_std_s``, ``lap_time_min_s``, ``completed``,
        ``vx_mae_mps`` / ``vx_mae_std_mps`` / ``vx_max_err_mps`` (mean, std and maximum of
        |v_x - v_x,ref| over the in-lap control steps of all trials, the paper's
        "mean +- std (max)"), the same for ``ey_*`` (m), ``wall_contacts`` (total),
        ``wall_contacts_per_lap``, ``wall_contact_time_s``, ``qp_failures``, ``qp_fallbacks``,
        ``solve_time_ms_median`` / ``_p99`` (controller time per step), the plan (``plan``:
        method, options, status, solve time), ``weights_source`` (``'tuned'``/``'defaults'``)
        and ``weights``, ``seeds``, ``trial_metrics`` (per trial), ``profile`` (the first
        seed's lap and the plan every 10 m of the track centerline) and the cache ``key``.

    Raises
    ------
    TrackError, ControlError
        Unknown track or row (raised before anything is computed).
    PlanningError
        A plan that did not converge.
    """
    selected = select_rows(rows, track)
    n_trials = _checked_trials(trials, spacing)
    seeds = [int(seed) + i for i in range(n_trials)]
    say = log or _quiet
    folder = FilePath(out_dir) if out_dir is not None else None
    track_objs = resolve_tracks(selected, tracks)
    memo: dict[str, tuple[Trajectory, dict]] = {}
    code = code_digests()
    pool = _LapPool(executor, workers)

    from tqdm.auto import tqdm

    results: list[TableRow] = []
    bar = tqdm(
        total=len(selected), desc="ablation", unit="row", disable=not progress or cached_only
    )
    try:
        for row in selected:
            trk = track_objs[row.track]
            bar.set_description(row.name)
            weights = tuned_weights(row.config)
            plan_key = digest(plan_key_inputs(row, trk, spacing, code))
            key_inputs = row_key_inputs(row, trk, plan_key, weights, seeds, code)
            key = digest(key_inputs)
            path = _row_file(folder, row.name, key) if folder is not None else None
            cached = _load_row(path, key) if path is not None else None
            if cached is not None:
                say(f"{row.name}: reused {path}")
                results.append(cached)
                if on_row is not None:
                    on_row(cached, True)
                bar.update(1)
                continue
            if cached_only:
                bar.update(1)
                continue
            traj, plan_info = _get_plan(row, trk, spacing, folder, memo, say, code)
            result = _drive_row(
                row, trk, traj, plan_info, weights, seeds, key, key_inputs, pool, say
            )
            _save_row(result, path, row.name, say)
            results.append(result)
            if on_row is not None:
                on_row(result, False)
            bar.update(1)
    except KeyboardInterrupt:
        if pool.own is not None:
            _stop_workers(pool.own)
        raise
    finally:
        bar.close()
        if pool.own is not None:
            pool.own.shutdown(wait=True, cancel_futures=True)
    return results


def _checked_trials(trials: int | None, spacing: float | None) -> int:
    """The number of seeded laps per row (``trials``, or :func:`default_trials`), checked.

    Raises
    ------
    ControlError
        If fewer than one trial is asked for.
    PlanningError
        If the plan spacing (m) is given and not a positive finite number.
    """
    n_trials = default_trials() if trials is None else int(trials)
    if n_trials < 1:
        raise ControlError(f"trials must be at least 1, got {trials}; the paper uses 10.")
    if spacing is not None and not (math.isfinite(spacing) and spacing > 0):
        raise PlanningError(f"plan spacing must be a positive number of m, got {spacing}.")
    return n_trials


class _LapPool:
    """Where a run's laps go: the caller's executor, this process, or a pool made on first use.

    Parameters
    ----------
    executor : Executor or None
        The caller's executor (never shut down here).
    workers : int
        Without ``executor``: worker processes of the pool made when a row first needs one; 1 or
        less drives the laps in this process.
    """

    def __init__(self, executor: Executor | None, workers: int) -> None:
        self.executor = executor
        self.workers = workers
        #: The pool this run made (and must shut down), once made.
        self.own: ProcessPoolExecutor | None = None

    def get(self) -> Executor | None:
        """The executor for the next row's laps (None: in this process)."""
        if self.executor is not None:
            return self.executor
        if self.workers <= 1:
            return None
        if self.own is None:
            self.own = ProcessPoolExecutor(max_workers=int(self.workers))
        return self.own


def _drive_row(
    row: AblationRow,
    trk: Track,
    traj: Trajectory,
    plan_info: dict,
    weights: dict[str, float] | None,
    seeds: list[int],
    key: str,
    key_inputs: KeyInputs,
    pool: _LapPool,
    say: Callable[[str], None],
) -> TableRow:
    """Drive the seeded trials of one row on its plan and summarize them.

    Parameters
    ----------
    row : AblationRow
        The row.
    trk : Track
        Its track.
    traj : Trajectory
        Its plan.
    plan_info : dict
        What the row's result says of the plan.
    weights : dict of str to float or None
        The controller's weights (None: its defaults).
    seeds : list of int
        One seed per trial.
    key, key_inputs
        The row's cache key and what it was made from.
    pool : _LapPool
        Where the laps run.
    say : callable
        Receives one line of text per stage.

    Returns
    -------
    TableRow
        The row's JSON-ready result (see :func:`run_ablation`).
    """
    spec = config_spec(row.config, trk, trajectory=traj, weights=weights)
    executor = pool.get()
    where = "in this process" if executor is None else "in parallel"
    say(f"{row.name}: {len(seeds)} trials {where} ...")
    tic = time.perf_counter()
    outcomes = run_trials(functools.partial(_trial, spec, profile_seed=seeds[0]), seeds, executor)
    return _row_result(
        row,
        trk,
        traj,
        plan_info,
        weights,
        seeds,
        outcomes,  # type: ignore[arg-type]
        key,
        key_inputs,
        time.perf_counter() - tic,
    )


def _save_row(
    result: TableRow, path: FilePath | None, name: str, say: Callable[[str], None]
) -> None:
    """Write a row's result to its cache file (atomically; ``path`` None: not cached), say so."""
    if path is not None:
        atomic_write_text(path, compact_json(result))
        result_file = str(path)
    else:
        result_file = "not cached"
    say(f"{name}: {row_summary(result)} -> {result_file}")


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """End the laps in progress of our own pool at once (on Ctrl-C).

    Otherwise shutting the pool down waits for the running laps, up to a minute for a car stuck at a
    wall (and the QP solver in the workers catches Ctrl-C itself). The pool has no public way to
    do this before Python 3.14 (``terminate_workers``); without the attribute it just waits.
    """
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        terminate()
        return
    processes = getattr(pool, "_processes", None) or {}
    for proc in list(processes.values()):
        proc.terminate()
