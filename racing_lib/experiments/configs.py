"""The configurations of the paper's tables and the weights tuned for them.

How each configuration is planned and driven, and the weights tuned for it (shipped in
``racing_lib/data/tuned_weights.json``).
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import Executor
from pathlib import Path as FilePath
from typing import TYPE_CHECKING, Any

import numpy as np

from racing_lib.errors import ControlError
from racing_lib.experiments.lap import LapSpec
from racing_lib.experiments.tuning import (
    evaluate_weights,
    mpc_weight_space,
    seed_tuple,
    tune_weights,
)
from racing_lib.geometry import Track
from racing_lib.io import atomic_write_json, data_file, jsonable
from racing_lib.model import CarModel, ModelOptions, identified_model
from racing_lib.optim.cmaes import TuningResult, TuningSettings
from racing_lib.planning import PlanResult, Trajectory, plan
from racing_lib.tracks import CircuitSpec, generate, load_track

if TYPE_CHECKING:
    # Only named in annotations: dask is an optional dependency (racing-lib[distributed]).
    from distributed import Client

__all__ = [
    "TUNED_FILE_FORMAT",
    "TUNED_WEIGHTS_FILE",
    "TUNING_CIRCUIT_LENGTH",
    "TUNING_CIRCUIT_SEEDS",
    "TUNING_CONFIGS",
    "config_model",
    "config_plan",
    "configuration_name",
    "config_spec",
    "generate_tuned_weights",
    "main_tuning_tracks",
    "history_summary",
    "tuned_configurations",
    "tuned_weights",
    "tuning_history",
    "tuning_record",
]


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

#: Version of the tuned-weights file.
TUNED_FILE_FORMAT = 1
TUNED_WEIGHTS_FILE = "tuned_weights.json"


def configuration_name(
    controller: str,
    method: str,
    options: ModelOptions | None = None,
    smooth_transition: bool = True,
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
        text = data_file(TUNED_WEIGHTS_FILE).read_text(encoding="utf-8")
    except (FileNotFoundError, OSError):
        return {}
    data = json.loads(text)
    return data.get("configs", {}) if isinstance(data, dict) else {}


def _start_label(initial: str | Mapping[str, float] | None) -> str:
    """Where a tuning run started, for the shipped file."""
    if initial is None:
        return "defaults"
    return f"tuned '{initial}'" if isinstance(initial, str) else "given weights"


def history_summary(
    # Any: TuningResult.history entries, the optimizer's records of mixed values (optim.cmaes).
    history: Sequence[Mapping[str, Any]],
) -> list[dict[str, float]]:
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


def tuning_record(config: str = "main") -> dict[str, Any] | None:
    """What the shipped tuning of a configuration was scored on, and how it went.

    Returns
    -------
    dict or None
        The shipped entry without its history and model: ``track`` (a name, or the list of
        circuits tuned on), ``seeds``, ``generations``, ``evaluations`` (candidates),
        ``objective`` and ``objective_at_defaults``, ``planned_lap_time_s``, ``settings``,
        ``started_from``, ``created_utc``; None when nothing is shipped for ``config``.
    """
    entry = _read_tuned_file().get(config)
    if not entry:
        return None
    return {k: v for k, v in entry.items() if k not in ("history", "model")}


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


def config_model(config: str, model: CarModel | None = None) -> CarModel:
    """The model of a configuration of :data:`TUNING_CONFIGS`: ``model`` with its effects.

    Parameters
    ----------
    config : str
        A name of :data:`TUNING_CONFIGS`.
    model : CarModel, optional
        The model to start from (default: :func:`racing_lib.model.identified_model`); the
        configuration sets its options (the paper's model ablations) and nothing else.
    """
    cfg = _config(config)
    base = identified_model() if model is None else model
    return base.replace(options=ModelOptions(**cfg["options"]))


def config_plan(
    config: str,
    track: Track,
    model: CarModel | None = None,
    # Any: forwarded to racing_lib.planning.plan, whose keywords have different types.
    **plan_kwargs: Any,
) -> PlanResult:
    """The plan of a configuration of :data:`TUNING_CONFIGS`: its method and model options.

    About 20 s for the time-optimal planner on the expressway.

    Parameters
    ----------
    config : str
        A name of :data:`TUNING_CONFIGS`.
    track : Track
        The track.
    model : CarModel, optional
        The model to plan with, before the configuration sets its options (default:
        :func:`racing_lib.model.identified_model`); see :func:`config_model`.
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
    cfg = _config(config)
    planned = plan(track, cfg["method"], config_model(config, model), **plan_kwargs)
    if not planned.success:
        raise ControlError(
            f"the {cfg['method']} plan of configuration {config!r} failed ({planned.status}); "
            "tune on a plan that converged (see racing_lib.planning.plan)."
        )
    return planned


def config_spec(
    config: str,
    track: Track,
    model: CarModel | None = None,
    *,
    trajectory: Trajectory | None = None,
    weights: dict[str, float] | None = None,
    # Any: forwarded to racing_lib.planning.plan, whose keywords have different types.
    **plan_kwargs: Any,
) -> LapSpec:
    """The :class:`~racing_lib.experiments.lap.LapSpec` of a configuration.

    The :class:`~racing_lib.experiments.lap.LapSpec` of a configuration of
    :data:`TUNING_CONFIGS`.

    Plans ``track`` with :func:`config_plan` unless a ``trajectory`` is given.

    Parameters
    ----------
    config : str
        A name of :data:`TUNING_CONFIGS`.
    track : Track
        The track.
    model : CarModel, optional
        The model to plan with, which the spec's MPC then predicts with too, before the
        configuration sets its options (default: :func:`racing_lib.model.identified_model`).
    trajectory : Trajectory, optional
        A plan already made for this configuration (for example loaded from a cache): no planning.
    weights : dict, optional
        MPC weights of the spec (default: the MPC's defaults).
    **plan_kwargs
        Passed on to :func:`racing_lib.planning.plan`.
    """
    cfg = _config(config)
    if trajectory is None:
        trajectory = config_plan(config, track, model, **plan_kwargs).trajectory
    return LapSpec(
        track=track,
        trajectory=trajectory,
        controller=cfg["controller"],
        smooth_transition=bool(cfg.get("smooth_transition", True)),
        weights=weights,
        model=config_model(config, model),
    )


#: Seeds of the generated circuits the shipped weights are tuned on: far from the seeds that the
#: course and the benchmarks draw for testing (0-49, 100-149, 500-509).
TUNING_CIRCUIT_SEEDS: tuple[int, ...] = tuple(range(1000, 1008))

#: Their lengths, m: shorter than most real circuits, so that a generation of laps stays cheap.
TUNING_CIRCUIT_LENGTH: tuple[float, float] = (2000.0, 4000.0)


def main_tuning_tracks() -> list[Track]:
    """The circuits every shipped weight set is tuned on: eight generated ones, none of them real.

    Circuits the generator draws (:func:`racing_lib.tracks.generate`, seeds
    :data:`TUNING_CIRCUIT_SEEDS`, 2-4 km, open edges), so that every track the course and the
    benchmarks report on (the expressway of the paper's table, the shortcut, the figure-eight and
    every real circuit) stays unseen by the tuning. The command line draws the same ones with
    ``racing-lib tracks --generate 8 --seed 1000 --length 2000 4000``.
    """
    spec = CircuitSpec(length=TUNING_CIRCUIT_LENGTH)
    return [generate(seed, spec) for seed in TUNING_CIRCUIT_SEEDS]


def generate_tuned_weights(
    configs: Iterable[str] = ("main",),
    *,
    track: str | os.PathLike[str] | Track | Sequence[str | os.PathLike[str] | Track] = "expressway",
    seeds: int | Iterable[int] = (0,),
    settings: TuningSettings | None = None,
    executor: Executor | Client | None = None,
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
    track : str, path, Track or sequence of them
        The track tuned on (the paper tunes on its main track), or several (names, CSV files,
        Tracks): the objective is then their mean, for weights that carry over to other circuits.
    seeds : int or iterable of int
        Seeds of the laps scoring every candidate.
    settings : TuningSettings, optional
        CMA-ES settings (default :meth:`TuningSettings.default`).
    executor, workers
        Where laps run (see :meth:`~racing_lib.optim.cmaes.CmaTuner.run`).
    out : path, optional
        The JSON file written (default: ``racing_lib/data/tuned_weights.json`` of the source
        tree this module was imported from).
    work_dir : path, optional
        Folder for the per-configuration checkpoints, so that an interrupted generation resumes.
    progress : bool
        Progress bars.
    initial : str or dict, optional
        Where CMA-ES starts: the MPC's default weights (None), the shipped tuned weights of another
        configuration (its name, e.g. ``'main'``: the ablations start from the main result; read
        from ``out`` when it has them, else from the shipped file), or explicit weights.
    """
    track_list = list(track) if isinstance(track, (list, tuple)) else [track]
    tracks = [t if isinstance(t, Track) else load_track(str(t)) for t in track_list]
    target = FilePath(out) if out is not None else data_file(TUNED_WEIGHTS_FILE)
    data: dict[str, Any] = {"format": TUNED_FILE_FORMAT, "configs": {}}
    if target.exists():
        data = json.loads(target.read_text())
        data.setdefault("configs", {})
    start = initial
    if isinstance(initial, str):
        # The file being written first: a re-tuning into a new file starts each row from the
        # main weights tuned in the same run, not from the shipped ones.
        written = data["configs"].get(initial, {}).get("weights")
        start = dict(written) if written else tuned_weights(initial)
        if start is None:
            raise ControlError(
                f"no tuned weights for {initial!r} to start from, neither in {target} nor "
                "shipped; tune it first or pass initial=None."
            )
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
        at_defaults = evaluate_weights(spec, {}, seed_tuple(seeds))
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
                "model": specs[0].model.to_dict(),
                "controller": specs[0].controller,
                "smooth_transition": specs[0].smooth_transition,
                "seeds": list(seed_tuple(seeds)),
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
