"""Tracks: a centerline path, the widths to its edges, an elevation profile and a boundary kind.

A :class:`Track` is a centerline :class:`~racing_lib.geometry.path.Path` plus the widths to its left
and right edges, an elevation profile and the boundary kind (``walls`` or ``open``), read from and
written to the racetrack-database CSV format (:mod:`racing_lib.geometry.csv`). Load one by name or
file with :func:`racing_lib.tracks.load_track`. Taught in notebook 00.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path as _FsPath
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

from racing_lib.errors import TrackError
from racing_lib.geometry.checks import (
    OVERLAP_STEP,
    clip_inner_widths,
    road_overlaps,
    thin_dense_rows,
)
from racing_lib.geometry.crossings import (
    BRIDGE_MIN_ANGLE_DEG,
    BRIDGE_MIN_SEPARATION,
    Crossing,
    find_crossings,
    refuse_broken_crossing,
)
from racing_lib.geometry.csv import CSV_COLUMNS, read_track_rows, write_track_text
from racing_lib.geometry.path import DUPLICATE_TOL, Path
from racing_lib.geometry.spline import PeriodicSpline

__all__ = ["Corner", "Track", "wall_clearance"]

Boundary = Literal["walls", "open"]

# --------------------------------------------------------------------------------------------
# Track
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Corner:
    """A named corner of a track, for zoomed plots and per-corner analysis.

    Attributes
    ----------
    number : int
        Corner number, 1-based, in order of travel.
    label : str
        Short description ("hairpin", "S-bend"...).
    s : float
        Arc length of the corner's middle (apex of the design arc), m.
    s_entry, s_exit : float
        Arc lengths where the corner's curvature starts and ends, m (s_exit < s_entry when the
        corner spans the start/finish line).
    radius : float
        Smallest design radius in the corner, m.
    angle : float
        Total turning, rad (> 0 left).
    """

    number: int
    label: str
    s: float
    s_entry: float
    s_exit: float
    radius: float
    angle: float


def _as_floats(values, what: str) -> np.ndarray:
    """A profile's values as floats, or a TrackError that names the profile."""
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise TrackError(
            f"The {what} must be a number of metres or an array of them, got {values!r}."
        ) from None


def _profile_on_grid(path: Path, values, s, what: str) -> np.ndarray:
    """Values of a profile (float, or samples at arc lengths s) at the path's knots."""
    grid = path.knots
    values = _as_floats(values, what)
    if np.ndim(values) == 0:
        v = float(values)
        if not math.isfinite(v):
            raise TrackError(f"The {what} must be finite, got {values!r}.")
        return np.full(grid.shape, v)
    vals = np.asarray(values, dtype=float).ravel()
    if s is None:
        if len(vals) != len(grid):
            raise TrackError(
                f"The {what} has {len(vals)} samples but no arc lengths s were given; pass s "
                f"(m) or one sample per path knot ({len(grid)})."
            )
        return vals
    s = np.asarray(s, dtype=float).ravel()
    if len(s) != len(vals):
        raise TrackError(f"The {what} has {len(vals)} samples for {len(s)} arc lengths s.")
    if not np.all(np.isfinite(vals)):
        raise TrackError(f"The {what} contains NaN or infinite values; give finite metres.")
    if len(vals) < 4 or np.any(np.diff(s) <= 0) or s[0] < 0 or s[-1] >= path.length:
        raise TrackError(
            f"The {what} needs >= 4 samples at increasing arc lengths in [0, length), got s "
            f"from {s.min():.3f} to {s.max():.3f} m for length {path.length:.3f} m."
        )
    spline = CubicSpline(
        np.append(s, s[0] + path.length), np.append(vals, vals[0]), bc_type="periodic"
    )
    return spline(grid)


