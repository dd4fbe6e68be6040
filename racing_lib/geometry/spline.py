"""Periodic cubic splines on arc-length knots: the machinery under every Path.

A closed curve is refitted by arc length (Gauss-Legendre quadrature and a few Newton steps) and
evaluated by hand on uniform knots, so a scalar evaluation costs no scipy call.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import CubicSpline

from racing_lib.errors import TrackError

__all__ = ["TWO_PI", "Knots", "PeriodicSpline", "arc_length_fit", "invert_arc_length", "wrap_angle"]

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(10)  # quadrature for arc lengths
TWO_PI = 2.0 * math.pi


def wrap_angle(a):
    """Wrap an angle (rad, scalar or array) to [-pi, pi)."""
    if isinstance(a, float):  # the per-step path of the controllers: no array round trip
        return (a + math.pi) % TWO_PI - math.pi
    return (np.asarray(a) + math.pi) % TWO_PI - math.pi


# --------------------------------------------------------------------------------------------
# A periodic cubic spline on uniform knots, evaluated by hand (no scipy call per evaluation)
# --------------------------------------------------------------------------------------------


class Knots:
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


class PeriodicSpline:
    """Periodic cubic spline through values at the knots (values (n,) or (n, d)).

    The coefficients are kept as numpy arrays (vectorized evaluation) and as Python lists
    (scalar evaluation without numpy overhead, which matters in per-step loops).
    """

    def __init__(self, knots: Knots, values: np.ndarray) -> None:
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


def arc_length_fit(points: np.ndarray, tol: float = 1e-11) -> tuple[CubicSpline, np.ndarray]:
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


def invert_arc_length(spline: CubicSpline, t_knots: np.ndarray, s: np.ndarray) -> np.ndarray:
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
