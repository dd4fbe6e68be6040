"""The paper's Table I and Table II on the simulated car: rows, runner, cache, table (chapter 07).

Every row of the paper's experiments is one configuration of the pipeline, planned once and then
driven for N seeded closed-loop laps (ten, as in the paper):

* Table I, the expressway (walled): the configurations of
  :data:`racing_lib.tuning.TUNING_CONFIGS`, that is ``main`` (time-optimal plan, drag and
  longitudinal weight transfer, coupled MPC, smooth reference transition) and the ablations that
  remove or add one element (``no-drag``, ``no-longitudinal-weight-transfer``,
  ``lateral-weight-transfer``, ``curvature-plan``, ``decoupled``, ``no-smooth-transition``);
* Table I, the sharper open track ``shortcut``: ``shortcut-main`` and
  ``shortcut-lateral-weight-transfer``;
* Table II: ``best-lap``, the coupled MPC (with the ``main`` weights) tracking the best possible
  lap of the expressway (:mod:`racing_lib.planning.best_lap`), our stand-in for the paper's
  human-best recording.

Each row uses the MPC weights tuned for its configuration
(:func:`racing_lib.tuning.tuned_weights`), or the MPC's defaults when none are shipped; the row
records which.

Results are cached in a folder (default ``runs/ablation``): one JSON file per finished row and one
plan CSV per plan, each named by a hash of everything that determines it (track geometry,
configuration, controller, model options and parameters, weights, seeds, fast mode, and the
source code of the modules involved). A rerun reuses every row whose hash matches and recomputes
the others; an interrupted run keeps every row it finished (writes are atomic).

The table of the full run is shipped with the package (:func:`shipped_table`), so that notebook
07 loads it in seconds; :func:`generate_ablation_table` recomputes it.

For the figures, each row keeps a ``profile`` of its first seed's lap and of its plan, sampled every
:data:`PROFILE_SPACING` m of the track centerline (``s_m``, the same grid for every row of a
track, so rows can be overlaid); values are None where the car never got (a lap that stopped):

* ``profile["plan"]``: ``vx_mps`` (planned v_x), ``kappa_radpm`` (curvature of the planned line,
  1/m), ``delta_rad`` (planned steering angle), ``n_m`` (offset of the line from the centerline,
  m, left positive: ``track.centerline.to_cartesian(s_m, n_m)`` draws it);
* ``profile["closed_loop"]``: ``vx_mps``, ``steer_rad`` (steering command), ``kappa_radpm``
  (path curvature r / v_x), ``ey_m`` (lateral error to the plan), ``n_m`` (offset from the
  centerline).

Examples
--------
The shipped table, as the paper prints it:

>>> from racing_lib.ablation import format_table, shipped_table  # doctest: +SKIP
>>> print(format_table(shipped_table()))  # doctest: +SKIP

Two rows, two trials each, on two worker processes (minutes):

>>> rows = run_ablation(["main", "decoupled"], trials=2, workers=2)  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass
from importlib import resources
from pathlib import Path as FilePath
from typing import Any

import numpy as np

from racing_lib.config import fast_mode
from racing_lib.errors import ControlError, PlanningError, RacingLibError, TrackError
from racing_lib.experiment import LapMetrics, LapSpec, drive_lap, run_trials, summarize
from racing_lib.geometry import Track
from racing_lib.io import atomic_write_text, jsonable
from racing_lib.planning.trajectory import Trajectory
from racing_lib.provenance import environment
from racing_lib.tracks import load_track
from racing_lib.tuning import (
    MPC_WEIGHT_NAMES,
    TUNING_CONFIGS,
    config_plan,
    config_spec,
    tuned_weights,
)

__all__ = [
    "DEFAULT_OUT",
    "DEFAULT_TRIALS",
    "FAST_TRIALS",
    "SHIPPED_TABLE_FILE",
    "AblationRow",
    "ablation_rows",
    "default_trials",
    "format_table",
    "generate_ablation_table",
    "load_table",
    "run_ablation",
    "select_rows",
    "shipped_table",
    "shipped_table_header",
    "stale_rows",
    "table_records",
]

#: Version of the row files; bumping it invalidates every cached row.
FORMAT = 1
#: Version of the table file: 2 added the provenance header and a checksum per row.
TABLE_FORMAT = 2
#: The cache folder used when none is given, relative to the working directory.
DEFAULT_OUT = "runs/ablation"
#: Seeded trials per row (the paper's ten).
DEFAULT_TRIALS = 10
#: Trials per row in fast mode (tests, CI): fewer laps, the same algorithm.
FAST_TRIALS = 2
#: Spacing of the stored profiles along the track centerline, m.
PROFILE_SPACING = 10.0
#: The shipped full-mode table, in ``racing_lib/data``.
SHIPPED_TABLE_FILE = "ablation_table.json"

#: Source files (relative to the package) whose code determines a plan / a row's laps; their
#: contents enter the cache keys, so a change of the planner or the controller invalidates the
#: rows that depend on it (and only those).
_PLAN_SOURCES = ("model.py", "track.py", "planning", "data/identified_params.json")
_BEST_LAP_SOURCES = (*_PLAN_SOURCES, "sim.py", "vehicle.py")
_LAP_SOURCES = (
    "control",
    "experiment.py",
    "model.py",
    "sim.py",
    "track.py",
    "vehicle.py",
    "data/identified_params.json",
)

# Labels of the table's rows in the paper's words ("without" = the paper's cross mark).
_LABELS = {
    "main": "main experiment (expressway)",
    "no-drag": "without drag",
    "no-longitudinal-weight-transfer": "without longitudinal weight transfer",
    "lateral-weight-transfer": "with lateral weight transfer",
    "curvature-plan": "curvature-optimal plan instead of time-optimal",
    "decoupled": "decoupled MPC instead of coupled",
    "no-smooth-transition": "without smooth reference transition",
}


# --------------------------------------------------------------------------------------------------
# The rows


@dataclass(frozen=True)
class AblationRow:
    """One row of the tables: which track, which configuration, which plan.

    Attributes
    ----------
    name : str
        Unique name (``'main'``, ``'no-drag'``, ..., ``'shortcut-main'``, ``'best-lap'``).
    track : str
        Built-in track the row is driven on.
    config : str
        The :data:`~racing_lib.tuning.TUNING_CONFIGS` entry giving the plan method, the model
        options (of planner and MPC), the controller, the smooth-transition switch and the tuned
        weights.
    table : str
        ``'I'`` (the ablation table) or ``'II'`` (tracking the best possible lap).
    label : str
        Description in the paper's words.
    best_lap : bool
        The plan is the best possible lap of the simulated car (Table II) instead of the
        configuration's planner.
    """

    name: str
    track: str
    config: str
    table: str
    label: str
    best_lap: bool = False


def ablation_rows() -> tuple[AblationRow, ...]:
    """Every row, in the order of the paper's tables.

    The expressway rows are exactly the configurations of
    :data:`~racing_lib.tuning.TUNING_CONFIGS` (in its order), so a configuration added there
    appears here.
    """
    rows = [
        AblationRow(name, "expressway", name, "I", _LABELS.get(name, name))
        for name in TUNING_CONFIGS
    ]
    rows += [
        AblationRow("shortcut-main", "shortcut", "main", "I", "sharper open track (shortcut)"),
        AblationRow(
            "shortcut-lateral-weight-transfer",
            "shortcut",
            "lateral-weight-transfer",
            "I",
            "shortcut, with lateral weight transfer",
        ),
        AblationRow(
            "best-lap",
            "expressway",
            "main",
            "II",
            "coupled MPC tracking the best possible lap",
            best_lap=True,
        ),
    ]
    return tuple(rows)


def select_rows(names: Iterable[str] | None = None, track: str | None = None) -> list[AblationRow]:
    """The rows to run, in table order.

    Parameters
    ----------
    names : iterable of str, optional
        Row names (all rows when omitted). Within a ``track``, a configuration name also selects
        that track's row (``track='shortcut'``, ``names=['main']`` is ``shortcut-main``).
    track : str, optional
        Only the rows driven on this built-in track.

    Raises
    ------
    TrackError
        ``track`` is not a track of the tables.
    ControlError
        A name is not a row (the message lists the rows).
    """
    rows = list(ablation_rows())
    if track is not None:
        tracks = sorted({r.track for r in rows})
        if track not in tracks:
            raise TrackError(
                f"the ablation tables have no rows on track {track!r}; choose one of "
                f"{', '.join(tracks)} (or no track for all rows)."
            )
        rows = [r for r in rows if r.track == track]
    if names is None:
        return rows
    wanted: set[str] = set()
    for name in names:
        exact = [r for r in rows if r.name == name]
        # Inside one track, 'main' means that track's main row (not the best-lap row).
        alias = [r for r in rows if r.config == name and not r.best_lap] if track else []
        found = exact or alias
        if len(found) != 1:
            where = f" on track {track!r}" if track else ""
            raise ControlError(
                f"unknown ablation row {name!r}{where}; choose from "
                f"{', '.join(r.name for r in rows)}."
            )
        wanted.add(found[0].name)
    return [r for r in rows if r.name in wanted]


def default_trials() -> int:
    """Trials per row: :data:`DEFAULT_TRIALS`, or :data:`FAST_TRIALS` in fast mode."""
    return FAST_TRIALS if fast_mode() else DEFAULT_TRIALS


# --------------------------------------------------------------------------------------------------
# Cache keys


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    raise TypeError(f"not JSON-serializable for a cache key: {type(obj).__name__}")


def _digest(obj: Any) -> str:
    """Hash (hex, 16 characters) of a JSON-able object, independent of dict order."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _source_digest(parts: Sequence[str]) -> str:
    """Hash of the package's source files (and data files) named in ``parts``."""
    root = FilePath(__file__).resolve().parent
    digest = hashlib.sha256()
    for part in parts:
        path = root / part
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        for file in files:
            digest.update(file.relative_to(root).as_posix().encode())
            digest.update(file.read_bytes() if file.exists() else b"<missing>")
    return digest.hexdigest()[:16]


