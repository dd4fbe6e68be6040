"""Cache keys: a hash of everything that determines a plan or a row, the code it runs included."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from racing_lib.config import fast_mode
from racing_lib.experiments.ablation.profiles import PROFILE_SPACING
from racing_lib.experiments.ablation.rows import AblationRow
from racing_lib.experiments.configs import TUNING_CONFIGS, config_model
from racing_lib.experiments.lap import (
    LapSpec,
)
from racing_lib.geometry import Track
from racing_lib.provenance import code_digest
from racing_lib.vehicle import VehicleParams

__all__ = [
    "FORMAT",
    "KeyInputs",
    "code_digests",
    "compact_json",
    "digest",
    "plan_key_inputs",
    "plan_options",
    "row_key_inputs",
]

#: Version of the row files; bumping it invalidates every cached row.
FORMAT = 1

#: The modules whose code makes a plan, a best lap and a row's laps. Their source, and that of
#: everything they import (read from the imports by :func:`racing_lib.provenance.code_digest`, so
#: no list of files here can fall behind a move), enters the cache keys: a change of the planner
#: or the controller invalidates the rows that depend on it, and only those.
#: A plan is keyed by its planner's code (the configuration's method, options and parameters enter
#: its key by value); a row by everything the runner runs, from the configuration and the weights
#: to the laps and the numbers it keeps.
_PLAN_CODE = ("racing_lib.planning",)
_BEST_LAP_CODE = (*_PLAN_CODE, "racing_lib.planning.best_lap")
_LAP_CODE = ("racing_lib.experiments.ablation.runner",)

#: What a cache key hashes (see :func:`plan_key_inputs` and :func:`row_key_inputs`): a JSON
#: object of names, numbers, the model's and the car's parameters and code digests, hence ``Any``.
KeyInputs = dict[str, Any]

# --------------------------------------------------------------------------------------------------
# Cache keys


def _json_default(obj: object) -> object:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    raise TypeError(f"not JSON-serializable for a cache key: {type(obj).__name__}")


def digest(obj: object) -> str:
    """Hash (hex, 16 characters) of a JSON-able object, independent of dict order."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def code_digests() -> dict[str, str]:
    """Source digests of the plan, best-lap and lap code, read once per run.

    Once per run, because the worker processes keep the code they started with: a file edited
    during a long run must not make later rows claim code they did not run.
    """
    return {
        "plan": code_digest(_PLAN_CODE),
        "best-lap": code_digest(_BEST_LAP_CODE),
        "lap": code_digest(_LAP_CODE),
    }


def _planning_model(row: AblationRow) -> KeyInputs:
    """What the row's plan is made with: the configuration's model, or the car's own equations."""
    if row.best_lap:
        return {"vehicle": dataclasses.asdict(VehicleParams())}
    return {"model": config_model(row.config).to_dict()}


def _plan_method(row: AblationRow) -> str:
    return "best-lap" if row.best_lap else str(TUNING_CONFIGS[row.config]["method"])


def plan_options(row: AblationRow) -> dict[str, bool]:
    """The model effects a row's configuration sets (none for the best lap)."""
    # The best lap uses the car's own equations: model options do not apply to it.
    return {} if row.best_lap else dict(TUNING_CONFIGS[row.config]["options"])


def plan_key_inputs(
    row: AblationRow, track: Track, spacing: float | None, code: Mapping[str, str]
) -> KeyInputs:
    """What determines a row's plan: track, method, options, parameters, spacing, planner code."""
    return {
        "kind": "plan",
        "format": FORMAT,
        "track": track.name,
        "track_checksum": track.checksum(),
        "boundary": track.boundary,
        "method": _plan_method(row),
        **_planning_model(row),
        "spacing": spacing,
        "code": code["best-lap" if row.best_lap else "plan"],
    }


def row_key_inputs(
    row: AblationRow,
    track: Track,
    plan_key: str,
    weights: dict[str, float] | None,
    seeds: Sequence[int],
    code: Mapping[str, str],
) -> KeyInputs:
    """What determines a row's laps: its plan's key, controller, weights, seeds and the lap code."""
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
        "mpc_model": config_model(row.config).to_dict(),
        "vehicle": dataclasses.asdict(VehicleParams()),
        "weights": weights,
        "seeds": list(seeds),
        "run_up_m": LapSpec.run_up,
        "profile_spacing_m": PROFILE_SPACING,
        "fast_mode": fast_mode(),
        "code": code["lap"],
    }


# --------------------------------------------------------------------------------------------------
# A row from its trials


def compact_json(obj: object) -> str:
    """One line of JSON without spaces (the profiles are most of a row: keep files small)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)
