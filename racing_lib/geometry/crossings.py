"""Where a closed curve crosses itself: broken rows against real bridges (figure-eight layouts)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from racing_lib.errors import TrackError

__all__ = [
    "BRIDGE_MIN_ANGLE_DEG",
    "BRIDGE_MIN_SEPARATION",
    "Crossing",
    "find_crossings",
    "refuse_broken_crossing",
    "self_intersections",
]


def _segments_intersect(p1, p2, q1, q2) -> np.ndarray:
    """Elementwise proper intersection test of segments p1-p2 and q1-q2 (arrays (m, 2))."""

    def orient(a, b, c):
        return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])

    d1, d2 = orient(q1, q2, p1), orient(q1, q2, p2)
    d3, d4 = orient(p1, p2, q1), orient(p1, p2, q2)
    return (d1 * d2 < 0.0) & (d3 * d4 < 0.0)


def self_intersections(xy: np.ndarray) -> list[tuple[int, int]]:
    """Index pairs (i, j) of crossing segments of the closed polyline xy (n, 2)."""
    n = len(xy)
    nxt = np.roll(xy, -1, axis=0)
    seg_len = np.hypot(*(nxt - xy).T)
    mid = 0.5 * (xy + nxt)
    # Two segments can only cross if their midpoints are closer than one segment length.
    pairs = cKDTree(mid).query_pairs(r=float(seg_len.max()) * 1.01, output_type="ndarray")
    if len(pairs) == 0:
        return []
    i, j = pairs[:, 0], pairs[:, 1]
    gap = np.abs(i - j)
    keep = np.minimum(gap, n - gap) > 1  # neighbours share an end point
    i, j = i[keep], j[keep]
    hit = _segments_intersect(xy[i], nxt[i], xy[j], nxt[j])
    return sorted(zip(i[hit].tolist(), j[hit].tolist(), strict=True))


#: A crossing of the centerline is a bridge (a figure-eight layout) when the two stretches that
#: meet are at least this far apart along the lap, m ...
BRIDGE_MIN_SEPARATION = 100.0
#: ... and cross at an angle of at least this many degrees: a broken file (swapped or misplaced
#: rows) makes a small loop between neighbouring rows or grazing stretches instead.
BRIDGE_MIN_ANGLE_DEG = 20.0


@dataclass(frozen=True)
class Crossing:
    """Where a closed curve crosses itself.

    Attributes
    ----------
    s_a, s_b : float
        Arc lengths of the two stretches that cross, m (s_a < s_b).
    angle_deg : float
        Angle between their directions, degrees (0-90).
    segment_a, segment_b : int
        Indices of the two crossing segments of the polyline tested (vertex k to k + 1).
    """

    s_a: float
    s_b: float
    angle_deg: float
    segment_a: int
    segment_b: int

    def is_bridge(self, length: float) -> bool:
        """True for a real crossing (two far-apart stretches of the lap at a sizeable angle)."""
        gap = abs(self.s_a - self.s_b)
        gap = min(gap, length - gap)
        return gap >= BRIDGE_MIN_SEPARATION and self.angle_deg >= BRIDGE_MIN_ANGLE_DEG


def find_crossings(xy: np.ndarray, s: np.ndarray) -> list[Crossing]:
    """The crossings of the closed polyline ``xy`` (n, 2), vertices at arc lengths ``s`` (m)."""
    nxt = np.roll(xy, -1, axis=0)
    out = []
    for i, j in self_intersections(xy):
        da, db = nxt[i] - xy[i], nxt[j] - xy[j]
        cos = abs(float(np.dot(da, db))) / (float(np.hypot(*da) * np.hypot(*db)) + 1e-300)
        angle = math.degrees(math.acos(min(1.0, cos)))
        out.append(Crossing(float(s[i]), float(s[j]), angle, int(i), int(j)))
    return out


def refuse_broken_crossing(crossings: list[Crossing], length: float, describe) -> None:
    """Raise TrackError for the first crossing that is not a bridge (``describe(c)`` words it)."""
    for c in crossings:
        if not c.is_bridge(length):
            raise TrackError(describe(c))
