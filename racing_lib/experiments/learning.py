"""Learning from laps: drive, fit a model correction, re-plan, drive again (chapter 09).

The paper closes with learning-based modelling as the way to close the rest of the gap to the
best lap, and its authors' follow-up (Su, Hao et al. 2023) fits Gaussian-process corrections to
the planner's and the controller's model, iterating between driving and fitting. This module is
that loop for any car racing_lib can drive:

* **iteration 0** drives the model as identified, with its blanket margins (the main job);
* **iteration i >= 1** fits a :class:`~racing_lib.model.ModelCorrection` on the clean laps of
  every iteration before it (:func:`racing_lib.model.residuals.fit_correction`), plans with the
  corrected model and drives the plan with the MPC predicting with that same model.

What replaces the blanket margins in a learned iteration:

* the **grip margin** (the same share of the friction everywhere: 5 % for the shipped model, the
  measured error for an identified car) gives way to the correction's own
  uncertainty: the friction ellipse of the plan shrinks by ``uncertainty_margin`` posterior
  standard deviations of the learned accelerations (longitudinal and lateral, each on its axis),
  node by node (:attr:`racing_lib.planning.TimeOptimalSettings.uncertainty_margin`): close to
  the limit where the laps went, away from it where they did not;
* the **edge margin** (0.8 m to a wall) becomes ``edge_margin`` (0.4 m by default), and after a
  clean learned iteration it follows that iteration's laps along the track: where they strayed
  from their line by more than the margin leaves, the next plan is made on a track narrowed to
  keep their largest lateral tracking error within :data:`EXCURSION_WINDOW` of the point plus
  :data:`EDGE_SAFETY` (:func:`planning_track`). The identified model's tracking, and that of an
  iteration that went wrong, say nothing of how closely the corrected model tracks: after those
  the setting alone holds. One excursion in one corner does not widen the margin on every metre
  of the lap, as a margin of the laps' largest error did: on circuits that error came from one
  corner, and the later iterations' plans slowed down everywhere.

* the **slip margin** (the plans keep the tyres' slip angles where they give at most 95 % of their
  peak force: the identified tyre curves are broader than the car's) shrinks with the caution
  below: the learned plans may use ``1 - 5 % caution`` of the peak (:func:`slip_share`);
* the **stability margin** of a car that identification found diverging in yaw under braking
  (``CarModel.lateral_stability``: how much faster it diverged than the identified model said)
  shrinks with the caution as well. Like the slip margin it stands in for an error of the model
  that the laps put to the test; the correction does not remove that error (the BMW's braking
  run, judged again against its learned models, still diverges 1.62-1.69 1/s faster than they
  say, against 1.79 as identified), so what spends the margin is the evidence of clean laps. On
  CommonRoad's BMW a learned model (of the second iteration) planned without it drove clean laps
  1.8 s faster than with it (100.31 s against 102.11 s), where the identified model without it
  touched the wall on every lap.

A lap that touched a wall or left the track is not learned from (its log holds the wall's forces,
not the car's). The factor on these margins (the iteration's *caution*) is set
by how the learned iteration before went: doubled after one that was not clean, halved after a
clean one, down to :data:`MIN_CAUTION`. The MPC predicting with a learned model keeps the front
tyres' slip angle within the plan's slip margin (``CarModel.slip_share``): without that bound,
laps on circuits with hairpins left the track.

The run's result (:meth:`LearningRun.best`) is its fastest clean iteration whose laps stayed
within the edge margins their plan kept (the fastest clean one when none did): four clean laps
that strayed beyond them were clean only because they strayed where their line was not beside a
wall (:func:`~racing_lib.experiments.track_margins.margin_excess`).

Every finished iteration is written to its own folder, with the run's track, settings and model
in ``run.json``, so an interrupted run resumes where it stopped and loses no finished iteration;
a folder of another run is refused.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any
from zipfile import BadZipFile

import numpy as np

from racing_lib.errors import ArgumentError, ModelError, PlanningError
from racing_lib.experiments.ablation.table import known_best_lap
from racing_lib.experiments.lap import LapLog, LapResult, PlantFactory
from racing_lib.experiments.learning_results import IterationResult, LearningRun, beyond_text
from racing_lib.experiments.pipeline import RaceResult, race
from racing_lib.experiments.track_margins import (
    EDGE_SAFETY,
    EXCURSION_WINDOW,
    edge_excursions,
    largest_margin,
    margin_excess,
    planning_track,
)
from racing_lib.geometry import Track
from racing_lib.io import atomic_write_json, jsonable
from racing_lib.model import CarModel, ModelCorrection, identified_model
from racing_lib.model.residuals import (
    ResidualSamples,
    fit_correction,
    one_step_errors,
    residual_samples,
    without_fast_driving,
)
from racing_lib.planning import PlanResult, TimeOptimalSettings, plan
from racing_lib.tracks import load_track

__all__ = [
    "EDGE_SAFETY",
    "EXCURSION_WINDOW",
    "MIN_CAUTION",
    "check_best",
    "IterationResult",
    "LearnSettings",
    "LearningRun",
    "edge_excursions",
    "known_best_lap",
    "learn",
    "planning_track",
    "slip_share",
]

#: Smallest factor on the uncertainty and slip margins that clean iterations may bring the loop to.
MIN_CAUTION = 0.5


@dataclass(frozen=True)
class LearnSettings:
    """How the learning loop drives and fits.

    Attributes
    ----------
    iterations : int
        Learning iterations after iteration 0 (the model as identified).
    seeds : int
        Laps per iteration (seeded, their mean is the iteration's lap time).
    seed : int
        Seed of the first lap; iteration ``i`` drives seeds ``seed + 1000 i + k``.
    uncertainty_margin : float
        Posterior standard deviations of the learned accelerations that the first learned
        iteration's plan keeps inside the friction ellipse; later iterations multiply it by
        their caution (:data:`MIN_CAUTION` to doubled after each iteration that was not clean).
    edge_margin : float
        Distance between the car's side and the track edge in the first learned iteration, and
        after one that was not clean, m (after a clean one: its measured tracking error and
        :data:`EDGE_SAFETY`).
    inducing : int
        Inducing inputs of each GP of the correction.
    min_length : float
        Shortest GP length scale, in standard deviations of each feature.
    top_speed_band : float
        Where the car drives faster than ``(1 - top_speed_band)`` times the model's top speed,
        the laps are not learned from (:func:`racing_lib.model.residuals.without_fast_driving`).
    """

    iterations: int = 5
    seeds: int = 4
    seed: int = 0
    uncertainty_margin: float = 2.0
    edge_margin: float = 0.4
    inducing: int = 40
    min_length: float = 1.0
    top_speed_band: float = 0.02

    def __post_init__(self) -> None:
        checks = (
            ("iterations", self.iterations, 0, "an integer >= 0"),
            ("seeds", self.seeds, 1, "an integer >= 1"),
            ("inducing", self.inducing, 5, "an integer >= 5"),
        )
        for name, value, low, rule in checks:
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ArgumentError(f"LearnSettings.{name} must be {rule}, got {value!r}.")
        for name in ("uncertainty_margin", "edge_margin", "min_length"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ArgumentError(f"LearnSettings.{name} must be a number >= 0, got {value!r}.")
        band = self.top_speed_band
        if not (isinstance(band, int | float) and 0.0 <= band < 0.5):
            raise ArgumentError(f"LearnSettings.top_speed_band must be in [0, 0.5), got {band!r}.")


def _run_identity(
    track: Track, settings: LearnSettings, base: CarModel, car: PlantFactory | None
) -> dict[str, Any]:
    """What a kept run must share with the one that resumes it."""
    return {
        "track": track.checksum(),
        "settings": asdict(settings),
        "model": base.to_dict(),
        "car": None if car is None else repr(car),
    }


def _check_run_folder(out: Path, identity: dict[str, Any]) -> None:
    """Create ``out``, or refuse it when it is a file or holds another run."""
    if out.exists() and not out.is_dir():
        raise ArgumentError(f"--out {out} is a file; name a folder for the run's iterations.")
    out.mkdir(parents=True, exist_ok=True)
    path = out / "run.json"
    if not path.is_file():
        atomic_write_json(path, jsonable(identity))
        return
    try:
        kept = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ArgumentError(f"{path} is damaged ({exc}); start the run in a new folder.") from None
    mine = jsonable(identity)
    # Settings may differ only in how many iterations are asked for: more resumes the run
    same = {k: v for k, v in mine["settings"].items() if k != "iterations"}
    theirs = {k: v for k, v in kept.get("settings", {}).items() if k != "iterations"}
    differ = [k for k in ("track", "model", "car") if kept.get(k) != mine[k]]
    differ += [f"settings.{k}" for k in sorted(same) if theirs.get(k) != same[k]]
    if differ:
        raise ArgumentError(
            f"{out} holds a run with another {', '.join(differ)}; resume it with the same "
            "track, car and settings, or start this run in a new folder."
        )


def _iteration_dir(out: Path, i: int) -> Path:
    return out / f"iteration_{i:02d}"


def _load_done(out: Path, i: int) -> tuple[IterationResult, list[LapLog], CarModel] | None:
    """A finished iteration from its folder, or None when it did not finish."""
    folder = _iteration_dir(out, i)
    summary = folder / "summary.json"
    if not summary.is_file():
        return None
    try:
        data = json.loads(summary.read_text(encoding="utf-8"))
        result = IterationResult(**data["result"])
        logs = [LapLog.load(folder / name) for name in data["clean_logs"]]
        model = CarModel.from_dict(json.loads((folder / "model.json").read_text(encoding="utf-8")))
    except (OSError, ValueError, TypeError, KeyError, EOFError, BadZipFile, ModelError) as exc:
        raise ArgumentError(
            f"{summary} is damaged ({exc}); delete the folder {folder} and every later "
            "iteration's folder to drive them again."
        ) from None
    return result, logs, model


def _clean(lap: LapResult) -> bool:
    """A lap to learn from: completed, no wall contact, never off the track."""
    m = lap.metrics
    return m.completed and m.wall_contacts == 0 and m.offtrack_time_s == 0.0


def _save_done(
    out: Path, result: IterationResult, laps: Sequence[LapResult], model: CarModel
) -> None:
    """Write an iteration's laps, model and summary (the summary last: it marks it done)."""
    folder = _iteration_dir(out, result.iteration)
    folder.mkdir(parents=True, exist_ok=True)
    clean_names = []
    for k, lap in enumerate(laps):
        name = f"lap_{k:02d}.npz"
        lap.log.save(folder / name)
        if _clean(lap):
            clean_names.append(name)
    atomic_write_json(folder / "model.json", model.to_dict())
    atomic_write_json(
        folder / "summary.json", {"result": asdict(result), "clean_logs": clean_names}
    )


def _caution(previous: IterationResult | None) -> float:
    """Factor on the uncertainty and slip margins, set by how the learned iteration before went.

    The laps of an iteration that touched a wall are not learned from, so the next one would fit
    nearly the same correction and make nearly the same plan: after one, the factor doubles and
    the plan keeps farther from what the correction is unsure of. After a clean learned
    iteration it halves, down to :data:`MIN_CAUTION`: the laps showed that the corrected model
    was trusted safely that far. The first learned iteration starts at 1.
    """
    if previous is None or previous.iteration == 0:
        return 1.0
    if previous.clean:
        return max(MIN_CAUTION, 0.5 * previous.caution)
    return 2.0 * previous.caution


def _follows_laps(previous: IterationResult | None) -> bool:
    """Whether the edge margin follows the last iteration's laps (a clean learned one)."""
    return previous is not None and previous.iteration > 0 and previous.clean


def slip_share(caution: float) -> float:
    """The share of the tyres' peak force a learned iteration's slip angles are kept to.

    The planner's margin below the peak (5 %, ``TimeOptimalSettings.slip_force_share``) stands
    in for what the model does not know of the tyres near it. Learned iterations scale it by
    their caution, as they do the uncertainty margin: 5 % in the first (caution 1), 2.5 % at
    :data:`MIN_CAUTION`, twice the last iteration's after one that was not clean (at most 50 %).
    On the expressway, 2.5 % instead of 5 % made the second iteration's plan 0.34 s faster
    (103.26 s), and its laps 0.36 s (103.68 s).

    Parameters
    ----------
    caution : float
        The iteration's factor on its margins (:func:`_caution`), dimensionless.

    Returns
    -------
    float
        Share of the peak force, in [0.5, 1).
    """
    gap = (1.0 - TimeOptimalSettings.slip_force_share) * caution
    return 1.0 - min(gap, 0.5)


def _iteration_model(
    base: CarModel, correction: ModelCorrection | None, settings: LearnSettings, caution: float
) -> CarModel:
    """The model an iteration plans and predicts with: ``base``, or ``base`` corrected.

    A corrected model keeps no blanket grip margin (the plan's uncertainty margin replaces it),
    the settings' edge margin (m), the slip margin of ``caution`` (:func:`slip_share`) and
    ``caution`` times the identified stability margin (1/s), if the car has one.
    """
    if correction is None:
        return base
    stability = base.lateral_stability
    # the least distance to an edge; where the laps strayed further, the track the plan is made
    # on is narrower (planning_track)
    return base.replace(
        params=base.params.replace(correction=correction),
        grip_margin=0.0,
        edge_margin=settings.edge_margin,
        slip_share=slip_share(caution),
        lateral_stability=None if stability is None else stability * caution,
    )


def learn(
    track: str | os.PathLike[str] | Track = "expressway",
    settings: LearnSettings = LearnSettings(),
    *,
    model: CarModel | None = None,
    car: PlantFactory | None = None,
    out: str | os.PathLike[str] | None = None,
    progress: bool = False,
    report: Callable[[str], None] | None = None,
) -> LearningRun:
    """Drive, fit a model correction, re-plan and drive again, ``settings.iterations`` times.

    Parameters
    ----------
    track : str, path or Track
        The track (a built-in name, a track CSV or a Track).
    settings : LearnSettings
        Iterations, laps per iteration, seeds and margins.
    model : CarModel, optional
        The model as identified (default :func:`racing_lib.model.identified_model`); a
        correction it carries is replaced by the learned one.
    car : callable ``(track, start_speed) -> Plant``, optional
        Another car than the simulated one (:attr:`racing_lib.experiments.lap.LapSpec.car`).
    out : path, optional
        Folder that keeps every iteration (laps, model, summary); a run started again with the
        same folder resumes after its last finished iteration. None: nothing is kept.
    progress : bool
        Show a progress bar over the iterations.
    report : callable, optional
        Called with one line of text per iteration.

    Returns
    -------
    LearningRun
    """
    if not isinstance(settings, LearnSettings):
        raise ArgumentError(f"settings must be a LearnSettings, got {type(settings).__name__}.")
    track_obj = track if isinstance(track, Track) else load_track(track)
    base = identified_model() if model is None else model
    if base.params.correction is not None:
        base = base.replace(params=base.params.replace(correction=None))
    out_dir = None if out is None else Path(out)
    if out_dir is not None:
        _check_run_folder(out_dir, _run_identity(track_obj, settings, base, car))
    best = known_best_lap(track_obj) if car is None else None
    say = report or (lambda line: None)
    run = LearningRun(track_obj.name, best, [], out=out_dir)
    samples: list[ResidualSamples] = []
    last_logs: list[LapLog] = []  # the clean laps of the iteration before

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=settings.iterations + 1, desc="learning", unit="iteration")
    for i in range(settings.iterations + 1):
        previous = run.iterations[-1] if run.iterations else None
        plan_track = track_obj
        if _follows_laps(previous) and last_logs:
            plan_track = planning_track(track_obj, last_logs, settings.edge_margin)
        done = None if out_dir is None else _load_done(out_dir, i)
        if done is not None:
            result, new_logs, model = done
            if result.margin_excess_m is None and result.clean:
                # kept before the excess was recorded: a clean iteration keeps all its laps
                excess = margin_excess(new_logs, track_obj, plan_track, model.edge_margin)
                result = replace(result, margin_excess_m=excess)
            say(f"iteration {i}: kept from {_iteration_dir(out_dir, i)}")
        else:
            if out_dir is not None and _load_done(out_dir, i + 1) is not None:
                raise ArgumentError(
                    f"{_iteration_dir(out_dir, i)} is missing but later iterations are kept, "
                    "fitted on its laps; delete the later iterations' folders too."
                )
            result, new_logs, model = _run_iteration(
                i, track_obj, plan_track, base, car, settings, samples, previous, out_dir, best
            )
            say(_line(result))
        run.iterations.append(result)
        run.models.append(model)
        run.plan_tracks.append(plan_track)
        last_logs = new_logs
        samples += [residual_samples(log, track_obj, base) for log in new_logs]
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return run


