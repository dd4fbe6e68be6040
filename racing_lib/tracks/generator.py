"""Random closed circuits with the variety of real ones, deterministic under a seed.

A circuit starts as a polygon: ``n`` corner points at sorted, jittered bearings around a centre,
each at its own distance from it, so the polygon is star-shaped and never crosses itself. Points
pulled towards the centre make corners that turn the other way (the S-bends of real circuits),
and on some long edges two points offset to one side make a chicane. The polygon is scaled to
the drawn lap length.

Every corner point becomes a circular arc that turns by the polygon's exterior angle there, its
radius drawn from a range that depends on how sharp the corner is (hairpins are tight, kinks are
fast), and every edge becomes the straight that is left between two arcs. Since the exterior
angles of a closed polygon sum to 360 degrees and the arcs replace its corners tangentially, the
layout of arcs and straights closes exactly; :func:`~racing_lib.tracks.track_from_segments` then
adds clothoid transitions and builds the :class:`~racing_lib.geometry.Track`, whose own checks
refuse a road that overlaps itself. A candidate that fails a check (a corner too tight to fit
its arc, an overlap, a lap outside the length range) is dropped and the next one drawn from the
same random stream, so a seed always gives the same circuit.

Widths vary slowly along the lap inside the given range; with ``grade=True`` the road rises and
falls as a sum of three periodic waves, scaled so that no slope exceeds ``max_grade``.
Taught in chapter 08 (your own circuit); used by ``racing-lib tracks --generate``, the robustness
benchmark and the Gymnasium environment's ``track="generated"``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from racing_lib.errors import TrackError
from racing_lib.geometry import Track
from racing_lib.tracks.segments import Arc, Segment, Straight, track_from_segments

__all__ = ["CircuitSpec", "generate"]

_MAX_ATTEMPTS = 400
_MIN_STRAIGHT = 10.0  # [m] shortest straight kept between two arcs
_MAX_TURN = math.radians(165.0)  # a sharper polygon corner is redrawn (tan(turn/2) explodes)
_CORNER_TURN = math.radians(25.0)  # arcs turning more than this are listed as corners
_TRANSITION = 25.0  # [m] clothoid length between segments


@dataclass(frozen=True)
class CircuitSpec:
    """What the generator may draw.

    Attributes
    ----------
    length : (float, float)
        Range of the lap length, m (each circuit draws its own target in it).
    width : (float, float)
        Range of the total road width, m.
    min_radius : float
        Radius of the tightest hairpin allowed, m.
    grade : bool
        Give the road an elevation profile (otherwise flat).
    max_grade : float
        Steepest slope when ``grade`` is set, dz/ds (0.06 = 6 %).
    boundary : {"walls", "open"}
        Edge behaviour of the circuit (CSV files do not store it; loading one gives ``open``).
    """

    length: tuple[float, float] = (2000.0, 7000.0)
    width: tuple[float, float] = (8.0, 15.0)
    min_radius: float = 15.0
    grade: bool = False
    max_grade: float = 0.06
    boundary: str = "open"

    def check(self) -> None:
        """Refuse sizes no circuit can have, before any drawing.

        Raises
        ------
        TrackError
            Naming the value and the range that works.
        """
        for name in ("length", "width"):
            pair = getattr(self, name)
            try:
                ok = len(pair) == 2 and all(_is_number(v) for v in pair)
            except TypeError:
                ok = False
            if not ok:
                raise TrackError(
                    f"Circuit {name} must be a (min, max) pair of numbers, got {pair!r}."
                )
        for name in ("min_radius", "max_grade"):
            if not _is_number(getattr(self, name)):
                raise TrackError(f"{name} must be a number, got {getattr(self, name)!r}.")
        lo, hi = (float(v) for v in self.length)
        if not (math.isfinite(lo) and math.isfinite(hi) and 500.0 <= lo <= hi <= 50_000.0):
            raise TrackError(
                f"Circuit length range {self.length} m is impossible: give 500 <= min <= max "
                "<= 50000 m (real circuits are 2000-7000 m)."
            )
        wlo, whi = (float(v) for v in self.width)
        if not (math.isfinite(wlo) and math.isfinite(whi) and 2.0 <= wlo <= whi <= 40.0):
            raise TrackError(
                f"Circuit width range {self.width} m is impossible: give 2 <= min <= max <= 40 m."
            )
        if not (math.isfinite(self.min_radius) and 0.5 * whi < self.min_radius <= 200.0):
            raise TrackError(
                f"Minimum corner radius {self.min_radius} m is impossible with widths up to "
                f"{whi} m: it must exceed half the widest road ({0.5 * whi} m) and be at most "
                "200 m."
            )
        if self.min_radius * 40.0 > lo:
            raise TrackError(
                f"A {lo} m lap cannot hold corners of radius {self.min_radius} m and more: "
                "lower the minimum radius or lengthen the lap (length >= 40 x radius)."
            )
        if not (0.0 < self.max_grade <= 0.25):
            raise TrackError(f"max_grade must be in (0, 0.25], got {self.max_grade}.")
        if self.boundary not in ("walls", "open"):
            raise TrackError(f"boundary must be 'walls' or 'open', got {self.boundary!r}.")


def _is_number(value: object) -> bool:
    """A real number (not a bool, not a string)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def generate(seed: int, spec: CircuitSpec | None = None, *, name: str | None = None) -> Track:
    """A random closed circuit, the same one for the same seed and spec.

    Parameters
    ----------
    seed : int
        Seed of the circuit (>= 0).
    spec : CircuitSpec, optional
        Ranges to draw from (default: 2-7 km, 8-15 m wide, hairpins down to 15 m, flat).
    name : str, optional
        Track name (default ``generated-<seed>``).

    Returns
    -------
    Track
        A circuit that passes every track check, with its corners listed.

    Raises
    ------
    TrackError
        An impossible spec (before any drawing), or no valid circuit in 400 candidates.

    Examples
    --------
    >>> track = generate(7)
    >>> 2000 <= track.length <= 7000
    True
    >>> track.length == generate(7).length
    True
    """
    spec = CircuitSpec() if spec is None else spec
    spec.check()
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise TrackError(f"Circuit seed must be an integer >= 0, got {seed!r}.")
    rng = np.random.default_rng([int(seed), 0x7261636B])  # own stream, apart from lap seeds
    target = rng.uniform(*spec.length)
    last = "no candidate drawn"
    for _ in range(_MAX_ATTEMPTS):
        layout = _layout(rng, target, spec.min_radius)
        if isinstance(layout, str):
            last = layout
            continue
        segments, corners = layout
        try:
            track = track_from_segments(
                segments,
                width=_width_profile(rng, spec.width),
                elevation=(
                    _elevation_profile(rng, sum(seg.length for seg in segments), spec.max_grade)
                    if spec.grade
                    else 0.0
                ),
                transition=_TRANSITION,
                boundary=spec.boundary,
                name=f"generated-{seed}" if name is None else name,
                corners=corners,
            )
        except TrackError as err:
            last = str(err)
            continue
        if spec.length[0] <= track.length <= spec.length[1]:
            return track
        last = f"lap of {track.length:.0f} m outside {spec.length}"
    raise TrackError(
        f"No valid circuit for seed {seed} in {_MAX_ATTEMPTS} candidates (last: {last}); "
        "widen the length range or lower the minimum radius."
    )


