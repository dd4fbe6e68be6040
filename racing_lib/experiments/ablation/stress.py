"""The controller ablations at the limit: the same plan, the same seeds, no grip margin.

With the pipeline's grip margin the plan leaves the tyres some grip to spare, and every
controller of the ablation table tracks it about equally well: the paper's decoupled and
no-smooth-transition failures do not show (chapter 07 finds them indistinguishable from main).
The paper's failures come from driving at the limit. This module removes the spare grip: it plans
the time-optimal lap with ``grip_margin`` (0 by default, the identified model's full ellipse),
drives that one plan with each controller configuration and its own tuned weights over the same
seeds, and weighs every ablation against main lap by lap with a Welch interval
(:func:`racing_lib.experiments.ablation.claims.welch_interval`).
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from racing_lib.errors import ArgumentError
from racing_lib.experiments.ablation.claims import LEVEL, welch_interval
from racing_lib.experiments.configs import (
    TUNING_CONFIGS,
    config_plan,
    config_spec,
    tuned_weights,
)
from racing_lib.experiments.lap import LapMetrics, LapSpec, drive_lap, run_trials
from racing_lib.geometry import Track
from racing_lib.model import identified_model
from racing_lib.tracks import load_track

__all__ = [
    "STRESS_CONFIGS",
    "Comparison",
    "StressResult",
    "compare_to_main",
    "stress_run",
    "stress_table",
]

#: The controller configurations the stress setting compares: main and its two controller
#: ablations (the plan is the same for all three, so only the controller differs).
STRESS_CONFIGS = ("main", "decoupled", "no-smooth-transition")

#: The measures weighed against main, with their units: (LapMetrics field, label, unit).
MEASURES = (
    ("lap_time_s", "lap time", "s"),
    ("vx_mae_mps", "v_x MAE", "m/s"),
    ("ey_mae_m", "e_y MAE", "m"),
    ("wall_contacts", "wall contacts", "per lap"),
)


@dataclass(frozen=True)
class StressResult:
    """The laps of the stress setting.

    Attributes
    ----------
    track : str
        The circuit's name.
    grip_margin : float
        The planning model's grip margin (0: the full friction ellipse).
    planned_lap_s : float
        The plan's lap time, s.
    laps : dict
        Configuration -> its laps' metrics, one per seed, in seed order.
    """

    track: str
    grip_margin: float
    planned_lap_s: float
    laps: dict[str, list[LapMetrics]]

    def values(self, config: str, field: str) -> np.ndarray:
        """One measure of a configuration's completed laps, seed by seed."""
        return np.array(
            [float(getattr(m, field)) for m in self.laps[config] if m.completed], dtype=float
        )


@dataclass(frozen=True)
class Comparison:
    """One measure of one ablation against main.

    Attributes
    ----------
    config, measure, unit : str
        The ablation, the measure's label and unit.
    ablation_mean, main_mean : float
        The means over completed laps.
    low, high : float
        The ``LEVEL`` Welch interval of ``ablation_mean - main_mean``.
    """

    config: str
    measure: str
    unit: str
    ablation_mean: float
    main_mean: float
    low: float
    high: float

    @property
    def verdict(self) -> str:
        """How the ablation compares with main beyond the trials' spread.

        ``"worse"`` or ``"better"`` when the whole interval lies on one side of zero, else
        ``"indistinguishable"`` (every measure here is better when smaller).
        """
        if self.low > 0.0:
            return "worse"
        if self.high < 0.0:
            return "better"
        return "indistinguishable"


def _drive(spec: LapSpec, seed: int) -> LapMetrics:
    """One seeded lap's metrics (module level, so that process pools can pickle it)."""
    return drive_lap(spec, seed=seed).metrics


