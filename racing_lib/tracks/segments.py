"""Build closed tracks from straights, arcs and clothoid transitions.

A layout is a list of :class:`Straight` and :class:`Arc` segments. Between two segments of
different curvature a clothoid (curvature linear in s) of length ``transition`` is inserted,
centred on the junction: it takes half its length from each neighbour, so the total turning of
the layout is exactly the sum of the arc angles. Heading and position are integrated numerically
on a fine grid (exact heading: curvature is piecewise linear; positions by the trapezoid rule
with steps of at most 0.1 m).

Closing the loop. A closed track must turn by exactly +-360 degrees (or by 0 degrees: a
figure-eight, whose two lobes turn opposite ways) and end where it starts.

* Heading: if the arc angles sum to +-360 (or 0) degrees within ``angle_tolerance``, every arc
  angle is scaled by the same factor so that the sum is exact (arcs keep their radii); for a
  figure-eight only the arcs of one turning direction are scaled.
* Position: the remaining gap e = r(L) - r(0) is closed by lengthening or shortening the
  straights, which moves everything after a straight without turning it. The changes dL_i
  minimize sum (dL_i / L_i)^2 subject to sum dL_i (cos theta_i, sin theta_i) = -e (least squares,
  long straights absorb more). Two non-parallel straights are enough. Without them the gap is
  spread linearly over s (r(s) -= e s / L), a correction of second order for small gaps.

The corrections are reported in :attr:`Centerline.closure` so a layout author can see that they
are small and fold them back into the layout.

Taught in notebook 00 (making a track).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from racing_lib.errors import TrackError
from racing_lib.geometry import (
    Corner,
    Path,
    Track,
)

__all__ = [
    "Arc",
    "Centerline",
    "Straight",
    "build_centerline",
    "track_from_segments",
]

_MAX_STEP = 0.1  # [m] integration step


@dataclass(frozen=True)
class Straight:
    """A straight of ``length`` m."""

    length: float

    @property
    def curvature(self) -> float:
        """0 1/m."""
        return 0.0

    @property
    def angle(self) -> float:
        """Turning angle, 0 rad."""
        return 0.0


@dataclass(frozen=True)
class Arc:
    """A circular arc of ``radius`` m (> 0) turning by ``angle`` rad (> 0 left, < 0 right)."""

    radius: float
    angle: float

    @classmethod
    def degrees(cls, radius: float, angle_deg: float) -> Arc:
        """An arc with its angle in degrees (> 0 left)."""
        return cls(radius, math.radians(angle_deg))

    @property
    def length(self) -> float:
        """Arc length, m."""
        return self.radius * abs(self.angle)

    @property
    def curvature(self) -> float:
        """Signed curvature, 1/m."""
        return math.copysign(1.0 / self.radius, self.angle)


Segment = Straight | Arc


@dataclass
class Centerline:
    """Result of :func:`build_centerline`.

    Attributes
    ----------
    x, y : np.ndarray
        Points along the closed loop, m, about ``spacing`` apart (last != first).
    s : np.ndarray
        Arc length of each point, m.
    kappa : np.ndarray
        Design curvature at each point, 1/m (piecewise linear: arcs and clothoids).
    starts : np.ndarray
        Arc length at which each segment starts (its nominal junction), m.
    segments : list
        The segments after the closing corrections.
    closure : dict
        The corrections applied: ``angle_scale`` (factor on arc angles), ``straight_changes``
        (m, per straight in layout order), ``spread_gap`` (m, gap spread linearly, 0 if the
        straights closed the loop).
    """

    x: np.ndarray
    y: np.ndarray
    s: np.ndarray
    kappa: np.ndarray
    starts: np.ndarray
    segments: list
    closure: dict = field(default_factory=dict)

    @property
    def length(self) -> float:
        """Total design length, m."""
        return float(sum(seg.length for seg in self.segments))


def _check_segments(segments: Sequence[Segment]) -> None:
    if len(segments) < 2:
        raise TrackError("A layout needs at least two segments; add straights and arcs.")
    for i, seg in enumerate(segments):
        if isinstance(seg, Straight):
            if not (math.isfinite(seg.length) and seg.length > 0):
                raise TrackError(f"Segment {i}: straight length must be > 0 m, got {seg.length}.")
        elif isinstance(seg, Arc):
            if not (math.isfinite(seg.radius) and seg.radius > 0):
                raise TrackError(f"Segment {i}: arc radius must be > 0 m, got {seg.radius}.")
            if not (math.isfinite(seg.angle) and seg.angle != 0):
                raise TrackError(f"Segment {i}: arc angle must be non-zero, got {seg.angle}.")
        else:
            raise TrackError(f"Segment {i} is {seg!r}; use Straight(length) or Arc(radius, angle).")


def _curvature_knots(
    segments: Sequence[Segment], transition: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Breakpoints (s, kappa) of the piecewise-linear curvature over one lap, and the starts."""
    lengths = np.array([seg.length for seg in segments])
    kappas = np.array([seg.curvature for seg in segments])
    starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    total = float(lengths.sum())
    n = len(segments)
    knots_s: list[float] = []
    knots_k: list[float] = []
    for j in range(n):  # junction j: between segment j-1 and segment j, at starts[j]
        prev, cur = (j - 1) % n, j
        if kappas[prev] == kappas[cur]:
            continue
        lt = min(transition, lengths[prev], lengths[cur])
        knots_s += [starts[j] - lt / 2, starts[j] + lt / 2]
        knots_k += [kappas[prev], kappas[cur]]
    if not knots_s:
        raise TrackError("The layout has a single curvature; a closed loop needs arcs.")
    ks = np.array(knots_s)
    kk = np.array(knots_k)
    # Junction 0 may start before s = 0: move it to the end of the lap.
    ks = np.where(ks < 0.0, ks + total, ks)
    order = np.argsort(ks, kind="stable")
    ks, kk = ks[order], kk[order]
    # Periodic closure of the breakpoint list.
    ks = np.concatenate([[ks[-1] - total], ks, [ks[0] + total]])
    kk = np.concatenate([[kk[-1]], kk, [kk[0]]])
    return ks, kk, starts


