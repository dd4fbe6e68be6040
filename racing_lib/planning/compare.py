"""Comparing plans: lap time of any line under a model, time gaps, corner lines (notebooks 03, 04).

The planners each report their own lap time, computed with their own assumptions: the curvature QP
drives its line at the quasi-steady speed profile, the NLP at the speeds it optimized with the
bicycle model. To compare lines fairly, or to ask how much of the NLP's gain comes from the line and
how much from the way it is driven, this module

* drives **any closed line** at its quasi-steady speed profile for a given parameter set and model
  options (:func:`speed_profile_trajectory`, :func:`line_lap_time`);
* measures where along the track one plan gains time on another (:func:`time_gap`);
* summarizes plans (:func:`compare_plans`) and their line through each corner
  (:func:`corner_summary`: entry, apex and exit offsets, positive towards the inside of the corner,
  so that an out-in-out line reads negative, positive, negative).

Taught in notebook 03 (section 5) and notebook 04 (sections 5 and 6).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Protocol, TypeAlias

import numpy as np
from numpy.typing import ArrayLike

from racing_lib.errors import PlanningError
from racing_lib.geometry import Corner, Path, Track
from racing_lib.model import ModelOptions, ModelParams
from racing_lib.planning.trajectory import Trajectory, model_inputs


class HasXY(Protocol):
    """Anything with ``x`` and ``y`` arrays of points, m: a :class:`Trajectory`, a drive's log."""

    @property
    def x(self) -> ArrayLike:
        """The points' x, m."""

    @property
    def y(self) -> ArrayLike:
        """The points' y, m."""


Line: TypeAlias = "HasXY | tuple[ArrayLike, ArrayLike]"
"""A closed line, m: an object with ``x`` and ``y`` arrays (:class:`HasXY`) or an ``(x, y)``
pair (first point not repeated at the end)."""


