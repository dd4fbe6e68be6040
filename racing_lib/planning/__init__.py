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

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from racing_lib.errors import PlanningError, checked_arguments
from racing_lib.planning.curvature import (
    CurvatureResult,
    CurvatureSettings,
    TrackGrid,
    solve_curvature,
)
from racing_lib.planning.speed import SpeedProfile, speed_profile
from racing_lib.planning.time_optimal import (
    DEFAULT_START,
    STARTS,
    TimeOptimalResult,
    TimeOptimalSettings,
    solve_time_optimal,
)
from racing_lib.planning.trajectory import Trajectory

if TYPE_CHECKING:
    from racing_lib.model.params import ModelParams

METHODS = ("centerline", "curvature", "time-optimal")

#: Share of the tyres' identified friction a plan leaves unused (dimensionless). A plan on the
#: model's limit asks the simulated car for grip it has only in pure slip: its tyres lose lateral
#: grip under braking (ABS) and to the load transfer, which the planning model knows nothing of.
#: Measured on the expressway with the coupled MPC (default weights, two seeds): planned on the
#: limit, the car drove 2.5 % over its plan and touched a wall; with 5 % kept, 0.8 % over and
#: clean, and the driven lap was 0.8 s faster.
GRIP_MARGIN = 0.05
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

    def summary(self, track: Any = None) -> dict[str, Any]:
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


def _warn_if_large(track: Any, method: str, spacing: float, say: Callable[[str], None]) -> None:
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
    track: Any,
    method: str = "time-optimal",
    params: ModelParams | None = None,
    options: Any = None,
    *,
    spacing: float = 3.0,
    start: str = DEFAULT_START,
    grip_margin: float = GRIP_MARGIN,
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
    params : ModelParams, optional
        Planning model parameters (default: the identified set,
        :func:`racing_lib.model.identified.identified_params`).
    options : ModelOptions, optional
        Model effects (default ``ModelOptions()``).
    spacing : float
        Node spacing along the centerline, m (overrides the settings' spacing).
    start : {'cold', 'warm'}
        Start of the time-optimal NLP: ``'cold'`` (default, :data:`DEFAULT_START`), the
        centerline at 10 m/s; ``'warm'``, the curvature QP's plan first (the paper's two-stage
        planner). Both reach the same lap; the cold start is faster, as it skips the QP.
    grip_margin : float
        Share of the friction coefficient the plan leaves unused, in [0, 0.5) (default
        :data:`GRIP_MARGIN`): the planner sees ``mu (1 - grip_margin)``. 0 plans on the model's
        limit.
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
    import dataclasses

    from racing_lib.geometry import Track

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
    if not 0.0 <= grip_margin < 0.5:
        raise PlanningError(
            f"grip_margin must be in [0, 0.5) (a share of the friction), got {grip_margin!r}."
        )
    say = report or (lambda _line: None)
    _warn_if_large(track, key, spacing, say)
    if params is None:
        from racing_lib.model.identified import identified_params

        params = identified_params()
    if grip_margin:
        params = params.replace(mu=params.mu * (1.0 - grip_margin))
    if key == "centerline":
        traj = Trajectory.from_centerline(track, params, options=options, spacing=spacing)
        return PlanResult(traj, key, True, "ok", 0, time.perf_counter() - t0)
    cs = dataclasses.replace(curvature_settings or CurvatureSettings(), spacing=spacing)
    if key == "curvature" or start == "warm":
        say(f"curvature QP on {track.name} ({track.length / spacing:.0f} nodes) ...")
    if key == "curvature":
        res = solve_curvature(track, params, options, cs)
        return PlanResult(
            res.trajectory, key, res.success, res.status, res.iterations, res.solve_time, res
        )
    ts = dataclasses.replace(time_optimal_settings or TimeOptimalSettings(), spacing=spacing)
    say(f"time-optimal NLP ({start} start; IPOPT, up to {ts.max_iter} iterations) ...")
    res = solve_time_optimal(track, params, options, ts, start=start, curvature_settings=cs)
    if res.trajectory is None:
        raise PlanningError(
            f"time-optimal NLP on track {track.name!r}: IPOPT returned '{res.status}' and no "
            "usable trajectory. Try: more iterations (TimeOptimalSettings.max_iter; on the "
            "command line --max-iter), or another node spacing (--spacing)."
        )
    return PlanResult(
        res.trajectory,
        key,
        res.success,
        res.status,
        res.iterations,
        time.perf_counter() - t0,
        res,
    )


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