def _code_digests() -> dict[str, str]:
    """Source digests of the plan, best-lap and lap code, read once per run.

    Once per run, because the worker processes keep the code they started with: a file edited
    during a long run must not make later rows claim code they did not run.
    """
    return {
        "plan": _source_digest(_PLAN_SOURCES),
        "best-lap": _source_digest(_BEST_LAP_SOURCES),
        "lap": _source_digest(_LAP_SOURCES),
    }


def _planning_params(row: AblationRow) -> tuple[str, dict[str, Any]]:
    """Which parameters the row's plan is made with: ("identified" | "vehicle", their values)."""
    if row.best_lap:
        from racing_lib.vehicle import VehicleParams

        return "vehicle", dataclasses.asdict(VehicleParams())
    from racing_lib.model.identified import identified_params

    return "identified", identified_params().to_dict()


def _plan_method(row: AblationRow) -> str:
    return "best-lap" if row.best_lap else str(TUNING_CONFIGS[row.config]["method"])


def _plan_options(row: AblationRow) -> dict[str, Any]:
    # The best lap uses the car's own equations: model options do not apply to it.
    return {} if row.best_lap else dict(TUNING_CONFIGS[row.config]["options"])


def _plan_key_inputs(
    row: AblationRow, track: Track, spacing: float | None, code: Mapping[str, str]
) -> dict[str, Any]:
    which, params = _planning_params(row)
    return {
        "kind": "plan",
        "format": FORMAT,
        "track": track.name,
        "track_checksum": track.checksum(),
        "boundary": track.boundary,
        "method": _plan_method(row),
        "options": _plan_options(row),
        "params": which,
        "param_values": params,
        "spacing": spacing,
        "code": code["best-lap" if row.best_lap else "plan"],
    }