class Track:
    """A race track: centerline path, widths to both edges, elevation and boundary kind.

    Parameters
    ----------
    centerline : Path
        The reference line; s = 0 is the start/finish line.
    width_left, width_right : float or array_like
        Distance from the centerline to the left / right edge, m, > 0: a constant, or samples at
        the arc lengths ``s`` (or at the centerline's knots when ``s`` is None).
    elevation : float or array_like, optional
        Height of the road, m (default 0), same sampling as the widths.
    s : array_like, optional
        Arc lengths of the samples, m, increasing in [0, length).
    boundary : {"walls", "open"}
        ``walls``: the car hits walls at the edges; ``open``: run-off with less grip.
    name : str
        A name for messages, plots and plan files.
    corners : sequence of Corner, optional
        The crucial corners (built-in tracks define them; empty for CSV tracks).

    Notes
    -----
    All profiles are periodic cubic splines over s on the centerline's knots; grade
    theta(s) = atan(dz/ds) is positive uphill in the direction of travel.
    """

    def __init__(
        self,
        centerline: Path,
        width_left: float | ArrayLike,
        width_right: float | ArrayLike,
        elevation: float | ArrayLike = 0.0,
        *,
        s: ArrayLike | None = None,
        boundary: Boundary = "open",
        name: str = "track",
        corners: tuple[Corner, ...] | list[Corner] = (),
    ) -> None:
        if not isinstance(centerline, Path):
            raise TrackError(
                f"Track needs a racing_lib.geometry.Path as its centerline, got "
                f"{type(centerline).__name__}; build one with Path(x, y)."
            )
        if boundary not in ("walls", "open"):
            raise TrackError(f"Track boundary must be 'walls' or 'open', got {boundary!r}.")
        self.name = str(name)
        self.centerline = centerline
        self.boundary: Boundary = boundary
        self.length = centerline.length
        self.corners: tuple[Corner, ...] = tuple(corners)
        wl = _profile_on_grid(centerline, width_left, s, "left width")
        wr = _profile_on_grid(centerline, width_right, s, "right width")
        z = _profile_on_grid(centerline, elevation, s, "elevation")
        grid = centerline.knots
        wl, wr = clip_inner_widths(grid, centerline.curvature(grid), wl, wr, self.name)
        knots = centerline._knots
        self._wl = PeriodicSpline(knots, wl)
        self._wr = PeriodicSpline(knots, wr)
        self._z = PeriodicSpline(knots, z)
        # The splines may dip between samples; check them densely, not only at the samples.
        fine = centerline.sample(n=4 * len(wl))
        for what, spl in (("left", self._wl), ("right", self._wr)):
            low = spl(fine)
            if np.min(low) <= 0.0:
                i = int(np.argmin(low))
                raise TrackError(
                    f"Track {self.name!r}: the {what} width is not positive near s = "
                    f"{fine[i]:.1f} m ({low[i]:.3f} m); widths must be > 0 m."
                )
        self._refuse_overlaps()

    def _refuse_overlaps(self) -> None:
        """Refuse two far-apart stretches whose roads share ground (bridges excepted)."""
        line = self.centerline
        s = line.sample(ds=OVERLAP_STEP)
        x, y = line.position(s)
        bridges = [(c.s_a, c.s_b, c.angle_deg) for c in line.crossings]
        found = road_overlaps(
            s,
            np.column_stack([x, y]),
            np.asarray(line.heading(s), float),
            self._wl(s),
            self._wr(s),
            self.length,
            bridges,
        )
        if found:
            o = found[0]
            raise TrackError(
                f"Track {self.name!r}: the road near s = {o.s_a:.0f} m overlaps the road near "
                f"s = {o.s_b:.0f} m by {o.depth:.2f} m (their centerlines are {o.distance:.2f} m "
                f"apart){f', and in {len(found) - 1} more place(s)' if len(found) > 1 else ''}; "
                "two stretches of road may share ground only where they cross on a bridge. "
                "Narrow the widths there, or fix the points."
            )

    def corner_positions(self) -> dict[int, float]:
        """The crucial corners as {number: s (m)}, the mapping the plotting functions take."""
        return {c.number: c.s for c in self.corners}

    # ------------------------------------------------------------ profiles
    def width_left(self, s: ArrayLike) -> np.ndarray:
        """Distance from the centerline to the left edge at s, m."""
        return self._wl.scalar(float(s)) if np.ndim(s) == 0 else self._wl(s)

    def width_right(self, s: ArrayLike) -> np.ndarray:
        """Distance from the centerline to the right edge at s, m."""
        return self._wr.scalar(float(s)) if np.ndim(s) == 0 else self._wr(s)

    def elevation(self, s: ArrayLike) -> np.ndarray:
        """Road height z(s), m."""
        return self._z.scalar(float(s)) if np.ndim(s) == 0 else self._z(s)

    def grade(self, s: ArrayLike) -> np.ndarray:
        """Road pitch theta(s) = atan(dz/ds), rad, positive uphill along +s."""
        out = np.arctan(self._z(np.asarray(s, dtype=float), 1))
        return float(out) if out.ndim == 0 else out

    def curvature(self, s: ArrayLike) -> np.ndarray:
        """Centerline curvature kappa(s), 1/m (shortcut for ``centerline.curvature``)."""
        return self.centerline.curvature(s)

    def edges(
        self, s: ArrayLike | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Edge points (x_left, y_left, x_right, y_right), m, at s (default: the knots)."""
        s = self.centerline.knots if s is None else np.asarray(s, dtype=float)
        xl, yl, _ = self.centerline.to_cartesian(s, self._wl(s))
        xr, yr, _ = self.centerline.to_cartesian(s, -self._wr(s))
        return xl, yl, xr, yr

    # ------------------------------------------------------------ identity
    def checksum(self) -> str:
        """Stable hash (hex, 16 characters) of the geometry: centerline, widths, elevation.

        Computed from values at 1 m steps rounded to 0.1 mm, so it does not depend on the
        floating-point noise of the spline fit, nor on the name or the boundary kind.
        """
        s = self.centerline.sample(ds=1.0)
        x, y = self.centerline.position(s)
        data = np.column_stack([x, y, self._wl(s), self._wr(s), self._z(s)])
        q = np.rint(data * 1e4).astype(np.int64)
        digest = hashlib.sha256()
        digest.update(f"racing_lib.geometry v1 n={len(s)};".encode())
        digest.update(q.tobytes())
        return digest.hexdigest()[:16]

    def __repr__(self) -> str:
        wl, wr = self._wl(self.centerline.sample()), self._wr(self.centerline.sample())
        return (
            f"Track({self.name!r}, length={self.length:.1f} m, width={np.min(wl + wr):.1f}-"
            f"{np.max(wl + wr):.1f} m, boundary={self.boundary!r})"
        )

    # ------------------------------------------------------------ files
    @classmethod
    def from_csv(
        cls, path: str | os.PathLike, name: str | None = None, boundary: Boundary = "open"
    ) -> Track:
        """Read a track in the racetrack-database CSV format.

        The file starts with the header ``# x_m,y_m,w_tr_right_m,w_tr_left_m`` (optionally
        ``,z_m`` for elevation) followed by one centerline point per row; the loop is closed
        implicitly (a last row repeating the first is accepted and dropped).

        Parameters
        ----------
        path : str or os.PathLike
            The CSV file.
        name : str, optional
            Track name (default: the file name without extension).
        boundary : {"walls", "open"}
            Boundary kind (the format does not store it).

        Raises
        ------
        TrackError
            Missing or unreadable file, wrong columns, NaN, too few points, non-positive widths,
            repeated points, an open or self-intersecting centerline; the message names the file,
            the row and the fix.
        """
        fpath = _FsPath(path)
        rows, has_z = read_track_rows(fpath)
        data = np.array([r[1] for r in rows], dtype=float)
        lines = [r[0] for r in rows]
        where = f"Track file {str(fpath)!r}"
        if len(data) >= 2 and np.hypot(*(data[-1, :2] - data[0, :2])) < DUPLICATE_TOL:
            data, lines = data[:-1], lines[:-1]  # last row repeats the first: closed explicitly
        keep = thin_dense_rows(data[:, :2], where)
        data, lines = data[keep], [lines[k] for k in keep]
        if len(data) < 4:
            raise TrackError(
                f"{where} has {len(data)} centerline point(s); a closed track needs at least 4 "
                "rows of x_m,y_m,w_tr_right_m,w_tr_left_m."
            )
        for col, side in ((2, "right"), (3, "left")):
            bad = np.flatnonzero(data[:, col] <= 0.0)
            if len(bad):
                raise TrackError(
                    f"{where}, line {lines[bad[0]]}: {side} width w_tr_{side}_m = "
                    f"{data[bad[0], col]:g} m is not positive; widths are distances from the "
                    "centerline to each edge and must be > 0."
                )
        xy = data[:, :2]
        step = np.hypot(*np.diff(xy, axis=0).T)
        bad = np.flatnonzero(step < DUPLICATE_TOL)
        if len(bad):
            i = bad[0]
            raise TrackError(
                f"{where}, lines {lines[i]} and {lines[i + 1]}: duplicate consecutive point "
                f"({xy[i, 0]:g}, {xy[i, 1]:g}); delete one of the two rows."
            )
        pairs = cKDTree(xy).query_pairs(r=DUPLICATE_TOL, output_type="ndarray")
        if len(pairs):
            i, j = sorted(pairs[0].tolist())
            raise TrackError(
                f"{where}, lines {lines[i]} and {lines[j]}: the centerline passes through the "
                f"same point ({xy[i, 0]:g}, {xy[i, 1]:g}) twice (duplicate point); a track must "
                "not touch or cross itself: fix or delete one of the rows."
            )
        gap = float(np.hypot(*(xy[-1] - xy[0])))
        spacing = float(np.median(step))
        if gap > 5.0 * spacing and gap > 2.0 * float(np.max(step)):
            raise TrackError(
                f"{where}: the centerline is open: its last point (line {lines[-1]}) is "
                f"{gap:.1f} m from its first (line {lines[0]}) while points are about "
                f"{spacing:.1f} m apart. The loop must be closed: the file lists one lap and the "
                "last point is joined to the first, so add the missing points up to the start."
            )
        s_rows = np.concatenate([[0.0], np.cumsum(step)])
        loop_length = float(s_rows[-1] + gap)

        def describe(c: Crossing) -> str:
            i, j = c.segment_a, c.segment_b
            return (
                f"{where}: the centerline crosses itself between lines {lines[i]}-"
                f"{lines[(i + 1) % len(lines)]} and {lines[j]}-{lines[(j + 1) % len(lines)]} "
                f"at {c.angle_deg:.0f} degrees; a track must be a closed loop that crosses itself "
                f"only at bridges (two stretches at least {BRIDGE_MIN_SEPARATION:.0f} m apart "
                f"along the lap, at {BRIDGE_MIN_ANGLE_DEG:.0f} degrees or more): fix the points "
                "there."
            )

        refuse_broken_crossing(find_crossings(xy, s_rows), loop_length, describe)
        try:
            centerline = Path(xy[:, 0], xy[:, 1])
        except TrackError as err:
            raise TrackError(f"{where}: {err}") from None
        s_rows = centerline.s_input  # the rows are knots of the centerline
        try:
            return cls(
                centerline,
                width_left=data[:, 3],
                width_right=data[:, 2],
                elevation=data[:, 4] if has_z else 0.0,
                s=s_rows,
                boundary=boundary,
                name=fpath.stem if name is None else name,
            )
        except TrackError as err:
            raise TrackError(f"{where}: {err}") from None

    def to_csv(self, path: str | os.PathLike, spacing: float = 5.0) -> None:
        """Write the track in the racetrack-database CSV format, atomically.

        Parameters
        ----------
        path : str or os.PathLike
            Destination file; written to a temporary file in the same folder, then renamed, so
            an interrupted write never leaves a partial file.
        spacing : float, optional
            Distance between written centerline points, m. A ``z_m`` column is added when the
            elevation is not flat.
        """
        if not spacing > 0:
            raise TrackError(f"CSV point spacing must be positive, got {spacing!r} m.")
        s = self.centerline.sample(ds=spacing)
        if len(s) < 4:
            s = self.centerline.sample(n=4)
        x, y = self.centerline.position(s)
        z = self._z(s)
        cols = [x, y, self._wr(s), self._wl(s)]
        header = "# " + ",".join(CSV_COLUMNS)
        if np.ptp(z) > 0.0 or np.any(z != 0.0):
            cols.append(z)
            header += ",z_m"
        body = "\n".join(",".join(f"{v:.6f}" for v in row) for row in np.column_stack(cols))
        write_track_text(_FsPath(path), header + "\n" + body + "\n")


# --------------------------------------------------------------------------------------------
# Checks and loading
# --------------------------------------------------------------------------------------------


def wall_clearance(track: Track, ds: float = 1.0, neighbourhood: float | None = None) -> float:
    """Smallest gap, m, between the road of one part of the track and the road of another.

    For every sample, distance from its centerline point to centerline points farther than
    ``neighbourhood`` m along s, minus both half-widths on the facing sides (taken as the larger
    width, a conservative bound). Positive means edges (walls) of different parts never overlap.

    Parameters
    ----------
    track : Track
    ds : float
        Sampling step, m.
    neighbourhood : float, optional
        Parts of the track closer than this along s count as the same part (default: 4 times the
        largest total width plus 50 m, so the inside of a hairpin is not compared with itself).
    """
    s = track.centerline.sample(ds=ds)
    x, y = track.centerline.position(s)
    w = np.maximum(track.width_left(s), track.width_right(s))
    if neighbourhood is None:
        neighbourhood = 4.0 * float(np.max(track.width_left(s) + track.width_right(s))) + 50.0
    tree = cKDTree(np.column_stack([x, y]))
    reach = 2.0 * float(np.max(w)) + 50.0
    pairs = tree.query_pairs(r=reach, output_type="ndarray")
    if len(pairs) == 0:
        return reach
    i, j = pairs[:, 0], pairs[:, 1]
    along = np.abs(s[i] - s[j])
    along = np.minimum(along, track.length - along)
    far = along > neighbourhood
    if not np.any(far):
        return reach
    i, j = i[far], j[far]
    gap = np.hypot(x[i] - x[j], y[i] - y[j]) - w[i] - w[j]
    return float(np.min(gap))