def _polygon(rng: np.random.Generator, n: int) -> np.ndarray:
    """A star-shaped polygon of ``n`` points around the origin, counter-clockwise, unit size.

    Stretched along a random direction (real circuits are often two or three times longer
    than wide), which keeps it star-shaped, so it still never crosses itself.
    """
    bearing = 2.0 * np.pi * (np.arange(n) + rng.uniform(-0.3, 0.3, n)) / n
    radius = rng.uniform(0.6, 1.4, n)
    pulled = rng.random(n) < 0.35  # corners that turn the other way
    radius[pulled] *= rng.uniform(0.25, 0.65, pulled.sum())
    points = np.column_stack([radius * np.cos(bearing), radius * np.sin(bearing)])
    angle = rng.uniform(0.0, np.pi)
    along = np.array([np.cos(angle), np.sin(angle)])
    stretch = rng.uniform(1.0, 2.8)
    return points + (stretch - 1.0) * np.outer(points @ along, along)


def _add_chicanes(rng: np.random.Generator, points: np.ndarray) -> np.ndarray:
    """The polygon (points, m) with up to two chicanes added.

    A chicane is two points offset to one side of a long edge: the road steps aside by 8-16 m
    over 50-120 m and back.
    """
    edges = np.roll(points, -1, axis=0) - points
    lengths = np.hypot(*edges.T)
    out = [points[i] for i in range(len(points))]
    inserted = 0
    for i in np.argsort(-lengths)[:4]:
        if inserted == 2 or lengths[i] < 400.0 or rng.random() < 0.5:
            continue
        along = edges[i] / lengths[i]
        normal = np.array([-along[1], along[0]]) * rng.choice([-1.0, 1.0])
        half = rng.uniform(25.0, 60.0)  # half the chicane's length, m
        offset = rng.uniform(8.0, 16.0)  # how far the road steps aside, m
        mid = points[i] + rng.uniform(0.35, 0.65) * edges[i]
        at = _index(out, points[i])
        out[at + 1 : at + 1] = [
            mid - half * along + offset * normal,
            mid + half * along + offset * normal,
        ]
        inserted += 1
    return np.array(out)


