"""The whole pipeline in one call: track -> plan -> (tuned) controller -> closed-loop laps.

:func:`race` strings together what the chapters build one at a time: it loads a track
(:func:`racing_lib.tracks.load_track`), plans a lap (:func:`racing_lib.planning.plan`), picks the
MPC weights that CMA-ES tuned for that set-up
(:func:`racing_lib.experiments.configs.configuration_name`,
:func:`racing_lib.experiments.configs.tuned_weights`), and drives seeded flying laps of the
simulated car (:class:`racing_lib.experiments.lap.LapSpec`,
:func:`racing_lib.experiments.lap.drive_lap`). It adds no algorithm of its own. Taught in notebook
00 (the introduction); ``racing-lib lap`` does the same from the command line.

Examples
--------
The paper's main experiment on the default track (a few seconds, most of it the planning):

>>> from racing_lib.experiments.pipeline import race
>>> result = race("expressway", method="time-optimal", controller="coupled-mpc")
>>> print(result.table())  # doctest: +ELLIPSIS
expressway: 1 lap of the simulated car
  plan                  time-optimal, Solve_Succeeded, ... iterations, ... s
  controller            coupled-mpc, weights tuned for 'main'
  reference lap time    ... s
  closed-loop lap time  ... s, ... % on the reference
  laps completed        1 of 1
...
>>> result.completed, abs(result.lap_time_gap) < 2.0  # within 2 % of the plan's lap time
(True, True)

A quick one (a few seconds):

>>> result = race("expressway", method="centerline", controller="nominal")
>>> result.completed, result.plan.method
(True, 'centerline')
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any

import numpy as np

from racing_lib.control import ControllerKind, controller_kind
from racing_lib.errors import ArgumentError, ControlError, checked_arguments
from racing_lib.experiments.configs import configuration_name, tuned_weights
from racing_lib.experiments.lap import (
    LapMetrics,
    LapResult,
    LapSpec,
    PlantFactory,
    drive_lap,
    summarize,
)
from racing_lib.geometry import Track
from racing_lib.model import CarModel, ModelMismatchWarning, identified_model
from racing_lib.planning import PlanResult, Trajectory, plan
from racing_lib.tracks import load_track

#: Values of ``race(weights=...)`` that name a choice rather than give the weights.
WEIGHT_CHOICES = ("tuned", "default")
#: What ``racing-lib lap --json`` prints (:meth:`RaceResult.summary`): track, controller, planned
#: lap time, one dict of lap metrics per trial and their summary; a JSON object of numbers,
#: strings, None and nested objects, hence ``Any``.
LapSummary = dict[str, Any]


@dataclass
class RaceResult:
    """What :func:`race` returns: the plan, the lap specification and the laps driven.

    Attributes
    ----------
    track : Track
        The track driven.
    plan : PlanResult or None
        The planner's result; None when a ready-made reference was given to :func:`race`.
    spec : LapSpec
        The lap as driven (track, reference, controller, weights, model); pass it to
        :func:`racing_lib.experiments.lap.drive_lap` to drive it again.
    laps : list of LapResult
        One lap per seed, in the order of :attr:`seeds`.
    weights_source : str
        Where the controller's weights came from, in words (for example
        ``"tuned for 'main'"`` or ``"defaults"``).
    configuration : str or None
        The entry of :data:`racing_lib.experiments.configs.TUNING_CONFIGS` this set-up corresponds
        to.
    """

    track: Track
    plan: PlanResult | None
    spec: LapSpec
    laps: list[LapResult] = field(repr=False)
    weights_source: str = "defaults"
    configuration: str | None = None

    # -- shortcuts -------------------------------------------------------------------------------
    @property
    def lap(self) -> LapResult:
        """The first lap (the only one unless ``trials > 1``)."""
        return self.laps[0]

    @property
    def metrics(self) -> LapMetrics:
        """Metrics of the first lap."""
        return self.laps[0].metrics

    @property
    def reference(self) -> Trajectory:
        """The trajectory the controller tracked.

        The trajectory the controller tracked (the plan; for the nominal controller a slower
        copy of it).
        """
        return self.spec.trajectory

    @property
    def planned_lap_time(self) -> float:
        """Lap time of the reference the controller tracked, s (equal to the plan's for MPCs)."""
        return float(self.spec.trajectory.lap_time)

    @property
    def seeds(self) -> list[int | None]:
        """The seeds of the laps, in order."""
        return [lap.metrics.seed for lap in self.laps]

    @property
    def completed(self) -> bool:
        """True when every lap was completed."""
        return all(lap.metrics.completed for lap in self.laps)

    @property
    def lap_time_gap(self) -> float:
        """Mean closed-loop lap time over the reference's, minus one, % (NaN if none completed)."""
        stats = summarize(lap.metrics for lap in self.laps)
        if not stats["completed"]:
            return math.nan
        return 100.0 * (float(stats["lap_time_mean_s"]) / self.planned_lap_time - 1.0)

    # -- reports ---------------------------------------------------------------------------------
    def summary(self) -> LapSummary:
        """The fields of ``racing-lib lap --json``.

        Returns
        -------
        LapSummary
            ``track``, ``controller``, ``planned_lap_time_s`` (of the reference tracked, s),
            ``trials`` (one dict of :class:`~racing_lib.experiments.lap.LapMetrics` fields per lap,
            without the controller's counters) and ``summary`` (lap-time mean, std and best over
            the completed laps, s, and their number); values of laps not completed are None.
        """
        metrics = [lap.metrics for lap in self.laps]
        trials = []
        for m in metrics:
            fields = m.to_dict()
            fields.pop("controller_stats", None)
            trials.append(fields)
        return {
            "track": self.track.name,
            "controller": self.spec.controller,
            "planned_lap_time_s": self.planned_lap_time,
            "trials": trials,
            "summary": summarize(metrics),
        }

    def table(self) -> str:
        """A short plain-text table of what the laps achieved (one row per quantity).

        With several trials, errors are averaged over the laps and lap times summarized as
        mean +- std (best), over the completed laps.
        """
        metrics = [lap.metrics for lap in self.laps]
        stats = summarize(metrics)
        n = len(metrics)
        method = self.plan.method if self.plan is not None else (self.reference.method or "given")
        rows: list[tuple[str, str]] = []
        if self.plan is not None:
            rows.append(
                (
                    "plan",
                    f"{method}, {self.plan.status}, {self.plan.iterations} iterations, "
                    f"{self.plan.solve_time:.1f} s",
                )
            )
        rows.append(("controller", f"{self.spec.controller}, weights {self.weights_source}"))
        rows.append(("reference lap time", f"{self.planned_lap_time:.2f} s"))
        if stats["completed"]:
            mean = float(stats["lap_time_mean_s"])
            lap_text = (
                f"{mean:.2f} s"
                if n == 1
                else f"{mean:.2f} +- {stats['lap_time_std_s']:.2f} s "
                f"(best {stats['lap_time_min_s']:.2f} s)"
            )
            rows.append(
                ("closed-loop lap time", f"{lap_text}, {self.lap_time_gap:+.1f} % on the reference")
            )
        rows.append(("laps completed", f"{stats['completed']} of {n}"))

        def avg(name: str) -> float:
            return float(np.nanmean([getattr(m, name) for m in metrics]))

        vx_err = f"{avg('vx_mae_mps'):.2f} / {avg('vx_max_err_mps'):.2f} m/s"
        rows.append(("v_x error mean / max", vx_err))
        rows.append(("e_y error mean / max", f"{avg('ey_mae_m'):.2f} / {avg('ey_max_m'):.2f} m"))
        walls = sum(m.wall_contacts for m in metrics)
        wall_time = sum(m.wall_contact_time_s for m in metrics)
        rows.append(("wall contacts", f"{walls} ({wall_time:.1f} s in contact)"))
        if self.track.boundary == "open":
            rows.append(("time off the track", f"{sum(m.offtrack_time_s for m in metrics):.1f} s"))
        rows.append(
            (
                "controller step",
                f"{avg('solve_time_ms_median'):.1f} ms median, "
                f"{avg('solve_time_ms_p99'):.1f} ms p99 (period 100 ms)",
            )
        )
        width = max(len(k) for k, _ in rows)
        car = self.spec.car
        car = "the simulated car" if car is None else getattr(car, "__name__", None) or str(car)
        title = f"{self.track.name}: {n} lap{'s' if n > 1 else ''} of {car}"
        return "\n".join([title] + [f"  {k:<{width}}  {v}" for k, v in rows])

    def __str__(self) -> str:
        return self.table()


def _resolve_weights(
    weights: str | Mapping[str, float] | None,
    kind: ControllerKind,
    method: str,
    model: CarModel,
    smooth_transition: bool,
) -> tuple[dict[str, float] | None, str, str | None]:
    """The MPC weights to drive with, a description of where they came from, and the config."""
    config = configuration_name(kind.name, method, model.options, smooth_transition)
    if not kind.takes_weights:
        return None, f"not used (the {kind.name} controller has no MPC weights)", config
    if weights is None or weights == "default":
        return None, "defaults", config
    if weights == "tuned":
        tuned = tuned_weights(config) if config else None
        if tuned:
            return tuned, f"tuned for '{config}'", config
        why = f"none shipped for '{config}'" if config else "no tuned configuration matches"
        return None, f"defaults ({why})", config
    return {str(k): float(v) for k, v in weights.items()}, "given", config


def check_speed_scale(speed_scale: float) -> float:
    """``speed_scale`` as a float in (0, 1], or :class:`ArgumentError` naming the range."""
    if isinstance(speed_scale, bool) or not isinstance(speed_scale, Real):
        raise ArgumentError(f"speed_scale must be a number in (0, 1], got {speed_scale!r}.")
    if not 0.0 < speed_scale <= 1.0:
        raise ArgumentError(f"speed_scale must be in (0, 1], got {speed_scale!r}.")
    return float(speed_scale)


def _check_choices(
    controller: str,
    weights: str | Mapping[str, float] | None,
    model: CarModel | None,
    reference: Trajectory | str | os.PathLike[str] | None,
    trials: int,
    seed: int,
) -> ControllerKind:
    """Refuse bad names and numbers before any planning (which can take tens of seconds)."""
    kind = controller_kind(controller)
    if reference is not None and not isinstance(reference, Trajectory | str | os.PathLike):
        raise ArgumentError(
            f"reference must be a planned Trajectory or the path of a plan file, got "
            f"{type(reference).__name__}; make one with racing_lib.planning.plan(track) or "
            "`racing-lib plan --out PLAN.csv`."
        )
    if model is not None and not isinstance(model, CarModel):
        raise ArgumentError(
            f"model must be a racing_lib.model.CarModel, got {type(model).__name__}; for "
            "parameters alone use CarModel(params)."
        )
    if isinstance(weights, str) and weights not in WEIGHT_CHOICES:
        raise ControlError(
            f"weights={weights!r} is not a choice; use 'tuned' (the shipped CMA-ES weights), "
            "'default' (the MPC's defaults) or a dict such as {'w_ey': 5.0}."
        )
    if weights is not None and not isinstance(weights, str | Mapping):
        raise ControlError(
            f"weights must be 'tuned', 'default', None or a dict, got {type(weights).__name__}."
        )
    if isinstance(weights, Mapping) and not kind.takes_weights:
        raise ControlError(
            f"the {kind.name} controller takes no MPC weights; drop weights= or use an MPC "
            "controller."
        )
    if isinstance(trials, bool) or not isinstance(trials, Integral) or trials < 1:
        raise ArgumentError(f"trials must be a whole number of at least 1, got {trials!r}.")
    if isinstance(seed, bool) or not isinstance(seed, Integral) or seed < 0:
        raise ArgumentError(
            f"seed must be a whole number >= 0 (NumPy seeds cannot be negative), got {seed!r}."
        )
    return kind


def _say_model(trajectory: Trajectory, model: CarModel | None, say: Callable[[str], None]) -> None:
    """Report which model a ready-made plan is driven with, when it is not the plan's own.

    The MPC itself warns of a mismatch (:class:`~racing_lib.model.ModelMismatchWarning`); a
    plan without a model (an old plan file) is driven with the default one, with a warning.
    """
    if trajectory.model is None:
        message = (
            "this plan carries no model (a plan file from before models were stored): it is "
            "driven with the default model, racing_lib.model.identified_model(); re-plan to "
            "record the model it was made with."
        )
        warnings.warn(message, ModelMismatchWarning, stacklevel=4)
        say(f"warning: {message}")
    elif model is not None and trajectory.model.differences(model):
        differ = "; ".join(trajectory.model.differences(model))
        say(f"warning: the plan and the controller use different models ({differ})")


def _lap_line(seed: int | None, m: LapMetrics) -> str:
    lap = f"lap {m.lap_time_s:.2f} s" if m.completed else "lap NOT completed"
    return (
        f"seed {seed}: {lap}, v_x MAE {m.vx_mae_mps:.2f} m/s, e_y MAE {m.ey_mae_m:.2f} m, "
        f"wall contacts {m.wall_contacts}, controller {m.solve_time_ms_median:.2f} ms median"
    )


@checked_arguments
def race(
    track: str | os.PathLike[str] | Track = "expressway",
    method: str = "time-optimal",
    controller: str = "coupled-mpc",
    seed: int = 0,
    weights: str | Mapping[str, float] | None = "tuned",
    *,
    trials: int = 1,
    model: CarModel | None = None,
    car: PlantFactory | None = None,
    speed_scale: float = 1.0,
    smooth_transition: bool = True,
    reference: Trajectory | str | os.PathLike[str] | None = None,
    # Any: passed on to racing_lib.planning.plan, whose keywords have different types.
    plan_kwargs: Mapping[str, Any] | None = None,
    progress: bool = False,
    report: Callable[[str], None] | None = None,
    on_lap: Callable[[LapResult], None] | None = None,
) -> RaceResult:
    """Plan a lap of a track and drive it in closed loop with the simulated car (or another).

    The three modules of the paper in one call: the planning model (identified from driving
    data, chapter 02), the planner (chapters 03-04) and the tracking controller (chapter 05),
    with the weights CMA-ES tuned for this set-up (chapter 06) when the package ships them.

    Parameters
    ----------
    track : str, path or Track
        A built-in track name (``'expressway'``, ``'shortcut'``), a track CSV file, or a Track.
    method : {'time-optimal', 'curvature', 'centerline'}
        The planner (:func:`racing_lib.planning.plan`); ignored when ``reference`` is given.
    controller : {'coupled-mpc', 'decoupled-mpc', 'nominal'}
        The tracking controller. The nominal (pure-pursuit) driver has no model of grip: as on the
        command line, it tracks the plan at its kind's
        :attr:`~racing_lib.control.ControllerKind.speed_scale` of its speed.
    seed : int
        Seed of the first lap's randomness (friction variation, actuation noise); lap ``i`` of
        ``trials`` uses ``seed + i``.
    weights : 'tuned', 'default', None or dict
        MPC weights. ``'tuned'``: the CMA-ES weights shipped for this set-up
        (:func:`racing_lib.experiments.configs.tuned_weights` of
        :func:`~racing_lib.experiments.configs.configuration_name`), the MPC's defaults when none
        are shipped; ``'default'`` or None: the defaults; a dict (fields of ``MPCSettings`` such as
        ``w_ey``): those weights.
    trials : int
        Number of seeded laps.
    model : CarModel, optional
        The model of the planner and of the MPC's prediction: parameters, effects, steering
        actuator and margins. Default: the plan's own model when a ``reference`` carries one,
        else :func:`racing_lib.model.identified_model` (the shipped fit, drag and longitudinal
        weight transfer as in the paper's main experiment, a 5 % grip margin).
    car : callable ``(track, start_speed) -> Plant``, optional
        The car to drive instead of the simulated one (``LapSpec.car``; for a car identified
        and raced in one call see :func:`racing_lib.experiments.own_car.race_car`). Plan it with
        its own identified ``model``.
    speed_scale : float
        Drive the plan at this share of its speeds, in (0, 1] (1: the plan as it is), for a car
        the controller cannot yet hold at the plan's speeds.
    smooth_transition : bool
        MPC: linearize along the blend from the measured state to the plan (the paper's choice).
    reference : Trajectory or path, optional
        A plan made before (a :class:`~racing_lib.planning.Trajectory` or a plan CSV written by
        ``racing-lib plan --out``); the planning step is then skipped.
    plan_kwargs : dict, optional
        More arguments of :func:`racing_lib.planning.plan` (``spacing``, ``start``, solver
        settings).
    progress : bool
        Show a progress bar over each lap.
    report : callable, optional
        Called with one line of text at each step (planning, weights, each lap), for example
        ``print``; silent when omitted.
    on_lap : callable, optional
        Called with each :class:`~racing_lib.experiments.lap.LapResult` as soon as that lap ends,
        for example to save its log, so that an interrupted run of many trials keeps the laps done.

    Returns
    -------
    RaceResult
        The plan, the lap specification and the laps; :meth:`RaceResult.table` summarizes them.

    Raises
    ------
    TrackError
        Unknown track name or an unusable track file (the message lists the built-in tracks).
    PlanningError
        Unknown planning method, or a planner that fails.
    ControlError
        Unknown controller or weights, checked before anything is planned.
    ArgumentError
        ``trials`` below 1, a negative ``seed``, or an argument ``race`` does not have.

    Warns
    -----
    ModelMismatchWarning
        A ``reference`` plan was made with another model than ``model``.
    """
    say = report or (lambda _line: None)
    kind = _check_choices(controller, weights, model, reference, trials, seed)
    speed_scale = check_speed_scale(speed_scale)
    trk = load_track(track)  # a Track is returned as it is; None or a number is refused

    planned: PlanResult | None = None
    if reference is None:
        model = model if model is not None else identified_model()
        say(f"planning {trk.name} ({trk.length:.0f} m) with method '{method}' ...")
        planned = plan(trk, method, model, **dict(plan_kwargs or {}))
        trajectory = planned.trajectory
        plan_method = planned.method
        say(f"planned lap time {trajectory.lap_time:.2f} s ({planned.status})")
    else:
        if isinstance(reference, Trajectory):
            trajectory = reference
        else:
            trajectory = Trajectory.load_csv(os.fspath(reference), track=trk)
            say(f"loaded plan {os.fspath(reference)} (planned lap {trajectory.lap_time:.2f} s)")
        plan_method = trajectory.method or method
        if kind.predicts:
            _say_model(trajectory, model, say)
        if model is None:
            model = trajectory.model if trajectory.model is not None else identified_model()

    reference_tracked = kind.reference(trajectory)
    if reference_tracked is not trajectory:
        say(
            f"{kind.name} controller: reference at {kind.speed_scale:.0%} of the planned speed "
            f"({reference_tracked.lap_time:.2f} s)"
        )
    if speed_scale != 1.0:
        reference_tracked = reference_tracked.scale_speed(speed_scale)
        lap = reference_tracked.lap_time
        say(f"driving at {speed_scale:.0%} of the reference's speeds ({lap:.2f} s)")
    lap_weights, source, config = _resolve_weights(
        weights, kind, plan_method, model, smooth_transition
    )
    if kind.takes_weights:
        say(f"MPC weights: {source}")
    spec = LapSpec(
        track=trk,
        trajectory=reference_tracked,
        controller=kind.name,
        smooth_transition=smooth_transition,
        weights=lap_weights,
        model=model,
        car=car,
    )
    laps = []
    for i in range(int(trials)):
        lap_seed = int(seed) + i
        result = drive_lap(spec, seed=lap_seed, progress=progress)
        say(_lap_line(lap_seed, result.metrics))
        laps.append(result)
        if on_lap is not None:
            on_lap(result)
    return RaceResult(
        track=trk,
        plan=planned,
        spec=spec,
        laps=laps,
        weights_source=source,
        configuration=config,
    )


__all__ = [
    "WEIGHT_CHOICES",
    "LapSummary",
    "ModelMismatchWarning",
    "RaceResult",
    "check_speed_scale",
    "race",
]