def _row_key_inputs(
    row: AblationRow,
    track: Track,
    plan_key: str,
    weights: dict[str, float] | None,
    seeds: Sequence[int],
    code: Mapping[str, str],
) -> dict[str, Any]:
    from racing_lib.model.identified import identified_params
    from racing_lib.vehicle import VehicleParams

    cfg = TUNING_CONFIGS[row.config]
    return {
        "kind": "row",
        "format": FORMAT,
        "name": row.name,
        "track_checksum": track.checksum(),
        "plan_key": plan_key,
        "config": row.config,
        "controller": cfg["controller"],
        "smooth_transition": bool(cfg.get("smooth_transition", True)),
        "mpc_options": dict(cfg["options"]),
        "mpc_params": identified_params().to_dict(),
        "vehicle": dataclasses.asdict(VehicleParams()),
        "weights": weights,
        "seeds": list(seeds),
        "run_up_m": LapSpec.run_up,
        "profile_spacing_m": PROFILE_SPACING,
        "fast_mode": fast_mode(),
        "code": code["lap"],
    }


# --------------------------------------------------------------------------------------------------
# Plans (cached as plan CSVs: the best lap takes minutes)


def _make_plan(row: AblationRow, track: Track, spacing: float | None) -> tuple[Trajectory, dict]:
    """Plan a row (no cache): its configuration's planner, or the best possible lap."""
    if row.best_lap:
        from racing_lib.planning.best_lap import BestLapSettings, solve_best_lap

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
    inputs = _plan_key_inputs(row, track, spacing, code)
    key = _digest(inputs)
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
            "options": inputs["options"],
            "params": inputs["params"],
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