def _run_iteration(
    i: int,
    track: Track,
    plan_track: Track,
    base: CarModel,
    car: PlantFactory | None,
    settings: LearnSettings,
    samples: Sequence[ResidualSamples],
    previous: IterationResult | None,
    out: Path | None,
    best: float | None,
) -> tuple[IterationResult, list[LapLog], CarModel]:
    """Fit (from iteration 1 on), plan (on ``plan_track``) and drive one iteration."""
    t0 = time.perf_counter()
    correction = None
    n_samples = 0
    if i > 0:
        if not samples:
            raise ModelError(
                "no clean lap to learn from: every lap so far touched a wall or left the track. "
                "Drive the identified model with larger margins first."
            )
        joined = ResidualSamples.concatenate(samples)
        below = base.v_top * (1.0 - settings.top_speed_band)
        n_samples = len(without_fast_driving(joined, below))
        correction = fit_correction(
            joined,
            inducing=settings.inducing,
            min_length=settings.min_length,
            seed=settings.seed,
            label=f"learned from {n_samples} samples, iteration {i}",
            below_speed=below,
        )
    caution = _caution(previous)
    model = _iteration_model(base, correction, settings, caution)
    t1 = time.perf_counter()
    margin = settings.uncertainty_margin * caution
    laps: list[LapResult] = []
    try:
        planned, result = _plan_and_drive(
            track,
            plan_track,
            model,
            margin,
            car=car,
            trials=settings.seeds,
            seed=settings.seed + 1000 * i,
            on_lap=laps.append,
        )
    except PlanningError as exc:
        kept = "" if out is None else f" The iterations before it are kept in {out}."
        what = (
            "the model as identified"
            if correction is None
            else f"its corrected model (uncertainty margin {margin:g} standard deviations, "
            f"edge margin {largest_margin(model.edge_margin, track, plan_track):.2f} m)"
        )
        raise PlanningError(
            f"learning iteration {i} could not plan a lap with {what}.{kept} Keep the best "
            "clean iteration so far, or learn again with fewer iterations or a smaller "
            f"LearnSettings.uncertainty_margin. The planner said: {exc}"
        ) from None
    t2 = time.perf_counter()
    plan_s = float(planned.solve_time)
    metrics = [lap.metrics for lap in result.laps]
    done = [m.lap_time_s for m in metrics if m.completed]
    mean = float(np.mean(done)) if done else None
    held_out = [lap.log for lap in result.laps if lap.metrics.completed]
    errors: dict[str, dict[str, float] | None] = {"identified": None, "learned": None}
    if held_out:
        errors["identified"] = one_step_errors(held_out, track, base)
        if correction is not None:
            errors["learned"] = one_step_errors(held_out, track, model)
    iteration = IterationResult(
        iteration=i,
        planned_lap_s=float(result.planned_lap_time),
        driven_lap_s=mean,
        driven_lap_std_s=float(np.std(done)) if done else None,
        gap_to_best_pct=None if (mean is None or best is None) else 100.0 * (mean / best - 1.0),
        walls=int(sum(m.wall_contacts for m in metrics)),
        offtrack_s=float(sum(m.offtrack_time_s for m in metrics)),
        completed=len(done),
        laps=len(metrics),
        ey_max_m=float(max(m.ey_max_m for m in metrics)),
        prediction_error=errors,
        grip_margin=model.grip_margin,
        edge_margin=largest_margin(model.edge_margin, track, plan_track),
        caution=caution,
        samples=n_samples,
        wall_time_s={"fit": t1 - t0, "plan": plan_s, "laps": t2 - t1 - plan_s},
        margin_excess_m=margin_excess(
            [lap.log for lap in laps], track, plan_track, model.edge_margin
        ),
    )
    if out is not None:
        _save_done(out, iteration, laps, model)
    return iteration, [lap.log for lap in laps if _clean(lap)], model