def _line_xy(line: Line) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) arrays of a line given as an object with ``x``/``y`` or as an ``(x, y)`` pair."""
    if isinstance(line, tuple | list) and len(line) == 2:
        x, y = line
    else:
        x, y = getattr(line, "x", None), getattr(line, "y", None)
    if x is None or y is None:
        raise PlanningError(
            f"cannot read a line from a {type(line).__name__}; pass a Trajectory, an object with "
            "x and y arrays, or an (x, y) pair of arrays in m."
        )
    x = np.asarray(x, float).ravel()
    y = np.asarray(y, float).ravel()
    if x.size != y.size or x.size < 4 or not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise PlanningError(
            f"a line needs at least 4 finite points with as many x as y values, got {x.size} x "
            f"and {y.size} y values; resample the line."
        )
    return x, y


def speed_profile_trajectory(
    track: Track,
    line: Line,
    params: ModelParams,
    options: ModelOptions | None = None,
    *,
    spacing: float = 3.0,
    v_top: float | None = None,
    method: str = "speed-profile",
) -> Trajectory:
    """Drive any closed line at its quasi-steady speed profile.

    The line is resampled every ``spacing`` m along a spline through it; its curvature gives the
    cornering limit and the road grade is read on the track centerline at the projection of each
    node (:func:`racing_lib.planning.speed.speed_profile` explains the profile).

    Parameters
    ----------
    track : Track
        The track the line lies on (for the grade and the plan's metadata).
    line : Trajectory, object with ``x``/``y``, or (x, y)
        The closed line, m (first point not repeated at the end).
    params : ModelParams
        Parameters of the speed profile (friction, mass, drag, pedal map).
    options : ModelOptions, optional
        Model effects (the drag switch matters); default ``ModelOptions()``.
    spacing : float
        Node spacing along the line, m.
    v_top : float, optional
        Top speed, m/s (default 190 km/h).
    method : str
        Label stored in the trajectory's ``method``.

    Returns
    -------
    Trajectory
        The line at its speed profile; ``lap_time`` is the profile's lap time, s. v_y is zero and
        delta the kinematic steering angle of the line (a point-mass evaluation has no more).

    Examples
    --------
    >>> from racing_lib.tracks import load_track
    >>> track = load_track("expressway")
    >>> line = track.centerline.position(track.centerline.sample(ds=3.0))
    >>> from racing_lib.model import identified_params
    >>> traj = speed_profile_trajectory(track, line, identified_params())
    >>> 100.0 < traj.lap_time < 120.0
    True
    """
    if not spacing > 0:
        raise PlanningError(f"spacing must be positive, got {spacing!r} m.")
    params, pedal_map, options = model_inputs(params, None, options, "speed_profile_trajectory")
    x, y = _line_xy(line)
    path = Path(x, y, check=False)
    n = max(16, int(round(path.length / spacing)))
    s = np.asarray(path.sample(n=n), float)
    xs, ys = path.position(s)
    s_center, _ = track.centerline.to_frenet_along(xs, ys)
    theta = np.asarray(track.grade(np.asarray(s_center, float)), float)
    return Trajectory.at_speed_profile(
        track, path, s, theta, params, pedal_map, options, v_top, method=method
    )


def line_lap_time(
    track: Track,
    line: Line,
    params: ModelParams,
    options: ModelOptions | None = None,
    *,
    spacing: float = 3.0,
    v_top: float | None = None,
) -> float:
    """Lap time (s) of any closed line driven at its quasi-steady speed profile.

    Shorthand for ``speed_profile_trajectory(...).lap_time``; see there for the arguments.
    """
    traj = speed_profile_trajectory(track, line, params, options, spacing=spacing, v_top=v_top)
    return traj.lap_time


def _on_centerline(track: Track, traj: Line) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centerline arc length (unwrapped from the first node, increasing), e_y and t of the nodes."""
    x, y = _line_xy(traj)
    s_c, e_y = track.centerline.to_frenet_along(x, y)
    s_c = np.unwrap(np.asarray(s_c, float), period=track.length)
    if s_c[-1] < s_c[0]:
        raise PlanningError(
            "the trajectory runs against the direction of the track's centerline; plans follow "
            "increasing s."
        )
    # A line projects monotonically wherever it stays within the radius of curvature of the
    # centerline; guard against round-off at the ends of straight sections.
    s_c = np.maximum.accumulate(s_c)
    t = np.asarray(getattr(traj, "t", np.zeros(x.size)), float)
    return s_c, np.asarray(e_y, float), t


def time_along_centerline(track: Track, traj: Trajectory, s: ArrayLike) -> np.ndarray:
    """Time (s) at which ``traj`` passes the centerline arc lengths ``s`` (m), from s = 0.

    The trajectory's nodes are projected onto the centerline and its time interpolated there, so
    plans on different lines (and with different own arc lengths) can be compared at the same
    place on the track.
    """
    s_c, _, t = _on_centerline(track, traj)
    length = float(track.length)
    lap = float(traj.lap_time)
    # Extend by one lap on both sides so that any s in [0, length] is bracketed.
    s_ext = np.concatenate((s_c - length, s_c, s_c + length))
    t_ext = np.concatenate((t - lap, t, t + lap))
    s_q = np.mod(np.asarray(s, float), length)
    t_q = np.interp(s_q, s_ext, t_ext)
    t0 = float(np.interp(0.0, s_ext, t_ext))
    return np.mod(t_q - t0, lap)


def time_gap(
    track: Track, reference: Trajectory, other: Trajectory, n: int = 2000
) -> tuple[np.ndarray, np.ndarray]:
    """Where along the track ``other`` gains or loses time against ``reference``.

    Parameters
    ----------
    track : Track
        The track (its centerline measures the place).
    reference, other : Trajectory
        Two plans of the same track.
    n : int
        Number of evaluation points over the lap.

    Returns
    -------
    s : ndarray (n,)
        Centerline arc length, m.
    gap : ndarray (n,)
        ``t_other(s) - t_reference(s)``, s: negative where ``other`` is ahead. At the end of the
        lap it approaches the difference of the lap times.
    """
    s = np.linspace(0.0, float(track.length), int(n), endpoint=False)
    gap = time_along_centerline(track, other, s) - time_along_centerline(track, reference, s)
    return s, gap


@dataclass(frozen=True)
class PlanSummary:
    """One plan in a few numbers.

    Attributes
    ----------
    name : str
        Label of the plan.
    lap_time_s : float
        Planned lap time, s.
    length_m : float
        Length of the line, m.
    mean_abs_kappa : float
        Mean |curvature| of the line over its length, 1/m. On a closed loop its integral is the
        total turning, at least 2 pi, so it hardly changes from line to line.
    kappa_sq_integral : float
        Integral of kappa^2 over the line, 1/m: what a minimum-curvature line makes small.
    max_abs_kappa : float
        Largest |curvature| of the line, 1/m (the sharpest point, usually the slowest).
    v_mean_mps, v_min_mps, v_max_mps : float
        Mean (length over lap time), minimum and maximum planned v_x, m/s.
    gain_s : float
        Lap time minus the first plan's (negative: faster), s.
    """

    name: str
    lap_time_s: float
    length_m: float
    mean_abs_kappa: float
    kappa_sq_integral: float
    max_abs_kappa: float
    v_mean_mps: float
    v_min_mps: float
    v_max_mps: float
    gain_s: float


def compare_plans(plans: Mapping[str, Trajectory]) -> list[PlanSummary]:
    """Summaries of several plans, each measured against the first.

    Parameters
    ----------
    plans : mapping of name -> Trajectory
        The plans, the reference first.
    """
    if not plans:
        raise PlanningError("compare_plans needs at least one plan.")
    out: list[PlanSummary] = []
    first: float | None = None
    for name, traj in plans.items():
        ds = np.diff(np.append(traj.s, traj.length))
        lap = float(traj.lap_time)
        first = lap if first is None else first
        out.append(
            PlanSummary(
                name=str(name),
                lap_time_s=lap,
                length_m=float(traj.length),
                mean_abs_kappa=float(np.sum(np.abs(traj.kappa) * ds) / traj.length),
                kappa_sq_integral=float(np.sum(traj.kappa**2 * ds)),
                max_abs_kappa=float(np.max(np.abs(traj.kappa))),
                v_mean_mps=float(traj.length / lap),
                v_min_mps=float(np.min(traj.vx)),
                v_max_mps=float(np.max(traj.vx)),
                gain_s=lap - first,
            )
        )
    return out


@dataclass(frozen=True)
class CornerLine:
    """How a plan takes one corner.

    Offsets are from the centerline and positive towards the **inside** of the corner, so an
    out-in-out line has ``ey_entry_m < 0 < ey_apex_m`` and ``ey_exit_m < 0``. For an S-bend the
    inside is that of its first part.

    Attributes
    ----------
    plan : str
        Label of the plan.
    corner : int
        Corner number.
    ey_entry_m, ey_exit_m : float
        Most outside offset (smallest inside offset) on the approach, from ``lead`` m before the
        corner to the apex, and on the way out, from the apex to ``lead`` m after it, m.
    ey_apex_m : float
        Largest inside offset within the corner (``Corner.s_entry`` to ``s_exit``), m.
    s_apex_m : float
        Centerline arc length of that point, m.
    v_min_mps : float
        Lowest planned v_x between entry and exit, m/s.
    """

    plan: str
    corner: int
    ey_entry_m: float
    ey_apex_m: float
    s_apex_m: float
    ey_exit_m: float
    v_min_mps: float


def corner_summary(
    track: Track,
    plans: Mapping[str, Trajectory],
    corners: Iterable[Corner] | None = None,
    *,
    lead: float = 100.0,
) -> list[CornerLine]:
    """Entry, apex and exit offsets and the slowest speed of each plan in each corner.

    Parameters
    ----------
    track : Track
        The track.
    plans : mapping of name -> Trajectory
        Plans of that track.
    corners : iterable of Corner, optional
        Corners with ``number``, ``s``, ``s_entry``, ``s_exit`` (and ``angle``, whose sign says
        the direction; 0 for an S-bend, where the turning of its first part decides). Default:
        the track's crucial corners.
    lead : float
        Length of the approach and of the way out searched for the outside offsets, m.
    """
    corners = list(track.corners if corners is None else corners)
    if not corners:
        raise PlanningError(
            f"track {getattr(track, 'name', '?')!r} defines no corners; pass them explicitly."
        )
    length = float(track.length)
    out: list[CornerLine] = []
    for name, traj in plans.items():
        s_c, e_y, _ = _on_centerline(track, traj)
        s_mod = np.mod(s_c, length)
        order = np.argsort(s_mod)
        s_sorted, ey_sorted = s_mod[order], e_y[order]
        vx_sorted = np.asarray(traj.vx, float)[order]

        for c in corners:
            lo, hi = float(c.s_entry), float(c.s_exit)
            direction = float(np.sign(c.angle))
            if direction == 0.0:
                # An S-bend: the direction of its first part (turning from entry to the middle).
                s_half = np.linspace(lo, float(c.s), 50)
                direction = float(np.sign(np.mean(track.centerline.curvature(s_half % length))))
            inside_ey = direction * ey_sorted

            def window(a: float, b: float, s_sorted=s_sorted) -> np.ndarray:
                return ((s_sorted - a) % length) <= ((b - a) % length)

            corner = window(lo, hi)
            if not np.any(corner):
                raise PlanningError(
                    f"plan {name!r} has no node within corner {c.number}; use a finer plan."
                )
            k = int(np.argmax(np.where(corner, inside_ey, -np.inf)))
            s_apex = float(s_sorted[k])
            out.append(
                CornerLine(
                    plan=str(name),
                    corner=int(c.number),
                    ey_entry_m=float(np.min(inside_ey[window(lo - lead, s_apex)])),
                    ey_apex_m=float(inside_ey[k]),
                    s_apex_m=s_apex,
                    ey_exit_m=float(np.min(inside_ey[window(s_apex, hi + lead)])),
                    v_min_mps=float(np.min(vx_sorted[corner])),
                )
            )
    return out


__all__ = [
    "CornerLine",
    "HasXY",
    "Line",
    "PlanSummary",
    "compare_plans",
    "corner_summary",
    "line_lap_time",
    "speed_profile_trajectory",
    "time_along_centerline",
    "time_gap",
]
