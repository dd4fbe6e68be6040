"""Tracks and paths: arc length, curvature and Frenet coordinates.

A :class:`Path` is a closed, C2, arc-length parametrized curve (a periodic cubic spline) with its
heading psi(s), curvature kappa(s) and dkappa/ds, and the conversion between Cartesian (x, y, psi)
and Frenet (s, e_y, e_psi) coordinates. A :class:`FrenetTracker` keeps the projection of a moving
car on a path cheaply from one call to the next. A :class:`Track` is a centerline path plus the
widths to its left and right edges, an elevation profile and the boundary kind (``walls`` or
``open``), read from and written to the racetrack-database CSV format.

Taught in notebook 00 (tracks and Frenet coordinates).

Conventions
-----------
* s : arc length along the path, m, in [0, length); every function takes s modulo length.
* e_y : lateral offset, m, positive to the LEFT of the path (the direction of travel).
* e_psi : heading error psi - psi_path(s), rad, wrapped to [-pi, pi).
* kappa : curvature, 1/m, positive for a left (counter-clockwise) turn.
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
from racing_lib.io import atomic_write_text
from racing_lib.track_geometry import (
    OVERLAP_STEP,
    clip_inner_widths,
    road_overlaps,
    thin_dense_rows,
)

__all__ = [
    "CSV_COLUMNS",
    "Corner",
    "FrenetTracker",
    "Path",
    "Track",
    "builtin_track_names",
    "load_track",
    "wall_clearance",
]

Boundary = Literal["walls", "open"]

#: Column names of the racetrack-database format; ``z_m`` (elevation) is optional.
CSV_COLUMNS = ("x_m", "y_m", "w_tr_right_m", "w_tr_left_m")

_RESOLUTION = 0.5  # [m] knot spacing of the arc-length spline every Path is resampled to
_DUPLICATE_TOL = 1e-3  # [m] two input points closer than this are the same point
_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(10)  # quadrature for arc lengths
_TWO_PI = 2.0 * math.pi


def _wrap_angle(a):
    """Wrap an angle (rad, scalar or array) to [-pi, pi)."""
    return (np.asarray(a) + math.pi) % _TWO_PI - math.pi


# --------------------------------------------------------------------------------------------
# A periodic cubic spline on uniform knots, evaluated by hand (no scipy call per evaluation)
# --------------------------------------------------------------------------------------------


class _Knots:
    """Knots 0 = s_0 < s_1 < ... < s_n = period of a periodic spline, with fast lookup.

    Vectorized lookup uses ``np.searchsorted``; scalar lookup uses a table of uniform buckets
    (each bucket knows the last knot at or before its start) and steps forward over the one or
    two knots inside the bucket, in plain Python.
    """

    def __init__(self, knots: np.ndarray) -> None:
        self.s = np.asarray(knots, dtype=float)
        self.n = len(self.s) - 1
        self.period = float(self.s[-1])
        self.hb = float(np.median(np.diff(self.s)))  # bucket width
        nb = int(self.period / self.hb) + 2
        self._bucket = (np.searchsorted(self.s, np.arange(nb) * self.hb, side="right") - 1).tolist()
        self._s_list = self.s.tolist()

    def locate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Piece index k and local coordinate t = s - s_k for s (wrapped to [0, period))."""
        s = np.mod(s, self.period)
        k = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, self.n - 1)
        return k, s - self.s[k]

    def locate_scalar(self, s: float) -> tuple[int, float]:
        """As :meth:`locate` for one float, without numpy."""
        if not -1e12 < s < 1e12:  # NaN fails both comparisons
            raise TrackError(f"Arc length s must be a finite number of metres, got {s!r}.")
        s = s % self.period
        k = self._bucket[int(s / self.hb)]
        knots = self._s_list
        while s >= knots[k + 1]:
            k += 1
        if k >= self.n:
            k = self.n - 1
        return k, s - knots[k]


class _PeriodicSpline:
    """Periodic cubic spline through values at the knots (values (n,) or (n, d)).

    The coefficients are kept as numpy arrays (vectorized evaluation) and as Python lists
    (scalar evaluation without numpy overhead, which matters in per-step loops).
    """

    def __init__(self, knots: _Knots, values: np.ndarray) -> None:
        values = np.asarray(values, dtype=float)
        closed = np.concatenate([values, values[:1]], axis=0)
        spline = CubicSpline(knots.s, closed, bc_type="periodic", axis=0)
        self.knots = knots
        self.c = np.ascontiguousarray(spline.c)  # (4, n) or (4, n, d): c3 t^3 + c2 t^2 + c1 t + c0
        self._lists = [self.c[i].tolist() for i in range(4)]

    def __call__(self, s: ArrayLike, der: int = 0) -> np.ndarray:
        """Evaluate the spline (der = 0) or its derivative of order der (1..3) at s."""
        k, t = self.knots.locate(np.asarray(s, dtype=float))
        c3, c2, c1, c0 = (self.c[i][k] for i in range(4))
        if self.c.ndim == 3:
            t = t[..., None]
        if der == 0:
            return ((c3 * t + c2) * t + c1) * t + c0
        if der == 1:
            return (3.0 * c3 * t + 2.0 * c2) * t + c1
        if der == 2:
            return 6.0 * c3 * t + 2.0 * c2
        if der == 3:
            return 6.0 * c3 + 0.0 * t
        raise ValueError(f"derivative order {der} not supported (0..3)")

    def scalar(self, s: float) -> float:
        """Value at a scalar s for a 1-D spline, with plain Python floats."""
        k, t = self.knots.locate_scalar(s)
        c3, c2, c1, c0 = self._lists
        return ((c3[k] * t + c2[k]) * t + c1[k]) * t + c0[k]