def _plan_and_drive(
    track: Track,
    plan_track: Track,
    model: CarModel,
    margin: float,
    *,
    car: PlantFactory | None,
    trials: int,
    seed: int,
    on_lap: Callable[[LapResult], None] | None = None,
) -> tuple[PlanResult, RaceResult]:
    """Plan ``model``'s lap on ``plan_track`` and drive it ``trials`` times on ``track``.

    ``margin``: the plan's uncertainty margin, posterior standard deviations.
    """
    settings = TimeOptimalSettings(uncertainty_margin=margin)
    planned = plan(plan_track, "time-optimal", model, time_optimal_settings=settings)
    result = race(
        track,
        model=model,
        car=car,
        trials=trials,
        seed=seed,
        reference=planned.trajectory,
        on_lap=on_lap,
    )
    return planned, result


def check_best(
    run: LearningRun,
    track: str | os.PathLike[str] | Track,
    settings: LearnSettings = LearnSettings(),
    *,
    laps: int = 10,
    seed: int | None = None,
    car: PlantFactory | None = None,
) -> dict[str, Any]:
    """Drive the model of the run's result (:meth:`LearningRun.best`) on seeds no iteration used.

    Re-plans with that model (with the run's ``settings``, its iteration's caution, on the
    track that iteration planned on) and drives ``laps`` seeded laps from ``seed`` on; default:
    the first seed after every iteration's (``settings.seed + 1000 * len(run.iterations)``).

    Returns
    -------
    dict
        ``iteration``, ``seeds``, ``lap_times_s`` (None for a lap not completed), ``walls``,
        ``offtrack_s``.

    Raises
    ------
    ModelError
        The run has no clean iteration.
    """
    best = run.best()
    if best is None:
        raise ModelError("no clean iteration to check: every iteration touched a wall.")
    margin = settings.uncertainty_margin * best.caution
    if seed is None:
        seed = settings.seed + 1000 * len(run.iterations)
    track_obj = load_track(track)
    plan_track = (
        run.plan_tracks[best.iteration] if best.iteration < len(run.plan_tracks) else track_obj
    )
    model = run.models[best.iteration]
    _, result = _plan_and_drive(
        track_obj, plan_track, model, margin, car=car, trials=laps, seed=seed
    )
    metrics = [lap.metrics for lap in result.laps]
    return {
        "iteration": best.iteration,
        "seeds": [m.seed for m in metrics],
        "lap_times_s": [m.lap_time_s if m.completed else None for m in metrics],
        "walls": int(sum(m.wall_contacts for m in metrics)),
        "offtrack_s": float(sum(m.offtrack_time_s for m in metrics)),
    }


def _line(it: IterationResult) -> str:
    """One line for people about an iteration."""
    driven = "not completed" if it.driven_lap_s is None else f"{it.driven_lap_s:.2f} s"
    gap = "" if it.gap_to_best_pct is None else f" ({it.gap_to_best_pct:+.2f} % on the best lap)"
    excess = beyond_text(it.margin_excess_m)
    beyond = "" if excess == "-" else f", {excess} beyond its edge margins"
    return (
        f"iteration {it.iteration}: plan {it.planned_lap_s:.2f} s, driven {driven}{gap}, "
        f"{it.walls} wall contacts, {it.offtrack_s:.1f} s off track{beyond}, "
        f"{sum(it.wall_time_s.values()):.0f} s"
    )