def _rounded(values: np.ndarray, decimals: int) -> list[float | None]:
    arr = np.round(np.asarray(values, dtype=float), decimals)
    return [float(v) if math.isfinite(v) else None for v in arr]


def _periodic_profile(
    s: np.ndarray, values: Mapping[str, np.ndarray], grid: np.ndarray, length: float, gap: float
) -> dict[str, np.ndarray]:
    """Values given at (unsorted) arc lengths ``s`` resampled on ``grid``, m (periodic).

    Grid points farther than ``gap`` (m) from every sample (a lap that stopped) become NaN.
    """
    s = np.mod(np.asarray(s, dtype=float), length)
    order = np.argsort(s)
    s_sorted = s[order]
    idx = np.searchsorted(s_sorted, grid) % s_sorted.size
    nearest = np.minimum(
        np.abs((s_sorted[idx] - grid + 0.5 * length) % length - 0.5 * length),
        np.abs((s_sorted[idx - 1] - grid + 0.5 * length) % length - 0.5 * length),
    )
    out = {}
    for name, vals in values.items():
        v = np.interp(grid, s_sorted, np.asarray(vals, dtype=float)[order], period=length)
        out[name] = np.where(nearest <= gap, v, np.nan)
    return out


def _profile_grid(track: Track) -> np.ndarray:
    return np.arange(0.0, float(track.length), PROFILE_SPACING)


def _closed_loop_profile(log: Any, track: Track) -> dict[str, list[float | None]]:
    """The closed-loop lap on the track-centerline grid (every :data:`PROFILE_SPACING` m)."""
    lap = log.in_lap if log.in_lap.any() else np.ones_like(log.in_lap)
    s = np.asarray(log.s_track, dtype=float)[lap]
    vx = np.asarray(log.vx, dtype=float)[lap]
    _, n, _ = track.centerline.to_frenet(log.x[lap], log.y[lap], s_hint=s)
    # Path curvature of the closed loop: yaw rate over speed (the side-slip rate is neglected).
    kappa = np.asarray(log.r, dtype=float)[lap] / np.maximum(vx, 1.0)
    values = {"vx": vx, "steer": log.steer[lap], "kappa": kappa, "ey": log.ey[lap], "n": n}
    # A gap of a few control steps means the car stopped lapping there.
    gap = max(3.0 * PROFILE_SPACING, 3.0 * float(np.max(vx, initial=0.0)) * 0.1)
    prof = _periodic_profile(s, values, _profile_grid(track), float(track.length), gap)
    return {
        "vx_mps": _rounded(prof["vx"], 2),
        "steer_rad": _rounded(prof["steer"], 4),
        "kappa_radpm": _rounded(prof["kappa"], 5),
        "ey_m": _rounded(prof["ey"], 3),
        "n_m": _rounded(prof["n"], 2),
    }


