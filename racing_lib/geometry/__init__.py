"""Geometry: paths, Frenet coordinates and tracks, and the racetrack-database CSV format.

The lowest layer of the library; it knows nothing of cars.

* :mod:`racing_lib.geometry.path`: :class:`Path`, a closed arc-length parametrized curve, and
  :class:`FrenetTracker`, a moving car's projection on it.
* :mod:`racing_lib.geometry.spline`: the periodic arc-length splines under every path.
* :mod:`racing_lib.geometry.track`: :class:`Track`, a centerline with widths, elevation and edges.
* :mod:`racing_lib.geometry.csv`: reading and writing the racetrack-database CSV format.
* :mod:`racing_lib.geometry.checks`: what real circuits need (thinning, width clipping, overlaps).
* :mod:`racing_lib.geometry.crossings`: broken rows against real bridges.

The names below are re-exported, so ``from racing_lib.geometry import Track`` works; tracks by name
come from :func:`racing_lib.tracks.load_track`.
"""

from racing_lib.geometry.csv import CSV_COLUMNS
from racing_lib.geometry.path import FrenetTracker, Path
from racing_lib.geometry.track import Corner, Track, wall_clearance

__all__ = ["CSV_COLUMNS", "Corner", "FrenetTracker", "Path", "Track", "wall_clearance"]