def _integrate(segments: Sequence[Segment], transition: float, spacing: float):
    """Integrate heading and position; returns (s, x, y, kappa, theta) on a fine grid."""
    ks, kk, starts = _curvature_knots(segments, transition)
    total = float(sum(seg.length for seg in segments))
    # Fine grid that contains every breakpoint inside [0, total].
    inner = ks[(ks > 0.0) & (ks < total)]
    edges = np.unique(np.concatenate([[0.0], inner, [total]]))
    pieces = [
        np.linspace(a, b, max(int(math.ceil((b - a) / _MAX_STEP)), 1) + 1)[:-1]
        for a, b in zip(edges[:-1], edges[1:], strict=True)
    ]
    s = np.concatenate([*pieces, [total]])
    kappa = np.interp(s, ks, kk)
    ds = np.diff(s)
    # Curvature is linear between grid points, so the trapezoid rule gives the exact heading.
    theta = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * ds)])
    x = np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(theta[1:]) + np.cos(theta[:-1])) * ds)])
    y = np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(theta[1:]) + np.sin(theta[:-1])) * ds)])
    return s, x, y, kappa, theta, starts


def build_centerline(
    segments: Sequence[Segment],
    transition: float = 30.0,
    spacing: float = 1.0,
    angle_tolerance: float = math.radians(10.0),
) -> Centerline:
    """Integrate a layout of straights and arcs (with clothoids) into a closed centerline.

    Parameters
    ----------
    segments : sequence of Straight and Arc
        The layout in order of travel, starting at the start/finish line (s = 0) heading along +x.
    transition : float
        Clothoid length between segments of different curvature, m (shortened where a
        neighbouring segment is shorter).
    spacing : float
        Distance between output points, m.
    angle_tolerance : float
        How far the arc angles may sum away from +-360 degrees before this is an error, rad.

    Returns
    -------
    Centerline
        Points, design curvature and the closing corrections (see the module notes).

    Raises
    ------
    TrackError
        Bad segments, turning far from +-360 (and from 0) degrees, or closing corrections that
        would make a straight shorter than its transitions.
    """
    _check_segments(segments)
    if not transition >= 0:
        raise TrackError(f"Transition length must be >= 0 m, got {transition}.")
    segs = list(segments)
    turning = sum(seg.angle for seg in segs)
    target = min((-2.0 * math.pi, 0.0, 2.0 * math.pi), key=lambda t: abs(turning - t))
    if abs(turning - target) > angle_tolerance:
        raise TrackError(
            f"The arcs turn by {math.degrees(turning):.2f} degrees in total; a closed loop turns "
            "by +-360 degrees (or by 0 degrees, a figure-eight): change the arc angles."
        )
    if target == 0.0:
        # A figure-eight: scale the left-hand arcs so that they undo the right-hand ones exactly.
        left = sum(seg.angle for seg in segs if seg.angle > 0.0)
        if left <= 0.0:
            raise TrackError("A layout that turns by 0 degrees needs left- and right-hand arcs.")
        scale = (left - turning) / left
        segs = [
            Arc(seg.radius, seg.angle * scale) if isinstance(seg, Arc) and seg.angle > 0 else seg
            for seg in segs
        ]
    else:
        scale = target / turning
        segs = [Arc(seg.radius, seg.angle * scale) if isinstance(seg, Arc) else seg for seg in segs]
    straight_idx = [i for i, seg in enumerate(segs) if isinstance(seg, Straight)]
    original = {i: segs[i].length for i in straight_idx}
    spread = 0.0
    for _ in range(8):
        s, x, y, kappa, theta, starts = _integrate(segs, transition, spacing)
        gap = np.array([x[-1] - x[0], y[-1] - y[0]])
        if np.hypot(*gap) < 1e-9:
            break
        # Heading of each straight (constant along it) from the integrated heading.
        if len(straight_idx) >= 2:
            mid = np.array([starts[i] + 0.5 * segs[i].length for i in straight_idx])
            th = np.interp(mid, s, theta)
            a = np.vstack([np.cos(th), np.sin(th)])  # (2, m)
            w = np.array([segs[i].length for i in straight_idx]) ** 2
            gram = (a * w) @ a.T
            if np.linalg.cond(gram) < 1e8:
                dl = w * (a.T @ np.linalg.solve(gram, -gap))
                new = [segs[i].length + d for i, d in zip(straight_idx, dl, strict=True)]
                if min(new) <= 0.0:
                    raise TrackError(
                        "Closing the loop would make a straight non-positive (changes "
                        f"{np.round(dl, 1).tolist()} m); adjust the layout so it nearly closes."
                    )
                for i, length in zip(straight_idx, new, strict=True):
                    segs[i] = Straight(length)
                continue
        # Fallback: spread the gap linearly along s.
        spread = float(np.hypot(*gap))
        x = x - gap[0] * s / s[-1]
        y = y - gap[1] * s / s[-1]
        break
    total = s[-1]
    n = max(int(round(total / spacing)), 8)
    s_out = np.arange(n) * (total / n)
    return Centerline(
        x=np.interp(s_out, s, x),
        y=np.interp(s_out, s, y),
        s=s_out,
        kappa=np.interp(s_out, s, kappa),
        starts=starts,
        segments=segs,
        closure={
            "angle_scale": scale,
            "straight_changes": [segs[i].length - original[i] for i in straight_idx],
            "spread_gap": spread,
        },
    )


