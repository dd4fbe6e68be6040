"""Edge margins that follow the laps along the track (chapter 09, the learning loop).

A plan keeps the car's side a margin from the track's edges, and a controller strays from the plan's
line: the margin has to cover that. One number for the whole lap covers the worst excursion
everywhere, and on circuits the worst came from one corner or two, so every plan after it slowed
down on every metre. Here the margin follows the laps: :func:`edge_excursions` measures how far a
set of laps strayed from their line near each point of the track, and :func:`planning_track` gives
the track narrowed where that, plus :data:`EDGE_SAFETY`, is more than the plan's own margin. A plan
made on the narrowed track is a plan of the real one (same centerline), with a margin that varies
along it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from racing_lib.experiments.lap import LapLog
from racing_lib.geometry import Track
from racing_lib.planning.grid import DEFAULT_CAR_WIDTH, default_margin

__all__ = [
    "EDGE_SAFETY",
    "EXCURSION_WINDOW",
    "edge_excursions",
    "largest_margin",
    "margin_excess",
    "planning_track",
]

#: Added to the laps' largest tracking error near a point to give the least distance the next
#: plan keeps from the edges there (:func:`planning_track`), m.
EDGE_SAFETY = 0.15
#: How far along the track an excursion counts, m, either way: laps stray where the ones before
#: did, give or take a few tens of metres (another braking point, another seed).
EXCURSION_WINDOW = 50.0
#: Spacing of the excursion profile along the track, m.
_EXCURSION_SPACING = 2.0


def edge_excursions(
    logs: Sequence[LapLog], track: Track, window: float = EXCURSION_WINDOW
) -> tuple[np.ndarray, np.ndarray]:
    """How far the laps strayed from their line near each point of the track.

    Parameters
    ----------
    logs : sequence of LapLog
        Laps driven on ``track``.
    track : Track
    window : float
        An excursion counts this far along the track either way, m.

    Returns
    -------
    s : ndarray
        Arc length on the track's centerline, m (every 2 m).
    excursion : ndarray
        The largest lateral distance between the car and its plan's line over the laps within
        ``window`` of ``s``, m.
    """
    length = float(track.length)
    s = np.arange(0.0, length, _EXCURSION_SPACING)
    worst = np.zeros(s.size)
    for log in logs:
        k = np.round(np.mod(log.s_track, length) / _EXCURSION_SPACING).astype(int) % s.size
        np.maximum.at(worst, k, np.abs(log.ey))
    half = max(int(round(window / _EXCURSION_SPACING)), 0)
    if half == 0:
        return s, worst
    around = np.concatenate([worst[-half:], worst, worst[:half]])  # the lap is a loop
    return s, np.lib.stride_tricks.sliding_window_view(around, 2 * half + 1).max(axis=1)


def planning_track(track: Track, logs: Sequence[LapLog], margin: float) -> Track:
    """``track`` narrowed where ``logs`` strayed from their line by more than ``margin`` allows.

    A plan made on it with an edge margin of ``margin`` (m) keeps, at every point, at least
    ``margin`` from the real edges, and the laps' largest tracking error near that point
    (:func:`edge_excursions`) plus :data:`EDGE_SAFETY` where that is more. Where the track is
    too narrow for that, it keeps the car and the margin on the track (the narrowing is capped).
    The centerline is the same, so a plan on it is a plan of ``track``.
    """
    s, excursion = edge_excursions(logs, track)
    knots = track.centerline.knots
    need = np.interp(knots, s, excursion, period=float(track.length)) + EDGE_SAFETY
    cut = need - margin
    left, right = track.width_left(knots), track.width_right(knots)
    room = 0.5 * (left + right - DEFAULT_CAR_WIDTH) - margin - 0.1
    cut = np.clip(cut, 0.0, np.maximum(room, 0.0))
    if not np.any(cut > 0.0):
        return track
    return Track(
        track.centerline,
        left - cut,
        right - cut,
        track.elevation(knots),
        s=knots,
        boundary=track.boundary,
        name=track.name,
        corners=track.corners,
    )


def largest_margin(margin: float | None, track: Track, plan_track: Track) -> float | None:
    """The largest distance from the edges of ``track`` a plan on ``plan_track`` keeps, m.

    Parameters
    ----------
    margin : float or None
        The plan's edge margin, m (None: the planner's default, on ``track`` itself).
    track : Track
        The track.
    plan_track : Track
        The track the plan was made on: ``track``, or ``track`` narrowed (:func:`planning_track`).

    Returns
    -------
    float or None
        ``margin`` plus the largest narrowing, m (None when ``margin`` is).
    """
    if margin is None or plan_track is track:
        return margin
    return float(margin + np.max(_narrowing(track, plan_track)))


def _narrowing(track: Track, plan_track: Track) -> np.ndarray:
    """How much narrower ``plan_track`` is than ``track`` on each side at the knots, m.

    :func:`planning_track` narrows both sides by the same amount, so one side says it.
    """
    knots = track.centerline.knots
    return np.asarray(track.width_left(knots) - plan_track.width_left(knots), dtype=float)


def margin_excess(
    logs: Sequence[LapLog], track: Track, plan_track: Track, margin: float | None
) -> float | None:
    """How far the laps strayed from their line beyond the edge margin their plan kept, m.

    The margin a plan keeps from the edges is there to hold the controller's tracking error. A
    lap that strayed further than that margin was clean only because it strayed where its line
    was not beside the edge, and the next seed may stray where it is: on the expressway, an
    iteration whose four laps strayed 0.38 m beyond their 0.4 m margin, clean, touched a wall
    seven times in ten laps on new seeds, where iterations whose laps stayed inside their
    margins drove ten clean laps.

    Parameters
    ----------
    logs : sequence of LapLog
        Laps driven on ``track`` after a plan made on ``plan_track``.
    track : Track
        The track.
    plan_track : Track
        The track the plan was made on: ``track``, or ``track`` narrowed
        (:func:`planning_track`).
    margin : float or None
        The plan's edge margin, m (None: the planner's default on ``track``).

    Returns
    -------
    float or None
        The largest, over the laps and the track, of the lateral distance between the car and
        its line less the margin kept at that point, m: zero or less when the margin held every
        excursion. None without a lap.
    """
    kept = default_margin(track) if margin is None else margin
    knots = track.centerline.knots
    length = float(track.length)
    cut = _narrowing(track, plan_track)
    worst = None
    for log in logs:
        lap = log.lap_steps
        if not lap.size:
            continue
        s = np.mod(np.asarray(log.s_track, dtype=float)[lap], length)
        # either side: the line runs beside either edge somewhere, and a lap that strayed this
        # far to one side here may stray as far to the other where the line hugs that edge
        beyond = np.abs(np.asarray(log.ey, dtype=float)[lap]) - (
            kept + np.interp(s, knots, cut, period=length)
        )
        worst = float(beyond.max()) if worst is None else max(worst, float(beyond.max()))
    return worst
