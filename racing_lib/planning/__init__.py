"""Trajectory planning: speed profiles, the curvature QP and the time-optimal NLP.

Trajectory planning (taught in notebook 03): speed profiles, the curvature QP and the
time-optimal NLP.

Every planner returns a :class:`Trajectory`; :func:`plan` is the one entry point the command line
uses.

Examples
--------
>>> from racing_lib.tracks import load_track
>>> from racing_lib.planning import plan
>>> result = plan(load_track("expressway"), method="centerline")
>>> result.trajectory.method
'centerline'
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from racing_lib.errors import PlanningError, checked_arguments
from racing_lib.geometry import Track
from racing_lib.model.car_model import CarModel
from racing_lib.model.identified import GRIP_MARGIN, identified_model
from racing_lib.planning.curvature import solve_curvature
from racing_lib.planning.curvature_settings import CurvatureResult, CurvatureSettings
from racing_lib.planning.grid import TrackGrid
from racing_lib.planning.speed import SpeedProfile, speed_profile
from racing_lib.planning.time_optimal import (
    DEFAULT_START,
    STARTS,
    TimeOptimalResult,
    TimeOptimalSettings,
    solve_time_optimal,
)
from racing_lib.planning.trajectory import Trajectory

METHODS = ("centerline", "curvature", "time-optimal")
#: Above this many nodes a plan warns of its size before it starts (18 km at the 3 m spacing).
LARGE_PLAN_NODES = 6000
#: Rough cost of the time-optimal NLP per node, measured on two cores: seconds and megabytes.
NLP_SECONDS_PER_NODE = 0.02
NLP_MEGABYTES_PER_NODE = 0.33


class LargePlanWarning(UserWarning):
    """A plan with many nodes: it will take minutes and gigabytes."""


@dataclass
class PlanResult:
    """What :func:`plan` returns: the trajectory and how it was found.

    Attributes
    ----------
    trajectory : Trajectory
        The plan.
    method : str
        ``'centerline'``, ``'curvature'`` or ``'time-optimal'``.
    success : bool
        The planner converged.
    status : str
        The solver's status ('ok' for the centerline).
    iterations : int
        QPs (curvature) or IPOPT iterations (time-optimal; 0 for the centerline).
    solve_time : float
        Wall time of the planning, s.
    details : object
        The planner's own result (:class:`CurvatureResult`, :class:`TimeOptimalResult`) or None.
    """

    trajectory: Trajectory
    method: str
    success: bool
    status: str
    iterations: int
    solve_time: float
    details: Any = field(default=None, repr=False)

    @property
    def lap_time(self) -> float:
        """Planned lap time, s."""
        return self.trajectory.lap_time

    def summary(self, track: Track | None = None) -> dict[str, str | int | float | None]:
        """The fields of ``racing-lib plan --json``."""
        traj = self.trajectory
        return {
            "track": getattr(track, "name", None) or traj.track_name,
            "method": self.method,
            "length_m": float(getattr(track, "length", traj.length)),
            "nodes": traj.n,
            "lap_time_s": float(traj.lap_time),
            "solve_time_s": float(self.solve_time),
            "iterations": int(self.iterations),
            "status": str(self.status),
        }


def _warn_if_large(track: Track, method: str, spacing: float, say: Callable[[str], None]) -> None:
    """Warn before a plan that will take minutes and gigabytes, with the way to shrink it."""
    nodes = int(track.length / spacing)
    if nodes <= LARGE_PLAN_NODES or method == "centerline":
        return
    message = (
        f"track {track.name!r} is {track.length / 1000:.1f} km long: {nodes} nodes at "
        f"{spacing:g} m spacing. The time-optimal NLP will take roughly "
        f"{nodes * NLP_SECONDS_PER_NODE / 60:.0f} min and "
        f"{nodes * NLP_MEGABYTES_PER_NODE / 1024:.1f} GB of memory; a coarser grid "
        f"(spacing={2 * spacing:g}, on the command line --spacing {2 * spacing:g}) halves both."
    )
    warnings.warn(message, LargePlanWarning, stacklevel=3)
    say(f"warning: {message}")


@checked_arguments
def plan(
    track: Track,
    method: str = "time-optimal",
    model: CarModel | None = None,
    *,
    spacing: float = 3.0,
    start: str = DEFAULT_START,
    curvature_settings: CurvatureSettings | None = None,
    time_optimal_settings: TimeOptimalSettings | None = None,
    report: Callable[[str], None] | None = None,
) -> PlanResult:
    """Plan a flying lap of ``track`` with one of the three methods.

    Parameters
    ----------
    track : Track
        The track.
    method : {'centerline', 'curvature', 'time-optimal'}
        ``centerline``: the centerline at its speed profile; ``curvature``: the iterated
        curvature-optimal QP; ``time-optimal``: the minimum-lap-time NLP.
    model : CarModel, optional
        The model to plan with: parameters, effects and margins (default:
        :func:`racing_lib.model.identified.identified_model`, the shipped fit with a grip margin
        of :data:`~racing_lib.model.identified.GRIP_MARGIN`). The planner sees the parameters
        with the grip margin applied (:meth:`CarModel.planning_params`), keeps the model's
        edge margin, when it has one, and its top speed ``v_top`` (unless the settings give one);
        the plan carries the model, so an MPC that tracks it predicts with the same one.
    spacing : float
        Node spacing along the centerline, m (overrides the settings' spacing).
    start : {'cold', 'warm'}
        Start of the time-optimal NLP: ``'cold'`` (default, :data:`DEFAULT_START`), the
        centerline at 10 m/s; ``'warm'``, the curvature QP's plan first (the paper's two-stage
        planner). Both reach the same lap; the cold start is faster, as it skips the QP.
    curvature_settings, time_optimal_settings : optional
        Planner settings.
    report : callable, optional
        Called with one line of text as each stage starts (for example ``print``), and with the
        size estimate of a large plan.

    Returns
    -------
    PlanResult

    Raises
    ------
    PlanningError
        Unknown method, or a planner that fails (the message names the solver and its status).

    Warns
    -----
    LargePlanWarning
        More than :data:`LARGE_PLAN_NODES` nodes: the estimated time and memory, and the way to
        make the plan smaller (a larger ``spacing``).
    """
    t0 = time.perf_counter()
    if not isinstance(track, Track):
        raise PlanningError(
            f"plan needs a racing_lib Track, got {type(track).__name__}; load one with "
            "racing_lib.tracks.load_track('expressway') or load_track('my_circuit.csv')."
        )
    if not (isinstance(spacing, int | float) and 0.5 <= spacing <= 20.0):
        raise PlanningError(
            f"spacing must be a node spacing between 0.5 and 20 m, got {spacing!r} (the "
            "planners are tuned for 3 m)."
        )
    if start not in STARTS:
        raise PlanningError(f"start must be {' or '.join(map(repr, STARTS))}, got {start!r}.")
    key = str(method).strip().lower().replace("_", "-")
    if key in ("time-optimal", "timeoptimal", "nlp", "min-time"):
        key = "time-optimal"
    if key not in METHODS:
        raise PlanningError(f"unknown planning method {method!r}; use one of {', '.join(METHODS)}.")
    if model is None:
        model = identified_model()
    elif not isinstance(model, CarModel):
        raise PlanningError(
            f"model must be a racing_lib.model.CarModel, got {type(model).__name__}; for "
            "parameters alone use CarModel(params) (racing_lib.model)."
        )
    say = report or (lambda _line: None)
    _warn_if_large(track, key, spacing, say)
    params, options = model.planning_params(), model.options
    if key == "centerline":
        traj = Trajectory.from_centerline(
            track, params, options=options, spacing=spacing, v_top=model.v_top
        )
        return PlanResult(traj.with_model(model), key, True, "ok", 0, time.perf_counter() - t0)
    cs = _with_grid(curvature_settings or CurvatureSettings(), spacing, model)
    if key == "curvature" or start == "warm":
        say(f"curvature QP on {track.name} ({track.length / spacing:.0f} nodes) ...")
    if key == "curvature":
        res = solve_curvature(track, params, options, cs)
        return PlanResult(
            res.trajectory.with_model(model),
            key,
            res.success,
            res.status,
            res.iterations,
            res.solve_time,
            res,
        )
    ts = _with_grid(time_optimal_settings or TimeOptimalSettings(), spacing, model)
    say(f"time-optimal NLP ({start} start; IPOPT, up to {ts.max_iter} iterations) ...")
    res = solve_time_optimal(track, params, options, ts, start=start, curvature_settings=cs)
    if res.trajectory is None:
        raise PlanningError(
            f"time-optimal NLP on track {track.name!r}: IPOPT returned '{res.status}' and no "
            "usable trajectory. Try: more iterations (TimeOptimalSettings.max_iter; on the "
            "command line --max-iter), or another node spacing (--spacing)."
        )
    return PlanResult(
        res.trajectory.with_model(model),
        key,
        res.success,
        res.status,
        res.iterations,
        time.perf_counter() - t0,
        res,
    )


_Settings = TypeVar("_Settings", CurvatureSettings, TimeOptimalSettings)


def _with_grid(settings: _Settings, spacing: float, model: CarModel) -> _Settings:
    """Planner settings with the node spacing (m) and the model's margin and top speed.

    The model's edge margin (m) and slip margin (a share of the tyres' peak force) apply if it
    has them; its top speed (m/s) and its lateral stability margin (1/s, when it has one) where
    the settings leave them open.
    """
    changes: dict[str, float] = {"spacing": spacing}
    if model.edge_margin is not None:
        changes["margin"] = model.edge_margin
    if model.slip_share is not None and isinstance(settings, TimeOptimalSettings):
        changes["slip_force_share"] = model.slip_share
    if model.lateral_stability is not None and isinstance(settings, TimeOptimalSettings):
        if settings.lateral_stability is None:
            changes["lateral_stability"] = model.lateral_stability
        if settings.steer_rate is None and math.isfinite(model.steer_rate_max):
            changes["steer_rate"] = model.steer_rate_max
    if settings.v_top is None:
        changes["v_top"] = model.v_top
    return dataclasses.replace(settings, **changes)


__all__ = [
    "DEFAULT_START",
    "STARTS",
    "GRIP_MARGIN",
    "LARGE_PLAN_NODES",
    "METHODS",
    "LargePlanWarning",
    "CurvatureResult",
    "CurvatureSettings",
    "PlanResult",
    "SpeedProfile",
    "TimeOptimalResult",
    "TimeOptimalSettings",
    "TrackGrid",
    "Trajectory",
    "plan",
    "solve_curvature",
    "solve_time_optimal",
    "speed_profile",
]