def track_from_segments(
    segments: Sequence[Segment],
    width: float | Callable[[np.ndarray], np.ndarray] = 10.0,
    elevation: float | Callable[[np.ndarray], np.ndarray] = 0.0,
    *,
    transition: float = 30.0,
    boundary: str = "open",
    name: str = "custom",
    corners: Sequence[tuple[str, int | tuple[int, int]]] = (),
) -> Track:
    """A :class:`~racing_lib.geometry.Track` from a layout of straights and arcs.

    Parameters
    ----------
    segments : sequence of Straight and Arc
        The layout (see :func:`build_centerline`).
    width : float or callable
        Total road width, m, constant or a function of the fraction of the lap u = s / L in
        [0, 1) (periodic); split equally left and right of the centerline.
    elevation : float or callable
        Road height, m, constant or a function of u = s / L (periodic).
    transition : float
        Clothoid length, m.
    boundary : {"walls", "open"}
    name : str
    corners : sequence of (label, index) or (label, (first, last))
        Crucial corners as layout segment indices (an arc, or a run of segments such as an
        S-bend); they become the track's :class:`~racing_lib.geometry.Corner` list.

    Examples
    --------
    >>> import math
    >>> oval = [Straight(200), Arc(50, math.pi), Straight(200), Arc(50, math.pi)]
    >>> round(track_from_segments(oval, width=12.0).length)
    714
    """
    cl = build_centerline(segments, transition=transition)
    path = Path(cl.x, cl.y)
    s = path.sample(ds=2.0)
    u = s / path.length
    w = np.full_like(s, float(width)) if not callable(width) else np.asarray(width(u), dtype=float)
    z = (
        np.full_like(s, float(elevation))
        if not callable(elevation)
        else np.asarray(elevation(u), dtype=float)
    )
    found = _corners(cl, corners, transition, path.length)
    return Track(
        path,
        0.5 * w,
        0.5 * w,
        z,
        s=s,
        boundary=boundary,
        name=name,
        corners=found,  # type: ignore[arg-type]
    )


def _corners(
    cl: Centerline,
    spec: Sequence[tuple[str, int | tuple[int, int]]],
    transition: float,
    length: float,
) -> list[Corner]:
    """Corner records from segment indices; s scaled from the design to the path's length."""
    segs = cl.segments
    n = len(segs)
    scale = length / cl.length
    out = []
    for number, (label, idx) in enumerate(spec, start=1):
        first, last = (idx, idx) if isinstance(idx, int) else idx
        if not (0 <= first <= last < n):
            raise TrackError(f"Corner {label!r}: segment indices {idx} outside 0..{n - 1}.")
        run = segs[first : last + 1]
        arcs = [seg for seg in run if isinstance(seg, Arc)]
        if not arcs:
            raise TrackError(f"Corner {label!r}: segments {idx} contain no arc.")
        start = cl.starts[first]
        end = cl.starts[last] + segs[last].length
        lt_in = min(transition, segs[first - 1].length, segs[first].length)
        lt_out = min(transition, segs[last].length, segs[(last + 1) % n].length)
        out.append(
            Corner(
                number=number,
                label=label,
                s=float(0.5 * (start + end) * scale % length),
                s_entry=float((start - 0.5 * lt_in) * scale % length),
                s_exit=float((end + 0.5 * lt_out) * scale % length),
                radius=float(min(seg.radius for seg in arcs)),
                angle=float(sum(seg.angle for seg in arcs)),
            )
        )
    return out