# --------------------------------------------------------------------------------------------
# Path
# --------------------------------------------------------------------------------------------


def _segment_arc_lengths(spline: CubicSpline, t: np.ndarray) -> np.ndarray:
    """Arc length of each piece [t_i, t_i+1] of a 2-D spline, by Gauss-Legendre quadrature."""
    dt = np.diff(t)
    nodes = t[:-1, None] + 0.5 * (1.0 + _GL_NODES[None, :]) * dt[:, None]
    d = spline(nodes, 1)
    speed = np.hypot(d[..., 0], d[..., 1])
    return 0.5 * dt * (speed @ _GL_WEIGHTS)


def _partial_arc_length(spline: CubicSpline, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """Arc length of a 2-D spline from t0 to t1 (elementwise), by Gauss-Legendre quadrature."""
    dt = t1 - t0
    nodes = t0[:, None] + 0.5 * (1.0 + _GL_NODES[None, :]) * dt[:, None]
    d = spline(nodes, 1)
    return 0.5 * dt * (np.hypot(d[..., 0], d[..., 1]) @ _GL_WEIGHTS)


def _arc_length_fit(points: np.ndarray, tol: float = 1e-11) -> tuple[CubicSpline, np.ndarray]:
    """Periodic spline through closed-loop points whose knots sit at its own arc length.

    Start from the chord-length parametrization and iterate: measure the arc length of each
    piece, move the knots there, refit. A few iterations reach ``tol`` (relative).
    """
    closed = np.vstack([points, points[:1]])
    t = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    for _ in range(30):
        spline = CubicSpline(t, closed, bc_type="periodic", axis=0)
        t_new = np.concatenate([[0.0], np.cumsum(_segment_arc_lengths(spline, t))])
        done = np.max(np.abs(t_new - t)) <= tol * t_new[-1]
        t = t_new
        if done:
            break
    return CubicSpline(t, closed, bc_type="periodic", axis=0), t


def _invert_arc_length(spline: CubicSpline, t_knots: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Spline parameters t with arc length s, for a spline whose knots are at arc length.

    Newton on arc(t) - s with arc(t) = t_k + integral of |r'| from t_k to t; the parameter is
    already close to arc length, so the start t = s is good and three steps reach 1e-12 m.
    """
    t = s.copy()
    period = t_knots[-1]
    for _ in range(4):
        k = np.clip(np.searchsorted(t_knots, t, side="right") - 1, 0, len(t_knots) - 2)
        arc = t_knots[k] + _partial_arc_length(spline, t_knots[k], t)
        d = spline(t, 1)
        t = np.clip(t - (arc - s) / np.hypot(d[:, 0], d[:, 1]), 0.0, period)
    return t


def _segments_intersect(p1, p2, q1, q2) -> np.ndarray:
    """Elementwise proper intersection test of segments p1-p2 and q1-q2 (arrays (m, 2))."""

    def orient(a, b, c):
        return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])

    d1, d2 = orient(q1, q2, p1), orient(q1, q2, p2)
    d3, d4 = orient(p1, p2, q1), orient(p1, p2, q2)
    return (d1 * d2 < 0.0) & (d3 * d4 < 0.0)


def _self_intersections(xy: np.ndarray) -> list[tuple[int, int]]:
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


def _crossings(xy: np.ndarray, s: np.ndarray) -> list[Crossing]:
    """The crossings of the closed polyline ``xy`` (n, 2), vertices at arc lengths ``s`` (m)."""
    nxt = np.roll(xy, -1, axis=0)
    out = []
    for i, j in _self_intersections(xy):
        da, db = nxt[i] - xy[i], nxt[j] - xy[j]
        cos = abs(float(np.dot(da, db))) / (float(np.hypot(*da) * np.hypot(*db)) + 1e-300)
        angle = math.degrees(math.acos(min(1.0, cos)))
        out.append(Crossing(float(s[i]), float(s[j]), angle, int(i), int(j)))
    return out


def _refuse_broken_crossing(crossings: list[Crossing], length: float, describe) -> None:
    """Raise TrackError for the first crossing that is not a bridge (``describe(c)`` words it)."""
    for c in crossings:
        if not c.is_bridge(length):
            raise TrackError(describe(c))


class Path:
    """A closed C2 curve parametrized by arc length s (m).

    The points are joined by a periodic cubic spline, reparametrized by its true arc length and
    resampled on uniform knots about 0.5 m apart, so that |dr/ds| = 1 to about 1e-6 and every
    evaluation is a cubic polynomial in s.

    Parameters
    ----------
    x, y : array_like, shape (n,)
        Points of a closed loop in order of travel, m; the loop is closed implicitly (the last
        point is joined to the first; a last point equal to the first is dropped). n >= 4.
    resolution : float, optional
        Target knot spacing of the arc-length spline, m.
    check : bool, optional
        Refuse a curve that crosses itself (default True), unless the crossing is a bridge: two
        stretches at least :data:`BRIDGE_MIN_SEPARATION` apart along the loop, meeting at
        :data:`BRIDGE_MIN_ANGLE_DEG` or more, as in a figure-eight circuit.

    Attributes
    ----------
    length : float
        Total arc length, m.
    crossings : list of Crossing
        The bridges of the curve (empty for a simple loop).

    Raises
    ------
    TrackError
        Too few points, NaN/inf, repeated consecutive points, or a curve that crosses itself other
        than at a bridge.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    >>> p = Path(50 * np.cos(a), 50 * np.sin(a))
    >>> round(p.length, 3), round(float(p.curvature(10.0)), 5)
    (314.159, 0.02)
    """

    def __init__(
        self, x: ArrayLike, y: ArrayLike, *, resolution: float = _RESOLUTION, check: bool = True
    ) -> None:
        pts = _coordinates(x, y)
        if not np.all(np.isfinite(pts)):
            bad = int(np.flatnonzero(~np.all(np.isfinite(pts), axis=1))[0])
            raise TrackError(f"Path point {bad} is NaN or infinite; give finite x, y in metres.")
        if len(pts) >= 2 and np.hypot(*(pts[-1] - pts[0])) < _DUPLICATE_TOL:
            pts = pts[:-1]  # the loop is closed implicitly; a repeated first point is dropped
        if len(pts) < 4:
            raise TrackError(
                f"A closed path needs at least 4 distinct points, got {len(pts)}; add points."
            )
        step = np.hypot(*(np.roll(pts, -1, axis=0) - pts).T)
        if np.any(step < _DUPLICATE_TOL):
            bad = int(np.flatnonzero(step < _DUPLICATE_TOL)[0])
            raise TrackError(
                f"Path points {bad} and {(bad + 1) % len(pts)} coincide; remove the duplicate."
            )
        spline0, t0 = _arc_length_fit(pts)
        # Subdivide every input piece into equal arc-length parts about `resolution` long. The
        # input points stay knots, so the corners of the first fit (its third derivative jumps
        # there) are knots of the new spline too, and the refit reproduces the curve closely.
        # Tight curves get shorter parts (h |kappa| <= 0.02) so that |dr/ds| stays 1 to ~1e-6
        # there too (the deviation grows like (h kappa)^3 / 24).
        probe = t0[:-1, None] + np.linspace(0.0, 1.0, 5)[None, :] * np.diff(t0)[:, None]
        d1, d2 = spline0(probe, 1), spline0(probe, 2)
        kappa = (
            np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
            / np.hypot(d1[..., 0], d1[..., 1]) ** 3
        )
        h_local = np.minimum(resolution, 0.02 / np.maximum(kappa.max(axis=1), 1e-12))
        parts = np.maximum(np.ceil(np.diff(t0) / h_local).astype(int), 1)
        frac = np.concatenate([np.arange(m) / m for m in parts])
        piece = np.repeat(np.arange(len(parts)), parts)
        s_res = t0[piece] + frac * np.diff(t0)[piece]
        resampled = spline0(_invert_arc_length(spline0, t0, s_res))
        self._init_knots(resampled)
        #: Arc length of each input point on the final path, m.
        self.s_input = self._knots.s[np.concatenate([[0], np.cumsum(parts)[:-1]])].copy()
        self.crossings = _crossings(self._knots_xy, self._knots.s) if check else []
        if check:

            def describe(c: Crossing) -> str:
                x, y = self.position(c.s_a)
                return (
                    f"The path crosses itself near s = {c.s_a:.1f} m and s = {c.s_b:.1f} m "
                    f"(x = {float(x):.1f}, y = {float(y):.1f}) at {c.angle_deg:.0f} degrees; fix "
                    "the points so the loop does not cross (only two stretches at least "
                    f"{BRIDGE_MIN_SEPARATION:.0f} m apart along the lap may cross, at "
                    f"{BRIDGE_MIN_ANGLE_DEG:.0f} degrees or more, as on a bridge)."
                )

            _refuse_broken_crossing(self.crossings, self.length, describe)

    def _init_knots(self, knots_xy: np.ndarray) -> None:
        """Fit the final spline with its knots at its own arc length."""
        spline, t = _arc_length_fit(knots_xy)
        self.length = float(t[-1])
        self._knots = _Knots(t)
        self._n = len(knots_xy)
        self._knots_xy = np.ascontiguousarray(knots_xy)
        self._xy = _PeriodicSpline(self._knots, knots_xy)
        c = self._xy.c
        # Python-float copies of the coefficients for the scalar (per-step) code paths.
        self._cx = [c[i, :, 0].tolist() for i in range(4)]
        self._cy = [c[i, :, 1].tolist() for i in range(4)]
        d = self._xy(t[:-1], 1)
        self._knot_heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        self._kdtree: cKDTree | None = None

    # ---------------------------------------------------------------- evaluation
    @property
    def knots(self) -> np.ndarray:
        """Arc lengths of the spline knots, m (n values in [0, length), about 0.5 m apart)."""
        return self._knots.s[:-1].copy()

    def sample(self, n: int | None = None, ds: float | None = None) -> np.ndarray:
        """Equally spaced arc lengths over one lap, m, starting at 0 (length excluded).

        Parameters
        ----------
        n : int, optional
            Number of samples.
        ds : float, optional
            Approximate spacing, m (rounded so the samples divide the lap evenly). With neither
            n nor ds: as many samples as the spline has knots.
        """
        if n is None and ds is None:
            n = self._n
        if n is None:
            if not ds > 0:
                raise TrackError(f"Sample spacing ds must be positive, got {ds!r}.")
            n = max(int(round(self.length / ds)), 1)
        if n < 1:
            raise TrackError(f"Number of samples must be at least 1, got {n!r}.")
        return np.arange(n) * (self.length / n)

    def position(self, s: ArrayLike) -> tuple:
        """Position x(s), y(s), m. Scalar s gives floats; s wraps modulo the length."""
        if np.ndim(s) == 0:
            x, y, *_ = self._eval_scalar(float(s))
            return x, y
        p = self._xy(np.asarray(s, dtype=float))
        return p[..., 0], p[..., 1]

    def tangent(self, s: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Unit tangent (cos psi, sin psi) at s."""
        d = self._xy(np.asarray(s, dtype=float), 1)
        v = np.hypot(d[..., 0], d[..., 1])
        return d[..., 0] / v, d[..., 1] / v

    def heading(self, s: ArrayLike) -> np.ndarray:
        """Heading psi(s), rad, continuous over one lap (grows by 2 pi per CCW lap)."""
        s = np.mod(np.asarray(s, dtype=float), self.length)
        d = self._xy(s, 1)
        raw = np.arctan2(d[..., 1], d[..., 0])
        k, _ = self._knots.locate(s)
        ref = self._knot_heading[k]
        out = ref + _wrap_angle(raw - ref)
        return float(out) if out.ndim == 0 else out

    def curvature(self, s: ArrayLike) -> np.ndarray:
        """Curvature kappa(s), 1/m, positive for left turns."""
        s = np.asarray(s, dtype=float)
        d1, d2 = self._xy(s, 1), self._xy(s, 2)
        cross = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
        out = cross / np.hypot(d1[..., 0], d1[..., 1]) ** 3
        return float(out) if out.ndim == 0 else out

    def curvature_derivative(self, s: ArrayLike) -> np.ndarray:
        """dkappa/ds, 1/m^2 (piecewise continuous: the spline is C2, not C3)."""
        s = np.asarray(s, dtype=float)
        d1, d2, d3 = self._xy(s, 1), self._xy(s, 2), self._xy(s, 3)
        v2 = d1[..., 0] ** 2 + d1[..., 1] ** 2
        cross = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
        dcross = d1[..., 0] * d3[..., 1] - d1[..., 1] * d3[..., 0]
        dot = d1[..., 0] * d2[..., 0] + d1[..., 1] * d2[..., 1]
        # kappa = cross / v^3: dkappa/dt = (dcross v^2 - 3 cross dot) / v^5, and d/ds = d/dt / v.
        out = (dcross * v2 - 3.0 * cross * dot) / (v2 * v2 * v2)
        return float(out) if out.ndim == 0 else out

    def speed(self, s: ArrayLike) -> np.ndarray:
        """|dr/ds| of the parametrization, 1 up to about 1e-6 (a diagnostic)."""
        d = self._xy(np.asarray(s, dtype=float), 1)
        return np.hypot(d[..., 0], d[..., 1])

    def _eval_scalar(self, s: float) -> tuple[float, float, float, float, float, float]:
        """x, y, x', y', x'', y'' at scalar s with Python floats."""
        k, t = self._knots.locate_scalar(s)
        a3, a2, a1, a0 = self._cx[0][k], self._cx[1][k], self._cx[2][k], self._cx[3][k]
        b3, b2, b1, b0 = self._cy[0][k], self._cy[1][k], self._cy[2][k], self._cy[3][k]
        return (
            ((a3 * t + a2) * t + a1) * t + a0,
            ((b3 * t + b2) * t + b1) * t + b0,
            (3.0 * a3 * t + 2.0 * a2) * t + a1,
            (3.0 * b3 * t + 2.0 * b2) * t + b1,
            6.0 * a3 * t + 2.0 * a2,
            6.0 * b3 * t + 2.0 * b2,
        )

    # ---------------------------------------------------------------- Frenet frame
    def _nearest_knot_s(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Global search: arc length of the knot nearest to each point."""
        if self._kdtree is None:
            self._kdtree = cKDTree(self._knots_xy)
        _, k = self._kdtree.query(np.column_stack([x, y]))
        return self._knots.s[k]

    def _nearest_knot_near(self, x: float, y: float, s0: float, window: float) -> float:
        """Arc length of the knot nearest (x, y) among those within ``window`` of ``s0``, m.

        The local search of a point that moves along the path: where the path crosses itself
        (a bridge), the globally nearest knot may lie on the other branch.
        """
        knots = self._knots.s[:-1]
        n = len(knots)
        lo = int(np.searchsorted(knots, s0 - window))
        hi = int(np.searchsorted(knots, s0 + window, side="right"))
        if s0 - window < 0.0:
            lo -= n - int(np.searchsorted(knots, s0 - window + self.length))
        if s0 + window >= self.length:
            hi += int(np.searchsorted(knots, s0 + window - self.length, side="right"))
        idx = np.arange(lo, max(hi, lo + 1)) % n
        d2 = (self._knots_xy[idx, 0] - x) ** 2 + (self._knots_xy[idx, 1] - y) ** 2
        return float(knots[idx[int(np.argmin(d2))]])

    def to_frenet_along(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Frenet (s, e_y) of points that follow one another along the path (a line, a log).

        Each point is projected near its predecessor (:class:`FrenetTracker`), so where the path
        crosses itself every point stays on the branch it is on; :meth:`to_frenet` takes the
        nearest branch.

        Parameters
        ----------
        x, y : array_like, shape (n,)
            Positions in order of travel, m.

        Returns
        -------
        s, e_y : ndarray, shape (n,)
            Arc length (m, in [0, length)) and signed offset (m, positive left).
        """
        xa = np.asarray(x, dtype=float).ravel()
        ya = np.asarray(y, dtype=float).ravel()
        if xa.shape != ya.shape:
            raise TrackError(
                f"to_frenet_along needs as many x as y values, got {xa.size} and {ya.size}."
            )
        tracker = FrenetTracker(self)
        s = np.empty(xa.size)
        e_y = np.empty(xa.size)
        for k in range(xa.size):
            s[k], e_y[k] = tracker.project(xa[k], ya[k])
        return s, e_y

    def _newton(self, x: np.ndarray, y: np.ndarray, s: np.ndarray, iters: int = 30) -> np.ndarray:
        """Refine s to the foot point of (x, y): solve (r(s) - p) . r'(s) = 0 by Newton.

        The derivative 1 - kappa e_y is floored so that points near a centre of curvature
        (inside a hairpin) take damped steps instead of wild ones; steps are limited to a few
        knots so the iteration stays in the basin found by the search.
        """
        s = s.copy()
        max_step = 4.0 * self._knots.hb + 2.0
        for _ in range(iters):
            p, d1, d2 = self._xy(s), self._xy(s, 1), self._xy(s, 2)
            rx, ry = p[:, 0] - x, p[:, 1] - y
            f = rx * d1[:, 0] + ry * d1[:, 1]
            fp = d1[:, 0] ** 2 + d1[:, 1] ** 2 + rx * d2[:, 0] + ry * d2[:, 1]
            step = -f / np.maximum(fp, 0.1)
            step = np.clip(step, -max_step, max_step)
            s = np.mod(s + step, self.length)
            s[s >= self.length] = 0.0  # mod of a tiny negative number can round to the length
            if np.max(np.abs(step)) < 1e-11:
                break
        return s

    def _newton_scalar(self, x: float, y: float, s: float) -> tuple[float, float, float, bool]:
        """Foot point of (x, y) by Newton from s, in plain Python floats (see :meth:`_newton`).

        Returns s (m), e_y (m), the path heading at s wrapped to [-pi, pi) (rad) and whether
        the iteration converged.
        """
        length = self.length
        kn = self._knots
        knots, bucket, hb, last = kn._s_list, kn._bucket, kn.hb, kn.n - 1
        max_step = 4.0 * hb + 2.0
        cx0, cx1, cx2, cx3 = self._cx
        cy0, cy1, cy2, cy3 = self._cy
        for _ in range(40):
            # Inline of _Knots.locate_scalar (a function call costs as much as the arithmetic).
            k = bucket[int(s / hb)]
            while s >= knots[k + 1]:
                k += 1
            if k > last:
                k = last
            t = s - knots[k]
            a3, a2, a1, a0 = cx0[k], cx1[k], cx2[k], cx3[k]
            b3, b2, b1, b0 = cy0[k], cy1[k], cy2[k], cy3[k]
            rx = ((a3 * t + a2) * t + a1) * t + a0 - x
            ry = ((b3 * t + b2) * t + b1) * t + b0 - y
            dx = (3.0 * a3 * t + 2.0 * a2) * t + a1
            dy = (3.0 * b3 * t + 2.0 * b2) * t + b1
            f = rx * dx + ry * dy
            fp = dx * dx + dy * dy + rx * (6.0 * a3 * t + 2.0 * a2) + ry * (6.0 * b3 * t + 2.0 * b2)
            if fp < 0.1:
                fp = 0.1  # near a centre of curvature: damped step (see Path._newton)
            step = -f / fp
            if step > max_step:
                step = max_step
            elif step < -max_step:
                step = -max_step
            s = (s + step) % length
            if s >= length:
                s = 0.0
            if -1e-10 < step < 1e-10:
                # e_y from the last evaluation; the point moved by < 1e-10 m since.
                e_y = (rx * dy - ry * dx) / math.sqrt(dx * dx + dy * dy)
                return s, e_y, math.atan2(dy, dx), True
        return s, 0.0, 0.0, False

    def to_frenet(
        self,
        x: ArrayLike,
        y: ArrayLike,
        psi: ArrayLike | None = None,
        s_hint: ArrayLike | None = None,
    ) -> tuple:
        """Cartesian (x, y, psi) to Frenet (s, e_y, e_psi).

        Parameters
        ----------
        x, y : array_like
            Positions, m.
        psi : array_like, optional
            Headings, rad. Without it, e_psi is NaN.
        s_hint : array_like, optional
            Arc lengths near the answer, m (local search); without it a global search over the
            knots starts the Newton refinement.

        Returns
        -------
        s : arc length of the closest path point, m, in [0, length)
        e_y : signed distance, m, positive left of the path
        e_psi : psi - psi_path(s) wrapped to [-pi, pi), rad (NaN if psi is None)

        Scalars in give floats out.
        """
        scalar = np.ndim(x) == 0 and np.ndim(y) == 0
        if (
            scalar
            and (psi is None or np.ndim(psi) == 0)
            and (s_hint is None or np.ndim(s_hint) == 0)
        ):
            out = self._to_frenet_scalar(float(x), float(y), psi, s_hint)
            if out is not None:
                return out
        xa = np.atleast_1d(np.asarray(x, dtype=float)).ravel()
        ya = np.atleast_1d(np.asarray(y, dtype=float)).ravel()
        xa, ya = np.broadcast_arrays(xa, ya)
        if not (np.all(np.isfinite(xa)) and np.all(np.isfinite(ya))):
            raise TrackError("to_frenet got NaN or infinite coordinates; pass finite x, y in m.")
        if s_hint is None:
            s0 = self._nearest_knot_s(xa, ya)
        else:
            s0 = np.mod(
                np.broadcast_to(np.asarray(s_hint, dtype=float).ravel(), xa.shape), self.length
            )
        s = self._newton(xa, ya, s0)
        p, d = self._xy(s), self._xy(s, 1)
        v = np.hypot(d[:, 0], d[:, 1])
        e_y = ((ya - p[:, 1]) * d[:, 0] - (xa - p[:, 0]) * d[:, 1]) / v
        if psi is None:
            e_psi = np.full_like(s, np.nan)
        else:
            psi_a = np.broadcast_to(np.asarray(psi, dtype=float).ravel(), s.shape)
            e_psi = _wrap_angle(psi_a - np.arctan2(d[:, 1], d[:, 0]))
        if scalar:
            return float(s[0]), float(e_y[0]), float(e_psi[0])
        shape = np.broadcast(np.asarray(x), np.asarray(y)).shape
        return s.reshape(shape), e_y.reshape(shape), e_psi.reshape(shape)

    def _to_frenet_scalar(self, x: float, y: float, psi, s_hint) -> tuple | None:
        """Scalar to_frenet without numpy arrays; None if Newton did not converge."""
        if not (math.isfinite(x) and math.isfinite(y)):
            raise TrackError("to_frenet got NaN or infinite coordinates; pass finite x, y in m.")
        if s_hint is None:
            if self._kdtree is None:
                self._kdtree = cKDTree(self._knots_xy)
            _, k = self._kdtree.query((x, y))
            s0 = self._knots._s_list[int(k)]
        else:
            s0 = float(s_hint) % self.length
        s, e_y, heading, ok = self._newton_scalar(x, y, s0)
        if not ok:
            return None
        e_psi = math.nan if psi is None else (float(psi) - heading + math.pi) % _TWO_PI - math.pi
        return s, e_y, e_psi

    def to_cartesian(self, s: ArrayLike, e_y: ArrayLike, e_psi: ArrayLike | None = None) -> tuple:
        """Frenet (s, e_y, e_psi) to Cartesian (x, y, psi); psi = psi_path(s) + e_psi (rad).

        Without e_psi, psi is the path heading. Scalars in give floats out.
        """
        scalar = np.ndim(s) == 0 and np.ndim(e_y) == 0 and (e_psi is None or np.ndim(e_psi) == 0)
        s_a, ey = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(e_y, dtype=float))
        p = self._xy(s_a)
        d = self._xy(s_a, 1)
        v = np.hypot(d[..., 0], d[..., 1])
        nx, ny = -d[..., 1] / v, d[..., 0] / v
        x = p[..., 0] + ey * nx
        y = p[..., 1] + ey * ny
        psi = np.asarray(self.heading(s_a))
        if e_psi is not None:
            psi = psi + np.asarray(e_psi, dtype=float)
        if scalar:
            return float(x), float(y), float(psi)
        return x, y, psi

    def __repr__(self) -> str:
        return f"Path(length={self.length:.3f} m, knots={self._n})"


# --------------------------------------------------------------------------------------------
# FrenetTracker
# --------------------------------------------------------------------------------------------


class FrenetTracker:
    """Keeps the Frenet projection of a moving point on a path, cheaply.

    The first call (or the first after :meth:`reset`) searches the whole path; later calls start
    Newton's method at the previous s, so a call costs a few microseconds of scalar arithmetic.
    When Newton's method fails or jumps, the nearest point within ``max_jump`` of the previous s
    decides, so that where the path crosses itself (a bridge) the point stays on its branch. Only
    a point farther than ``max_jump`` from that stretch (a teleport, a new lap set-up) falls back
    to the global search.

    Parameters
    ----------
    path : Path
        The path to project on.
    max_jump : float, optional
        If local tracking moves s by more than this, m, the global search decides instead.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    >>> tracker = FrenetTracker(Path(50 * np.cos(a), 50 * np.sin(a)))
    >>> s, e_y = tracker.project(49.0, 0.0)
    >>> round(s, 6), round(e_y, 6)
    (0.0, 1.0)
    """

    def __init__(self, path: Path, max_jump: float = 50.0) -> None:
        self.path = path
        self.max_jump = float(max_jump)
        self._s: float | None = None
        self._length = path.length
        self._newton = path._newton_scalar

    def reset(self) -> None:
        """Forget the previous position: the next call searches globally."""
        self._s = None

    @property
    def s(self) -> float | None:
        """The last projected arc length, m (None before the first call)."""
        return self._s

    def project(self, x: float, y: float) -> tuple[float, float]:
        """Arc length s (m) and lateral offset e_y (m, positive left) of the point (x, y)."""
        x = float(x)
        y = float(y)
        if not (math.isfinite(x) and math.isfinite(y)):
            raise TrackError("FrenetTracker.project got NaN or infinite x, y; pass finite values.")
        if self._s is None:
            s, e_y, _ = self.path.to_frenet(x, y)
            self._s = s
            return s, e_y
        s0 = self._s
        s, e_y, _, ok = self._newton(x, y, s0)
        jump = abs(s - s0)
        jump = min(jump, self._length - jump)
        if not ok or jump > self.max_jump:
            s_near = self.path._nearest_knot_near(x, y, s0, self.max_jump)
            s, e_y, _ = self.path.to_frenet(x, y, s_hint=s_near)
            if abs(e_y) > self.max_jump:
                s, e_y, _ = self.path.to_frenet(x, y)
        self._s = s
        return s, e_y


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


def _coordinates(x: ArrayLike, y: ArrayLike) -> np.ndarray:
    """Points (n, 2) from x and y, refusing text and arrays of different lengths."""
    try:
        xa = np.asarray(x, dtype=float).ravel()
        ya = np.asarray(y, dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise TrackError(
            f"Path x and y must be numbers (m), got {type(x).__name__} and {type(y).__name__} "
            f"({exc}); convert them, e.g. with np.asarray(x, dtype=float)."
        ) from None
    if xa.size != ya.size:
        raise TrackError(f"Path x has {xa.size} values but y has {ya.size}; give one y per x (m).")
    return np.column_stack([xa, ya])


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
                f"Track needs a racing_lib.track.Path as its centerline, got "
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
        self._wl = _PeriodicSpline(knots, wl)
        self._wr = _PeriodicSpline(knots, wr)
        self._z = _PeriodicSpline(knots, z)
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
        digest.update(f"racing_lib.track v1 n={len(s)};".encode())
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
        rows, has_z = _read_csv_rows(fpath)
        data = np.array([r[1] for r in rows], dtype=float)
        lines = [r[0] for r in rows]
        where = f"Track file {str(fpath)!r}"
        if len(data) >= 2 and np.hypot(*(data[-1, :2] - data[0, :2])) < _DUPLICATE_TOL:
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
        bad = np.flatnonzero(step < _DUPLICATE_TOL)
        if len(bad):
            i = bad[0]
            raise TrackError(
                f"{where}, lines {lines[i]} and {lines[i + 1]}: duplicate consecutive point "
                f"({xy[i, 0]:g}, {xy[i, 1]:g}); delete one of the two rows."
            )
        pairs = cKDTree(xy).query_pairs(r=_DUPLICATE_TOL, output_type="ndarray")
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

        _refuse_broken_crossing(_crossings(xy, s_rows), loop_length, describe)
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
        _atomic_write_text(_FsPath(path), header + "\n" + body + "\n")


def _read_csv_rows(fpath: _FsPath) -> tuple[list[tuple[int, list[float]]], bool]:
    """Parse a racetrack-database CSV into (line number, values) rows; validate columns."""
    where = f"Track file {str(fpath)!r}"
    if not fpath.exists():
        raise TrackError(
            f"{where} does not exist; check the path, or use a built-in track name "
            f"({', '.join(builtin_track_names())})."
        )
    try:
        # utf-8-sig: a byte-order mark, as some spreadsheet programs write, is dropped.
        text = fpath.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as err:
        raise TrackError(
            f"{where} cannot be read ({err}); check that it is a readable text CSV."
        ) from None
    lines = text.splitlines()
    header_idx = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if header_idx is None:
        raise TrackError(f"{where} is empty; expected the header '# {','.join(CSV_COLUMNS)}'.")
    names = [c.strip() for c in lines[header_idx].lstrip().lstrip("#").split(",")]
    expected = list(CSV_COLUMNS)
    if names not in (expected, [*expected, "z_m"]):
        raise TrackError(
            f"{where}, line {header_idx + 1}: wrong columns {names}; expected the header "
            f"'# {','.join(CSV_COLUMNS)}' (optionally ',z_m' for elevation)."
        )
    ncol = len(names)
    rows: list[tuple[int, list[float]]] = []
    for i in range(header_idx + 1, len(lines)):
        raw = lines[i].strip()
        if not raw or raw.startswith("#"):
            continue
        parts = raw.split(",")
        if len(parts) != ncol:
            raise TrackError(
                f"{where}, line {i + 1}: {len(parts)} values, expected {ncol} "
                f"({','.join(names)}); fix the row."
            )
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise TrackError(
                f"{where}, line {i + 1}: {raw!r} is not numeric; every row needs {ncol} numbers."
            ) from None
        if not all(math.isfinite(v) for v in vals):
            raise TrackError(
                f"{where}, line {i + 1}: NaN or infinite value in {raw!r}; give finite metres."
            )
        rows.append((i + 1, vals))
    return rows, ncol == 5


def _atomic_write_text(target: _FsPath, text: str) -> None:
    """Write text to ``target`` atomically, with a clear error if its folder does not exist."""
    folder = target.parent if str(target.parent) else _FsPath(".")
    if not folder.is_dir():
        raise TrackError(f"Cannot write {str(target)!r}: folder {str(folder)!r} does not exist.")
    atomic_write_text(target, text)


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


def builtin_track_names() -> list[str]:
    """Names of the built-in tracks, e.g. ``["expressway", "shortcut"]``."""
    from racing_lib import tracks

    return list(tracks.BUILTIN)


def load_track(name_or_file: str | os.PathLike) -> Track:
    """A built-in track by name (case-insensitive) or a track from a CSV file.

    Parameters
    ----------
    name_or_file : str, os.PathLike or Track
        ``"expressway"``, ``"shortcut"``... or a path to a racetrack-database CSV (a Track is
        returned as it is).

    Raises
    ------
    TrackError
        Unknown name (the message lists the built-in names), or a bad CSV file.
    """
    from racing_lib import tracks

    if isinstance(name_or_file, Track):
        return name_or_file
    if not isinstance(name_or_file, str | os.PathLike):
        raise TrackError(
            f"load_track needs a track name or a CSV path, got {name_or_file!r}; built-in "
            f"tracks are {', '.join(builtin_track_names())}."
        )
    text = os.fspath(name_or_file)
    key = text.strip().lower()
    if key in tracks.BUILTIN:
        return tracks.BUILTIN[key]()
    if key.endswith(".csv") or os.sep in text or _FsPath(text).exists():
        return Track.from_csv(text)
    raise TrackError(
        f"Unknown track {text!r}: built-in tracks are {', '.join(builtin_track_names())}; a path "
        "to a racetrack-database CSV file (.csv) is also accepted."
    )
