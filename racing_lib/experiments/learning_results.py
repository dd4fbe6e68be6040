"""What the learning loop measured: one iteration's result, and a whole run (chapter 09).

:func:`racing_lib.experiments.learning.learn` returns a :class:`LearningRun` of
:class:`IterationResult`; ``racing-lib learn --json`` prints :meth:`LearningRun.to_dict`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from racing_lib.geometry import Track
from racing_lib.model import CarModel

__all__ = ["IterationResult", "LearningRun", "beyond_text"]


def beyond_text(excess: float | None) -> str:
    """How far laps strayed beyond their edge margins, for a table: "-" when within, else m.

    An excess under a centimetre reads "< 0.01 m", not "0.00 m": the iteration is not within its
    margins (:attr:`IterationResult.within_margins`), however little it strayed.
    """
    if excess is None or excess <= 0.0:
        return "-"
    return "< 0.01 m" if excess < 0.005 else f"{excess:.2f} m"


@dataclass
class IterationResult:
    """One iteration of the loop, as written to its folder and printed by ``racing-lib learn``.

    Attributes
    ----------
    iteration : int
        0 for the model as identified, then 1, 2, ...
    planned_lap_s : float
        The plan's lap time, s.
    driven_lap_s : float or None
        Mean closed-loop lap time over the iteration's completed laps, s.
    driven_lap_std_s : float or None
        Their standard deviation, s.
    gap_to_best_pct : float or None
        ``driven_lap_s`` over the best possible lap, minus one, % (None when unknown).
    walls : int
        Wall contacts over all the iteration's laps.
    offtrack_s : float
        Time off the track over all its laps, s.
    completed : int
        Laps completed (of ``laps``).
    laps : int
        Laps driven.
    ey_max_m : float
        Largest lateral distance to the plan's line over the laps, m.
    prediction_error : dict
        One-period RMS prediction error of ``v_x``, ``v_y`` (m/s^2) and ``r`` (rad/s^2) on this
        iteration's laps, which no correction has seen: ``{"identified": {...}, "learned":
        {...}}`` (``learned`` is None in iteration 0).
    grip_margin : float
        The share of friction the plan left unused.
    edge_margin : float or None
        The largest distance the plan kept from the track's edges, m (None: the planner's
        default); after a clean learned iteration, the margin varies along the track
        (:func:`~racing_lib.experiments.track_margins.planning_track`).
    caution : float
        Factor on the settings' uncertainty and slip margins: 1 in the first learned iteration,
        then halved after a clean iteration (down to
        :data:`~racing_lib.experiments.learning.MIN_CAUTION`) and doubled after one that was not
        clean.
    samples : int
        Residual samples the correction was fitted on (0 in iteration 0).
    wall_time_s : dict
        Seconds spent fitting, planning and driving.
    margin_excess_m : float or None
        How far the laps strayed from their line beyond the edge margin the plan kept there, m
        (:func:`~racing_lib.experiments.track_margins.margin_excess`): zero or less when the
        margin held every excursion. None without a lap.
    """

    iteration: int
    planned_lap_s: float
    driven_lap_s: float | None
    driven_lap_std_s: float | None
    gap_to_best_pct: float | None
    walls: int
    offtrack_s: float
    completed: int
    laps: int
    ey_max_m: float
    prediction_error: dict[str, dict[str, float] | None]
    grip_margin: float
    edge_margin: float | None
    caution: float
    samples: int
    wall_time_s: dict[str, float] = field(default_factory=dict)
    margin_excess_m: float | None = None

    @property
    def clean(self) -> bool:
        """Every lap completed, without wall contact or time off the track."""
        return self.completed == self.laps and self.walls == 0 and self.offtrack_s == 0.0

    @property
    def within_margins(self) -> bool:
        """Clean, and every lap stayed within the edge margin its plan kept (when measured)."""
        return self.clean and (self.margin_excess_m is None or self.margin_excess_m <= 0.0)


@dataclass
class LearningRun:
    """What :func:`~racing_lib.experiments.learning.learn` returns: iterations, where kept.

    Attributes
    ----------
    track : str
        Name of the track.
    best_possible_lap_s : float or None
        The best possible lap of the simulated car on this track, where racing_lib knows it.
    iterations : list of IterationResult
    models : list of CarModel
        The model each iteration planned and predicted with, correction included.
    plan_tracks : list of Track
        The track each iteration planned on: the track itself, or the track narrowed by the
        tracking errors of the iteration before
        (:func:`~racing_lib.experiments.track_margins.planning_track`).
    out : Path or None
        The folder of the run.
    """

    track: str
    best_possible_lap_s: float | None
    iterations: list[IterationResult]
    models: list[CarModel] = field(default_factory=list, repr=False)
    plan_tracks: list[Track] = field(default_factory=list, repr=False)
    out: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of ``racing-lib learn --json``.

        Each iteration has its fields and ``gain_over_identified_pct`` (:meth:`gain_pct`), the
        measure of a car whose best possible lap nobody knows.
        """
        return {
            "track": self.track,
            "best_possible_lap_s": self.best_possible_lap_s,
            "identified_lap_s": self.identified_lap_s,
            "iterations": [
                {**asdict(it), "gain_over_identified_pct": self.gain_pct(it)}
                for it in self.iterations
            ],
        }

    @property
    def identified_lap_s(self) -> float | None:
        """Iteration 0's driven lap (the model as identified), s; None before or without one."""
        return self.iterations[0].driven_lap_s if self.iterations else None

    def gain_pct(self, it: IterationResult) -> float | None:
        """How much faster ``it`` drove than iteration 0 (the model as identified), %.

        None when either did not complete a lap.
        """
        first = self.identified_lap_s
        if first is None or it.driven_lap_s is None:
            return None
        return 100.0 * (1.0 - it.driven_lap_s / first)

    def best(self) -> IterationResult | None:
        """The run's result: the fastest clean iteration whose laps stayed within their margins.

        A few clean laps that strayed beyond the margin their plan kept were clean by luck
        (:attr:`IterationResult.within_margins`); when no clean iteration stayed within, the
        fastest clean one.
        """
        clean = [it for it in self.iterations if it.clean and it.driven_lap_s is not None]
        held = [it for it in clean if it.within_margins] or clean
        return min(held, key=lambda it: it.driven_lap_s or math.inf) if held else None
