"""Checks of a track's geometry that the file format cannot express: roads that are impossible.

A racetrack-database file is a list of centerline points with two widths each. Three things such a
file can say are not a road a car can drive, and :class:`racing_lib.geometry.Track` checks each:

* **An inner width beyond the turn's radius.** On a turn of radius R, a point at distance n
  towards the inside has the Frenet factor 1 - n / R; at n = R the frame is singular (the
  inner edge passes through the turn's centre) and beyond it the road folds over itself. The
  inner width is clipped to :data:`INNER_WIDTH_SHARE` of the local radius, with a warning that
  says where. (Four of ten racetrack-database circuits have a few such points, where a kink of
  the recorded centerline makes the radius 5-9 m.)
* **Overlapping stretches.** Two parts of the lap that are far apart along it but whose roads
  share ground (a hairpin whose legs are closer than their widths), other than at a bridge,
  leave the car on two roads at once. Refused.
* **Very dense points.** The spline through the points is exact, so the rounding of the
  coordinates (a file's 6 decimals) at 0.1 m spacing becomes curvature noise of about 3 %
  (0.04 % at 1 m). Rows closer than
  :data:`MIN_ROW_SPACING` are thinned, with a warning.

Used by :mod:`racing_lib.geometry`; importable alone (it works on arrays and takes no Track).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: Largest share of the local radius of curvature that the inner width may take (at 1 the
#: inner edge touches the turn's centre and the Frenet frame is singular there).
INNER_WIDTH_SHARE = 0.95
#: Rows of a track file closer than this (median, m) are thinned to about this spacing.
MIN_ROW_SPACING = 1.0
#: Two stretches of road may overlap by this much (m) before it counts (rounding of the file).
OVERLAP_TOLERANCE = 0.05
#: Sampling step of the overlap check, m.
OVERLAP_STEP = 2.0


class TrackGeometryWarning(UserWarning):
    """A track was changed to make it drivable (inner widths clipped, dense rows thinned)."""


@dataclass(frozen=True)
class Overlap:
    """Two stretches of road that share ground.

    Attributes
    ----------
    s_a, s_b : float
        Arc lengths of the two places, m.
    depth : float
        By how much the two roads overlap there, m.
    distance : float
        Distance between the two centerline points, m.
    """

    s_a: float
    s_b: float
    depth: float
    distance: float


def clip_inner_widths(
    s: np.ndarray, kappa: np.ndarray, left: np.ndarray, right: np.ndarray, name: str
) -> tuple[np.ndarray, np.ndarray]:
    """Clip the inner widths to :data:`INNER_WIDTH_SHARE` of the local radius, warning where.

    Parameters
    ----------
    s, kappa : ndarray
        Arc lengths (m) and curvature (1/m, > 0 turning left) at the width samples.
    left, right : ndarray
        Widths to the left and right edge at those samples, m.
    name : str
        The track's name, for the warning.

    Returns
    -------
    left, right : ndarray
        The widths, clipped where they reached past the turn's centre.
    """
    limit = INNER_WIDTH_SHARE / np.maximum(np.abs(kappa), 1e-12)
    out = []
    for side, width, inner in (("left", left, kappa > 0), ("right", right, kappa < 0)):
        bad = inner & (width > limit)
        if np.any(bad):
            k = int(np.flatnonzero(bad)[np.argmax((width - limit)[bad])])
            warnings.warn(
                f"Track {name!r}: the {side} (inner) width reaches the centre of the turn (or "
                f"within {1 - INNER_WIDTH_SHARE:.0%} of the radius of it) at {int(bad.sum())} "
                f"point(s) between s = {s[bad].min():.0f} and "
                f"{s[bad].max():.0f} m (worst at s = {s[k]:.0f} m: width {width[k]:.2f} m, "
                f"radius {1.0 / abs(kappa[k]):.2f} m). Clipped to {INNER_WIDTH_SHARE:.0%} of "
                "the radius; fix the widths or the points there to silence this.",
                TrackGeometryWarning,
                stacklevel=4,
            )
            width = np.where(bad, limit, width)
        out.append(width)
    return out[0], out[1]


def road_overlaps(
    s: np.ndarray,
    xy: np.ndarray,
    heading: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    length: float,
    bridges: Sequence[tuple[float, float, float]] = (),
) -> list[Overlap]:
    """Places where two far-apart stretches of road share ground (bridges excepted).

    For each pair of samples farther apart along the lap than the neighbourhood (4 times the
    largest total width plus 20 m, so that the inside of a hairpin is not compared with itself),
    the roads overlap when the centerline points are closer than the two widths that face each
    other. One :class:`Overlap` per pair of stretches, the deepest point of each.

    Parameters
    ----------
    s : ndarray, shape (n,)
        Arc lengths of the samples, m.
    xy : ndarray, shape (n, 2)
        Centerline points, m.
    heading : ndarray, shape (n,)
        Centerline heading, rad.
    left, right : ndarray, shape (n,)
        Widths, m.
    length : float
        Lap length, m.
    bridges : sequence of (s_a, s_b, angle_deg)
        Crossings accepted as bridges; pairs near one are not compared.
    """
    widest = float(np.max(left + right))
    neighbourhood = 4.0 * widest + 20.0
    pairs = cKDTree(xy).query_pairs(
        r=2.0 * float(max(left.max(), right.max())), output_type="ndarray"
    )
    if len(pairs) == 0:
        return []
    i, j = pairs[:, 0], pairs[:, 1]
    along = np.abs(s[i] - s[j])
    along = np.minimum(along, length - along)
    keep = along > neighbourhood
    for s_a, s_b, angle in bridges:
        reach = widest / max(math.sin(math.radians(angle)), 0.1) + 20.0
        near_a = _near(s[i], s_a, length, reach) & _near(s[j], s_b, length, reach)
        near_b = _near(s[i], s_b, length, reach) & _near(s[j], s_a, length, reach)
        keep &= ~(near_a | near_b)
    i, j = i[keep], j[keep]
    if len(i) == 0:
        return []
    d = xy[j] - xy[i]
    dist = np.hypot(d[:, 0], d[:, 1])
    facing_i = _facing_width(d, heading[i], left[i], right[i])
    facing_j = _facing_width(-d, heading[j], left[j], right[j])
    depth = facing_i + facing_j - dist
    hit = depth > OVERLAP_TOLERANCE
    return _worst_per_stretch(s[i][hit], s[j][hit], depth[hit], dist[hit], neighbourhood)


def thin_dense_rows(xy: np.ndarray, where: str) -> np.ndarray:
    """Indices of the rows to keep so that their median spacing is about ``MIN_ROW_SPACING``.

    Indices of the rows to keep so that their median spacing is at least about
    :data:`MIN_ROW_SPACING` (all rows when they are already that far apart), warning if any go.

    Parameters
    ----------
    xy : ndarray, shape (n, 2)
        The file's centerline points, m.
    where : str
        Names the file in the warning.
    """
    step = np.hypot(*np.diff(xy, axis=0).T)
    spacing = float(np.median(step)) if len(step) else MIN_ROW_SPACING
    keep_every = int(math.ceil(MIN_ROW_SPACING / spacing)) if spacing > 0 else 1
    if keep_every <= 1 or len(xy) // keep_every < 8:
        return np.arange(len(xy))
    warnings.warn(
        f"{where}: its points are only {spacing:.2f} m apart (median); a spline through such "
        "dense points turns the rounding of the coordinates into percent of curvature noise. Every "
        f"{keep_every}th row is used ({keep_every * spacing:.2f} m apart); resample the file to "
        f"{MIN_ROW_SPACING:g}-5 m spacing to silence this.",
        TrackGeometryWarning,
        stacklevel=4,
    )
    keep = np.arange(0, len(xy), keep_every)
    # The loop closes from the last kept row to row 0: drop a last row that would sit closer to
    # row 0 than the others sit to each other.
    while len(keep) > 8 and np.hypot(*(xy[keep[-1]] - xy[0])) < 0.5 * keep_every * spacing:
        keep = keep[:-1]
    return keep


def _near(values: np.ndarray, centre: float, length: float, reach: float) -> np.ndarray:
    gap = np.abs(values - centre)
    return np.minimum(gap, length - gap) < reach


def _facing_width(
    towards: np.ndarray, heading: np.ndarray, left: np.ndarray, right: np.ndarray
) -> np.ndarray:
    """The width of the side that faces the direction ``towards`` (left when it points left)."""
    normal = np.column_stack([-np.sin(heading), np.cos(heading)])
    side = np.einsum("ij,ij->i", towards, normal)
    return np.where(side >= 0.0, left, right)


def _worst_per_stretch(
    s_a: np.ndarray, s_b: np.ndarray, depth: np.ndarray, dist: np.ndarray, gap: float
) -> list[Overlap]:
    """The deepest pair of each group of overlapping pairs (groups: pairs within ``gap`` m)."""
    found: list[Overlap] = []
    for k in np.argsort(-depth):
        a, b = sorted((float(s_a[k]), float(s_b[k])))
        if any(abs(o.s_a - a) < gap and abs(o.s_b - b) < gap for o in found):
            continue
        found.append(Overlap(a, b, float(depth[k]), float(dist[k])))
    return found