def _plan_profile(trajectory: Trajectory, track: Track) -> dict[str, list[float | None]]:
    """The plan on the track-centerline grid (every :data:`PROFILE_SPACING` m)."""
    s, n = track.centerline.to_frenet_along(trajectory.x, trajectory.y)
    values = {"vx": trajectory.vx, "kappa": trajectory.kappa, "delta": trajectory.delta, "n": n}
    prof = _periodic_profile(s, values, _profile_grid(track), float(track.length), math.inf)
    return {
        "vx_mps": _rounded(prof["vx"], 2),
        "kappa_radpm": _rounded(prof["kappa"], 5),
        "delta_rad": _rounded(prof["delta"], 4),
        "n_m": _rounded(prof["n"], 2),
    }


def _trial(spec: LapSpec, seed: int, profile_seed: int | None = None) -> _TrialOutcome:
    """One seeded lap of ``spec`` (module level, so process pools can ship it)."""
    tic = time.perf_counter()
    res = drive_lap(spec, seed=seed)
    wall = time.perf_counter() - tic
    log = res.log
    # The steps between the two line crossings, as in the lap metrics.
    lap = log.in_lap if log.in_lap.any() else np.ones_like(log.in_lap)
    profile = None
    if seed == profile_seed:
        profile = {"seed": seed, "completed": res.metrics.completed}
        profile["closed_loop"] = _closed_loop_profile(log, spec.track)
    return _TrialOutcome(
        metrics=res.metrics,
        vx_abs_err=np.abs(log.vx[lap] - log.vx_ref[lap]).astype(np.float32),
        ey_abs=np.abs(log.ey[lap]).astype(np.float32),
        solve_ms=np.asarray(log.solve_ms, dtype=np.float32),
        wall_time_s=wall,
        profile=profile,
    )


# --------------------------------------------------------------------------------------------------
# A row from its trials


def _compact_json(obj: Any) -> str:
    """One line of JSON without spaces (the profiles are most of a row: keep files small)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def _pooled(values: Sequence[np.ndarray]) -> tuple[float, float, float]:
    """Mean, std and max of |error| over the control steps of all trials (the paper's format)."""
    arr = np.concatenate([np.asarray(v, dtype=float) for v in values]) if values else np.zeros(0)
    if arr.size == 0:
        return math.nan, math.nan, math.nan
    return float(arr.mean()), float(arr.std()), float(arr.max())


def _effective_weights(weights: dict[str, float] | None) -> dict[str, float]:
    """The MPC weights actually used: the given ones over the MPC's defaults."""
    from racing_lib.control.mpc import MPCSettings

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
    key_inputs: dict[str, Any],
    wall_time: float,
) -> dict[str, Any]:
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
            "s_m": _rounded(_profile_grid(track), 1),
            **profile,
            "plan": _plan_profile(trajectory, track),
        }
    row_dict: dict[str, Any] = {
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


def _load_row(path: FilePath, key: str) -> dict[str, Any] | None:
    """A cached row if ``path`` holds one with this key (None if missing or damaged)."""
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) and data.get("key") == key else None


