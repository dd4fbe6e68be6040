"""``shortcut``: an open circuit, about 3.1 km, with two U corners then a run of sharp corners.

Inspired by (not copied from) the Autopolis shortcut course: after the start/finish straight two
180-degree U-shaped corners in opposite directions (R 40 and 35 m) fold the track back on itself,
then a series of sharp corners (R 20-30 m) climbs round to the long back straight. Open boundary:
leaving the road means less grip, not a wall. Counter-clockwise; s = 0 on the start/finish
straight heading east. Width 12 m; elevation about +-8 m (a hillside circuit).

Crucial corners: 1 first U (left), 2 second U (right), 3-6 the sharp corners.
Taught in notebook 00.
"""

from __future__ import annotations

import numpy as np

from racing_lib.geometry import Track
from racing_lib.tracks.segments import Arc, Straight, track_from_segments

A = Arc.degrees

#: The layout; straight lengths include the small closing corrections folded back in (m).
LAYOUT = (
    Straight(496.2),  # 0  start/finish straight, heading east
    A(40.0, 180.0),  # 1  corner 1: U, left
    Straight(251.0),  # 2
    A(35.0, -180.0),  # 3  corner 2: U, right
    Straight(348.1),  # 4
    A(25.0, 90.0),  # 5  corner 3
    Straight(135.5),  # 6
    A(30.0, 90.0),  # 7  corner 4
    Straight(200.6),  # 8
    A(20.0, -60.0),  # 9  corner 5
    Straight(76.4),  # 10
    A(25.0, 60.0),  # 11 corner 6
    Straight(503.8),  # 12 back straight
    A(40.0, 90.0),  # 13
    Straight(357.0),  # 14
    A(35.0, 90.0),  # 15
    Straight(199.4),  # 16 to the line
)

CORNER_SEGMENTS = (
    ("U-turn left", 1),
    ("U-turn right", 3),
    ("sharp left", 5),
    ("sharp left", 7),
    ("sharp right", 9),
    ("sharp left", 11),
)

TRANSITION = 20.0  # [m] clothoid length between segments
WIDTH = 12.0  # [m]


def _elevation(u: np.ndarray) -> np.ndarray:
    """Height, m: one hill over the lap, +-8 m."""
    return 8.0 * np.sin(2.0 * np.pi * u + 0.5)


def build() -> Track:
    """Generate the shortcut track (use :func:`racing_lib.tracks.shortcut_track`, cached)."""
    return track_from_segments(
        LAYOUT,
        width=WIDTH,
        elevation=_elevation,
        transition=TRANSITION,
        boundary="open",
        name="shortcut",
        corners=CORNER_SEGMENTS,
    )