def _index(points: list[np.ndarray], point: np.ndarray) -> int:
    """Position of ``point`` in ``points`` (by identity of values)."""
    return next(k for k, p in enumerate(points) if np.array_equal(p, point))


def _turns(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exterior angle at each point, rad (> 0 left), and the length of the edge after it, m."""
    edges = np.roll(points, -1, axis=0) - points
    heading = np.arctan2(edges[:, 1], edges[:, 0])
    turn = np.angle(np.exp(1j * (heading - np.roll(heading, 1))))
    return turn, np.hypot(*edges.T)


def _radius_range(turn: float, min_radius: float) -> tuple[float, float]:
    """Radii to draw from for a corner turning by ``turn`` rad: sharp corners are tight, m."""
    sharp = abs(turn)
    if sharp > math.radians(110.0):
        return min_radius, 3.0 * min_radius
    if sharp > math.radians(50.0):
        return 1.5 * min_radius, 8.0 * min_radius
    return 3.0 * min_radius, 20.0 * min_radius


def _layout(
    rng: np.random.Generator, target: float, min_radius: float
) -> tuple[list[Segment], list[tuple[str, int]]] | str:
    """Arcs and straights of one candidate, or why it was dropped."""
    n = int(np.clip(round(target / 330.0), 8, 22))
    points = _polygon(rng, n)
    perimeter = np.hypot(*(np.roll(points, -1, axis=0) - points).T).sum()
    points = points * (target / perimeter)
    points = _add_chicanes(rng, points)
    turn, edge = _turns(points)
    if abs(turn.sum() - 2.0 * np.pi) > 1e-6:
        return "polygon not simple"
    if np.any(np.abs(turn) > _MAX_TURN):
        return "a polygon corner sharper than 165 degrees"
    radius = np.array([math.exp(rng.uniform(*np.log(_radius_range(t, min_radius)))) for t in turn])
    # An arc saves 2 R tan(|turn|/2) - R |turn| on the polygon's corner: scale the polygon so
    # that the layout, not the polygon, has the target length.
    tangent = radius * np.tan(np.abs(turn) / 2.0)
    scale = (target + np.sum(2.0 * tangent - radius * np.abs(turn))) / edge.sum()
    edge = edge * scale
    # Shrink the radii where two arcs do not fit on the edge between them.
    for _ in range(3):
        tangent = radius * np.tan(np.abs(turn) / 2.0)
        room = (edge - _MIN_STRAIGHT) / (tangent + np.roll(tangent, -1))
        fit = np.minimum(1.0, np.minimum(room, np.roll(room, 1)))
        radius = radius * np.maximum(fit, 0.0)
    if np.any(radius < min_radius):
        return "a corner too tight for its neighbours"
    tangent = radius * np.tan(np.abs(turn) / 2.0)
    straight = edge - tangent - np.roll(tangent, -1)
    if rng.random() < 0.5:  # clockwise circuits too
        turn = -turn
    segments: list[Segment] = []
    for k in range(len(turn)):
        segments += [Arc(float(radius[k]), float(turn[k])), Straight(float(straight[k]))]
    # Start on the longest straight, as the start/finish line of most circuits is.
    first = 2 * int(np.argmax(straight)) + 1
    segments = segments[first:] + segments[:first]
    corners = [
        (f"T{number}", index)
        for number, index in enumerate(
            (i for i, seg in enumerate(segments) if abs(seg.angle) > _CORNER_TURN), start=1
        )
    ]
    return segments, corners


def _width_profile(rng: np.random.Generator, width: Sequence[float]):
    """A total width that drifts slowly along the lap inside ``width``, m, as a function of u."""
    lo, hi = float(width[0]), float(width[1])
    base = rng.uniform(lo, hi)
    swing = min(base - lo, hi - base) * rng.uniform(0.0, 1.0)
    waves, phase = rng.integers(1, 4), rng.uniform(0.0, 2.0 * np.pi)
    return lambda u: base + swing * np.sin(2.0 * np.pi * waves * u + phase)


def _elevation_profile(rng: np.random.Generator, length: float, max_grade: float):
    """Heights, m, as a function of u: three periodic waves, scaled to a steepest slope."""
    order = np.arange(1, 4)
    amp = rng.normal(0.0, 1.0, 3) / order
    phase = rng.uniform(0.0, 2.0 * np.pi, 3)
    u = np.linspace(0.0, 1.0, 2000, endpoint=False)
    slope = (2.0 * np.pi / length) * (
        amp * order * np.cos(2.0 * np.pi * order * u[:, None] + phase)
    )
    scale = rng.uniform(0.4, 0.95) * max_grade / np.max(np.abs(slope.sum(axis=1)))
    return lambda u: (
        scale * (amp * np.sin(2.0 * np.pi * order * np.asarray(u)[..., None] + phase)).sum(-1)
    )