def _resolve_tracks(
    rows: Sequence[AblationRow], tracks: Mapping[str, Track] | None
) -> dict[str, Track]:
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
    on_row: Callable[[dict[str, Any], bool], None] | None = None,
    cached_only: bool = False,
) -> list[dict[str, Any]]:
    """Compute rows of the tables (or reuse them from the cache folder).

    Each row is planned once (plans are cached too), then driven for ``trials`` seeded laps
    (seeds ``seed, seed + 1, ...``) through :func:`racing_lib.experiment.run_trials`; the row is
    written to ``out_dir`` as soon as its trials are done, so an interruption (Ctrl-C) keeps every
    finished row, and a rerun reuses every row whose cache key still matches.

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
    list of dict
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
    n_trials = default_trials() if trials is None else int(trials)
    if n_trials < 1:
        raise ControlError(f"trials must be at least 1, got {trials}; the paper uses 10.")
    if spacing is not None and not (math.isfinite(spacing) and spacing > 0):
        raise PlanningError(f"plan spacing must be a positive number of m, got {spacing}.")
    seeds = [int(seed) + i for i in range(n_trials)]
    say = log or _quiet
    folder = FilePath(out_dir) if out_dir is not None else None
    track_objs = _resolve_tracks(selected, tracks)
    memo: dict[str, tuple[Trajectory, dict]] = {}
    code = _code_digests()
    own_pool: ProcessPoolExecutor | None = None

    def lap_executor() -> Executor | None:
        nonlocal own_pool
        if executor is not None:
            return executor
        if workers <= 1:
            return None
        if own_pool is None:
            own_pool = ProcessPoolExecutor(max_workers=int(workers))
        return own_pool

    from tqdm.auto import tqdm

    results: list[dict[str, Any]] = []
    bar = tqdm(
        total=len(selected), desc="ablation", unit="row", disable=not progress or cached_only
    )
    try:
        for row in selected:
            trk = track_objs[row.track]
            bar.set_description(row.name)
            weights = tuned_weights(row.config)
            plan_key = _digest(_plan_key_inputs(row, trk, spacing, code))
            key_inputs = _row_key_inputs(row, trk, plan_key, weights, seeds, code)
            key = _digest(key_inputs)
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
            spec = config_spec(row.config, trk, trajectory=traj, weights=weights)
            pool = lap_executor()
            where = "in this process" if pool is None else "in parallel"
            say(f"{row.name}: {n_trials} trials {where} ...")
            tic = time.perf_counter()
            outcomes = run_trials(
                functools.partial(_trial, spec, profile_seed=seeds[0]), seeds, pool
            )
            result = _row_result(
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
            if path is not None:
                atomic_write_text(path, _compact_json(result))
                result_file = str(path)
            else:
                result_file = "not cached"
            say(f"{row.name}: {_short(result)} -> {result_file}")
            results.append(result)
            if on_row is not None:
                on_row(result, False)
            bar.update(1)
    except KeyboardInterrupt:
        if own_pool is not None:
            _stop_workers(own_pool)
        raise
    finally:
        bar.close()
        if own_pool is not None:
            own_pool.shutdown(wait=True, cancel_futures=True)
    return results


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


def _short(row: Mapping[str, Any]) -> str:
    """One line on a row: planned and closed-loop lap time, errors, walls."""
    mean = row.get("lap_time_mean_s")
    lap = f"{mean:.2f} +- {row['lap_time_std_s']:.3f} s" if mean is not None else "no lap completed"
    vx, ey = row.get("vx_mae_mps"), row.get("ey_mae_m")
    return (
        f"planned {row['planned_lap_time_s']:.2f} s, closed loop {lap} "
        f"({row['completed']}/{row['trials']} completed), v_x MAE "
        f"{_num(vx, 3)} m/s, e_y MAE {_num(ey, 3)} m, wall contacts {row['wall_contacts']}"
    )


def _num(x: Any, decimals: int) -> str:
    return "-" if x is None else f"{float(x):.{decimals}f}"


# --------------------------------------------------------------------------------------------------
# The table as the paper prints it


def table_records(rows: Iterable[Mapping[str, Any]]) -> list[dict[str, str]]:
    """The paper's columns as formatted text, one dict per row.

    Columns: ``row``, ``planned lap [s]``, ``closed-loop lap [s]`` (mean +- std (min)),
    ``v_x MAE [m/s]`` and ``e_y MAE [m]`` (mean +- std (max) over the control steps of all
    trials), ``wall contacts`` (total over the trials, and per lap), ``completed``.
    """
    out = []
    for r in rows:
        mean = r.get("lap_time_mean_s")
        lap = (
            f"{mean:.2f} ± {r['lap_time_std_s']:.3f} ({r['lap_time_min_s']:.2f})"
            if mean is not None
            else "-"
        )
        vx = f"{_num(r.get('vx_mae_mps'), 3)} ± {_num(r.get('vx_mae_std_mps'), 3)} "
        vx += f"({_num(r.get('vx_max_err_mps'), 2)})"
        ey = f"{_num(r.get('ey_mae_m'), 3)} ± {_num(r.get('ey_mae_std_m'), 3)} "
        ey += f"({_num(r.get('ey_max_m'), 2)})"
        walls = f"{r['wall_contacts']} ({_num(r.get('wall_contacts_per_lap'), 1)}/lap)"
        out.append(
            {
                "row": str(r["name"]),
                "planned lap [s]": f"{r['planned_lap_time_s']:.2f}",
                "closed-loop lap [s]": lap,
                "v_x MAE [m/s]": vx,
                "e_y MAE [m]": ey,
                "wall contacts": walls,
                "completed": f"{r['completed']}/{r['trials']}",
            }
        )
    return out


def format_table(
    rows: Iterable[Mapping[str, Any]],
    markdown: bool = False,
    sources: Sequence[str] | None = None,
) -> str:
    """The table as text (aligned columns) or as a Markdown table (for a notebook).

    Parameters
    ----------
    rows : iterable of dict
        Rows of :func:`run_ablation` or :func:`shipped_table`.
    markdown : bool
        Markdown table (``IPython.display.Markdown`` renders it) instead of plain text.
    sources : sequence of str, optional
        Where each row comes from (``'shipped'``, ``'recomputed'``): an extra last column.
    """
    records = table_records(rows)
    if sources is not None:
        records = [{**r, "source": src} for r, src in zip(records, sources, strict=True)]
    if not records:
        return "(no rows)"
    cols = list(records[0])
    if markdown:
        lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        lines += ["| " + " | ".join(r[c] for c in cols) + " |" for r in records]
        return "\n".join(lines)
    widths = {c: max(len(c), *(len(r[c]) for r in records)) for c in cols}
    lines = ["  ".join(c.ljust(widths[c]) for c in cols)]
    lines.append("  ".join("-" * widths[c] for c in cols))
    lines += ["  ".join(r[c].ljust(widths[c]) for c in cols) for r in records]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------------
# The shipped table


def _shipped_path() -> FilePath:
    return FilePath(__file__).resolve().parent / "data" / SHIPPED_TABLE_FILE


def load_table(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A table file written by :func:`generate_ablation_table` (the whole object).

    Returns
    -------
    dict
        ``format``, ``created_utc``, ``fast_mode``, ``trials``, ``wall_time_s`` and ``rows``.
    """
    try:
        data = json.loads(FilePath(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise RacingLibError(
            f"cannot read the ablation table {os.fspath(path)!r} ({exc}); regenerate it with "
            "racing_lib.ablation.generate_ablation_table()."
        ) from exc
    if not isinstance(data, dict) or not isinstance(data.get("rows"), list):
        raise RacingLibError(
            f"{os.fspath(path)!r} is not an ablation table (no 'rows'); regenerate it with "
            "racing_lib.ablation.generate_ablation_table()."
        )
    if int(data.get("format", 0)) < TABLE_FORMAT:
        raise RacingLibError(
            f"the ablation table {os.fspath(path)!r} has format {data.get('format')}, from before "
            "tables recorded their provenance and row checksums; regenerate it with "
            "racing_lib.ablation.generate_ablation_table()."
        )
    for row in data["rows"]:
        if not isinstance(row, dict) or row.get("sha256") != _row_digest(row):
            name = row.get("name", "?") if isinstance(row, dict) else "?"
            raise RacingLibError(
                f"row {name!r} of the ablation table {os.fspath(path)!r} fails its checksum: "
                "its numbers were changed after the table was made, so none of them can be "
                "trusted; restore the file (git checkout) or recompute the row with "
                f"`racing-lib ablation --recompute {name}`."
            )
    return data


def shipped_table_header() -> dict[str, Any]:
    """The shipped table's header: format, date, trials, wall time and ``provenance`` (the
    machine, BLAS kernel and package versions that made it, see
    :func:`racing_lib.provenance.environment`)."""
    data = _read_shipped()
    return {k: v for k, v in data.items() if k != "rows"}


def _read_shipped() -> dict[str, Any]:
    ref = resources.files("racing_lib").joinpath("data", SHIPPED_TABLE_FILE)
    if not ref.is_file():
        raise RacingLibError(
            f"racing_lib/data/{SHIPPED_TABLE_FILE} is not shipped yet; compute it with "
            "racing_lib.ablation.generate_ablation_table(workers=2), or run rows with "
            "run_ablation()."
        )
    with resources.as_file(ref) as path:
        return load_table(path)


def shipped_table() -> list[dict[str, Any]]:
    """The rows of the full-mode table shipped in ``racing_lib/data/ablation_table.json``.

    Loads in milliseconds; notebook 07 reads it instead of recomputing (about five minutes on two
    cores). :func:`stale_rows` tells which rows the current code would compute differently.

    Raises
    ------
    RacingLibError
        No table is shipped yet (make it with :func:`generate_ablation_table`).
    """
    return _read_shipped()["rows"]


def stale_rows(
    rows: Iterable[Mapping[str, Any]], tracks: Mapping[str, Track] | None = None
) -> list[str]:
    """Names of the rows that the current code and data would not reproduce.

    A row is stale when its cache key differs from the one computed now from the same seeds and
    plan spacing (the weights, model parameters, track or source code changed since it was made).
    """
    by_name = {r.name: r for r in ablation_rows()}
    code = _code_digests()
    stale = []
    for row in rows:
        spec = by_name.get(str(row.get("name")))
        if spec is None:
            stale.append(str(row.get("name")))
            continue
        trk = _resolve_tracks([spec], tracks)[spec.track]
        spacing = (row.get("plan") or {}).get("spacing_m")
        plan_key = _digest(_plan_key_inputs(spec, trk, spacing, code))
        weights = tuned_weights(spec.config)
        inputs = _row_key_inputs(spec, trk, plan_key, weights, row["seeds"], code)
        inputs["fast_mode"] = bool(row.get("fast_mode", False))  # judge the row on its own terms
        if _digest(inputs) != row.get("key"):
            stale.append(spec.name)
    return stale


def _row_digest(row: Mapping[str, Any]) -> str:
    """SHA-256 of a row's JSON (its own ``sha256`` field left out)."""
    return hashlib.sha256(
        _compact_json({k: v for k, v in row.items() if k != "sha256"}).encode("utf-8")
    ).hexdigest()


def _table_text(header: Mapping[str, Any], rows: Sequence[Mapping[str, Any]]) -> str:
    """JSON with one row per line: small diffs when a row changes, still one JSON object.

    Each row carries the checksum of its own numbers, so that :func:`load_table` refuses a row
    edited by hand instead of showing it.
    """
    head = ",\n".join(f"{json.dumps(k)}: {json.dumps(v)}" for k, v in sorted(header.items()))
    signed = [{**r, "sha256": _row_digest(r)} for r in rows]
    body = ",\n".join(_compact_json(r) for r in signed)
    return "{\n" + head + ',\n"rows": [\n' + body + "\n]\n}\n"


def generate_ablation_table(
    workers: int = 2,
    *,
    out_dir: str | os.PathLike[str] | None = DEFAULT_OUT,
    target: str | os.PathLike[str] | None = None,
    progress: bool = True,
    **kwargs: Any,
) -> list[dict[str, Any]]:
    """Recompute every row (reusing the cache) and write the shipped table (maintainers).

    Run after a change to the planner, the MPC, the car or the tuned weights, then commit
    ``racing_lib/data/ablation_table.json``. Rows already in ``out_dir`` with a matching key are
    reused, so an interrupted run continues where it stopped.

    Parameters
    ----------
    workers : int
        Local worker processes for the laps.
    out_dir : path or None
        The cache folder (see :func:`run_ablation`).
    target : path, optional
        The file written (default: ``racing_lib/data/ablation_table.json`` of the source tree
        this module was imported from).
    progress : bool
        Progress bar.
    **kwargs
        More :func:`run_ablation` arguments (``trials``, ``seed``, ``executor``, ``log``, ...).

    Raises
    ------
    RacingLibError
        Fast mode is on and the target is the shipped file (the shipped table is full-mode).
    """
    path = FilePath(target) if target is not None else _shipped_path()
    if fast_mode() and target is None:
        raise RacingLibError(
            "generate_ablation_table writes the shipped full-mode table, but fast mode is on "
            "(RACING_LIB_FAST); unset it, or pass target= to write somewhere else."
        )
    tic = time.perf_counter()
    rows = run_ablation(out_dir=out_dir, workers=workers, progress=progress, **kwargs)
    env = environment()
    header = {
        "format": TABLE_FORMAT,
        "created_utc": env["created_utc"],
        "provenance": env,
        "fast_mode": fast_mode(),
        "trials": max((int(r["trials"]) for r in rows), default=0),
        "workers": workers,
        "wall_time_s": round(time.perf_counter() - tic, 1),
    }
    atomic_write_text(path, _table_text(header, rows))
    return rows