def stress_run(
    track: str | Track = "expressway",
    grip_margin: float = 0.0,
    seeds: int | Iterable[int] = 10,
    configs: Sequence[str] = STRESS_CONFIGS,
    executor: Executor | None = None,
) -> StressResult:
    """Plan once at ``grip_margin`` and drive the plan with each configuration over ``seeds``.

    Parameters
    ----------
    track : str or Track
        The circuit (a built-in name, a CSV path or a Track).
    grip_margin : float
        Share of the identified friction the plan leaves unused, in [0, 0.5); 0 plans at the
        model's full ellipse (the pipeline plans with
        :data:`racing_lib.model.identified.GRIP_MARGIN`).
    seeds : int or iterable of int
        Seeds of the car's per-trial randomness: ``n`` means seeds ``0 .. n-1``. Every
        configuration drives the same seeds.
    configs : sequence of str
        Configurations of :data:`racing_lib.experiments.configs.TUNING_CONFIGS` that share the
        time-optimal plan of the full model; each drives with its own tuned weights. Must
        include ``"main"``, against which the others are weighed.
    executor : Executor, optional
        Where to run the laps (a ``ProcessPoolExecutor``, a Dask client's executor); serial when
        omitted.

    Returns
    -------
    StressResult
    """
    if not 0.0 <= grip_margin < 0.5:
        raise ArgumentError(f"grip_margin {grip_margin!r} must be in [0, 0.5) (a share, not a %)")
    unknown = [c for c in configs if c not in TUNING_CONFIGS]
    if unknown or "main" not in configs:
        raise ArgumentError(
            f"configs {list(configs)!r} must include 'main' and name only configurations of "
            f"TUNING_CONFIGS ({', '.join(TUNING_CONFIGS)}); unknown: {unknown}"
        )
    shared = [c for c in configs if TUNING_CONFIGS[c]["method"] != "time-optimal"]
    shared += [c for c in configs if TUNING_CONFIGS[c]["options"]]
    if shared:
        raise ArgumentError(
            f"configurations {shared} plan differently from main; the stress setting compares "
            "controllers on one plan (use run_ablation for the planning rows)"
        )
    seed_list = list(range(seeds)) if isinstance(seeds, int) else [int(s) for s in seeds]
    if not seed_list:
        raise ArgumentError("seeds is empty: give a number of seeds or a list of them")
    circuit = load_track(track) if not isinstance(track, Track) else track
    model = identified_model().replace(grip_margin=grip_margin)
    # Every configuration here plans like main (checked above): one plan serves them all.
    trajectory = config_plan("main", circuit, model).trajectory
    laps = {}
    for config in configs:
        spec = config_spec(
            config, circuit, model, trajectory=trajectory, weights=tuned_weights(config)
        )
        laps[config] = run_trials(functools.partial(_drive, spec), seed_list, executor)
    return StressResult(circuit.name, grip_margin, float(trajectory.lap_time), laps)


def compare_to_main(result: StressResult, level: float = LEVEL) -> list[Comparison]:
    """Every measure of every ablation against main, with its Welch interval."""
    out = []
    for config in result.laps:
        if config == "main":
            continue
        for field, label, unit in MEASURES:
            ablation, main = result.values(config, field), result.values("main", field)
            if ablation.size == 0 or main.size == 0:
                continue
            low, high = welch_interval(ablation, main, level)
            out.append(
                Comparison(
                    config, label, unit, float(ablation.mean()), float(main.mean()), low, high
                )
            )
    return out


def stress_table(result: StressResult) -> tuple[list[str], list[list[str]]]:
    """Header and rows of a summary: one row per configuration (means over the seeds).

    Returns
    -------
    (list of str, list of list of str)
        For :class:`racing_lib.face.notebook.Table`.
    """
    header = [
        "configuration",
        "laps completed",
        "lap (s)",
        "behind the plan",
        "v_x MAE (m/s)",
        "e_y MAE (m)",
        "wall contacts",
        "off track (s)",
    ]
    rows = []
    for config, laps in result.laps.items():
        lap = result.values(config, "lap_time_s")
        mean = float(lap.mean()) if lap.size else float("nan")
        spread = f" ± {lap.std(ddof=1):.2f}" if lap.size > 1 else ""
        rows.append(
            [
                config,
                f"{lap.size}/{len(laps)}",
                f"{mean:.2f}{spread}",
                f"{100 * (mean / result.planned_lap_s - 1):+.1f} %",
                f"{np.mean([m.vx_mae_mps for m in laps]):.2f}",
                f"{np.mean([m.ey_mae_m for m in laps]):.2f}",
                str(sum(m.wall_contacts for m in laps)),
                f"{sum(m.offtrack_time_s for m in laps):.1f}",
            ]
        )
    return header, rows
