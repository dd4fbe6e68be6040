"""Paths: closed, arc-length parametrized curves with curvature and Frenet coordinates.

A :class:`Path` is a closed, C2, arc-length parametrized curve (a periodic cubic spline) with its
heading psi(s), curvature kappa(s) and dkappa/ds, and the conversion between Cartesian (x, y, psi)
and Frenet (s, e_y, e_psi) coordinates. Taught in notebook 01.

Conventions
-----------
* s : arc length along the path, m, in [0, length); every function takes s modulo length.
* e_y : lateral offset, m, positive to the LEFT of the path (the direction of travel).
* e_psi : heading error psi - psi_path(s), rad, wrapped to [-pi, pi).
* kappa : curvature, 1/m, positive for a left (counter-clockwise) turn.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from racing_lib.errors import TrackError
from racing_lib.geometry.crossings import (
    BRIDGE_MIN_ANGLE_DEG,
    BRIDGE_MIN_SEPARATION,
    Crossing,
    find_crossings,
    refuse_broken_crossing,
)
from racing_lib.geometry.spline import (
    TWO_PI,
    Knots,
    PeriodicSpline,
    arc_length_fit,
    invert_arc_length,
    wrap_angle,
)

__all__ = ["DUPLICATE_TOL", "FrenetTracker", "Path", "chord_arc_length"]

_RESOLUTION = 0.5  # [m] knot spacing of the arc-length spline every Path is resampled to
DUPLICATE_TOL = 1e-3  # [m] two input points closer than this are the same point


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


def chord_arc_length(x: np.ndarray, y: np.ndarray, length: float) -> np.ndarray:
    """Arc length of closed-loop nodes (x, y), m from the first: chords scaled to ``length``.

    Chords fall short of a spline's arc length by O(ds^3 kappa^2) per interval; scaling them to
    the spline's ``length`` (m) removes the error that would add up over a lap.
    """
    chord = np.hypot(np.diff(np.append(x, x[0])), np.diff(np.append(y, y[0])))
    s = np.concatenate(([0.0], np.cumsum(chord[:-1])))
    return s * float(length) / float(np.sum(chord))


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
        if len(pts) >= 2 and np.hypot(*(pts[-1] - pts[0])) < DUPLICATE_TOL:
            pts = pts[:-1]  # the loop is closed implicitly; a repeated first point is dropped
        if len(pts) < 4:
            raise TrackError(
                f"A closed path needs at least 4 distinct points, got {len(pts)}; add points."
            )
        step = np.hypot(*(np.roll(pts, -1, axis=0) - pts).T)
        if np.any(step < DUPLICATE_TOL):
            bad = int(np.flatnonzero(step < DUPLICATE_TOL)[0])
            raise TrackError(
                f"Path points {bad} and {(bad + 1) % len(pts)} coincide; remove the duplicate."
            )
        spline0, t0 = arc_length_fit(pts)
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
        resampled = spline0(invert_arc_length(spline0, t0, s_res))
        self._init_knots(resampled)
        #: Arc length of each input point on the final path, m.
        self.s_input = self._knots.s[np.concatenate([[0], np.cumsum(parts)[:-1]])].copy()
        self.crossings = find_crossings(self._knots_xy, self._knots.s) if check else []
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

            refuse_broken_crossing(self.crossings, self.length, describe)

    def _init_knots(self, knots_xy: np.ndarray) -> None:
        """Fit the final spline with its knots at its own arc length."""
        spline, t = arc_length_fit(knots_xy)
        self.length = float(t[-1])
        self._knots = Knots(t)
        self._n = len(knots_xy)
        self._knots_xy = np.ascontiguousarray(knots_xy)
        self._xy = PeriodicSpline(self._knots, knots_xy)
        c = self._xy.c
        # Python-float copies of the coefficients for the scalar (per-step) code paths.
        self._cx = [c[i, :, 0].tolist() for i in range(4)]
        self._cy = [c[i, :, 1].tolist() for i in range(4)]
        d = self._xy(t[:-1], 1)
        self._knot_heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        self._kdtree: cKDTree | None = None
        # The last scalar projection, ((x, y, s_start), result): a closed-loop lap projects each
        # position twice onto the plan's line from the same start (the controller, then the
        # lap's log). One attribute, so that threads sharing the path read a consistent pair.
        self._last_projection: tuple[tuple[float, float, float] | None, tuple] = (None, ())

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

    def heading(self, s: ArrayLike) -> np.ndarray:
        """Heading psi(s), rad, continuous over one lap (grows by 2 pi per CCW lap)."""
        s = np.mod(np.asarray(s, dtype=float), self.length)
        d = self._xy(s, 1)
        raw = np.arctan2(d[..., 1], d[..., 0])
        k, _ = self._knots.locate(s)
        ref = self._knot_heading[k]
        out = ref + wrap_angle(raw - ref)
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
        key = (x, y, s)
        last_key, last_result = self._last_projection
        if key == last_key:
            return last_result
        result = self._newton_scalar_from(x, y, s)
        self._last_projection = (key, result)
        return result

    def _newton_scalar_from(self, x: float, y: float, s: float) -> tuple[float, float, float, bool]:
        """The Newton iteration of :meth:`_newton_scalar`, without its memory."""
        length = self.length
        kn = self._knots
        knots, bucket, hb, last = kn._s_list, kn._bucket, kn.hb, kn.n - 1
        max_step = 4.0 * hb + 2.0
        cx0, cx1, cx2, cx3 = self._cx
        cy0, cy1, cy2, cy3 = self._cy
        for _ in range(40):
            # Inline of Knots.locate_scalar (a function call costs as much as the arithmetic).
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
            e_psi = wrap_angle(psi_a - np.arctan2(d[:, 1], d[:, 0]))
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
        e_psi = math.nan if psi is None else (float(psi) - heading + math.pi) % TWO_PI - math.pi
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
        self._heading = 0.0
        self._length = path.length
        self._newton = path._newton_scalar

    def reset(self) -> None:
        """Forget the previous position: the next call searches globally."""
        self._s = None

    @property
    def s(self) -> float | None:
        """The last projected arc length, m (None before the first call)."""
        return self._s

    @property
    def heading(self) -> float:
        """The path's heading at the last projection, wrapped to [-pi, pi), rad.

        A by-product of the projection's Newton step (``Path.heading`` costs 19 us a call);
        for the heading error ``wrap_angle(psi - heading)`` only the angle modulo 2 pi matters.
        """
        return self._heading

    def project(self, x: float, y: float) -> tuple[float, float]:
        """Arc length s (m) and lateral offset e_y (m, positive left) of the point (x, y)."""
        x = float(x)
        y = float(y)
        if not (math.isfinite(x) and math.isfinite(y)):
            raise TrackError("FrenetTracker.project got NaN or infinite x, y; pass finite values.")
        if self._s is None:
            s, e_y, _ = self.path.to_frenet(x, y)
            self._s = s
            self._heading = wrap_angle(float(self.path.heading(s)))
            return s, e_y
        s0 = self._s
        s, e_y, heading, ok = self._newton(x, y, s0)
        jump = abs(s - s0)
        jump = min(jump, self._length - jump)
        if not ok or jump > self.max_jump:
            s_near = self.path._nearest_knot_near(x, y, s0, self.max_jump)
            s, e_y, _ = self.path.to_frenet(x, y, s_hint=s_near)
            if abs(e_y) > self.max_jump:
                s, e_y, _ = self.path.to_frenet(x, y)
            heading = wrap_angle(float(self.path.heading(s)))
        self._s = s
        self._heading = heading
        return s, e_y
