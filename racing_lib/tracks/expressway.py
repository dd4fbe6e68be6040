"""``expressway``: a walled expressway-style street circuit, about 4.4 km.

Inspired by (not copied from) the Tokyo Expressway Central Outer Loop of Gran Turismo Sport, the
paper's track: long flat-out straights between concrete walls, fast sweepers, a tight S-bend and
a near-hairpin where the expressway doubles back. Counter-clockwise; s = 0 is the start/finish
line on the southern straight, heading east.

The six crucial corners:

1. fast left sweeper (R 250 m, 30 deg) at the east end,
2. left-hander onto the northbound climb (R 45 m, 60 deg),
3. S-bend, left-right (R 70 m, 35 deg each),
4. fast right kink on the westbound straight (R 200 m, 20 deg),
5. near-hairpin at the west end (R 20 m, 150 deg),
6. left-hander onto the start/finish straight (R 35 m, 30 deg).

Width varies smoothly between 10 and 12 m; elevation changes smoothly by about +-5 m (an
expressway dipping under and climbing over junctions). Taught in notebook 00.
"""

from __future__ import annotations

import numpy as np

from racing_lib.geometry import Track
from racing_lib.tracks.segments import Arc, Straight, track_from_segments

A = Arc.degrees

#: The layout; straight lengths include the small closing corrections folded back in (m).
LAYOUT = (
    Straight(400.4),  # 0  start/finish straight, heading east
    A(250.0, 30.0),  # 1  corner 1: fast sweeper
    Straight(100.1),  # 2
    A(45.0, 60.0),  # 3  corner 2
    Straight(100.1),  # 4
    A(70.0, 35.0),  # 5  corner 3: S-bend, left...
    A(70.0, -35.0),  # 6  ...right
    Straight(100.1),  # 7
    A(120.0, 90.0),  # 8  turn onto the westbound straight
    Straight(698.6),  # 9  westbound straight
    A(200.0, -20.0),  # 10 corner 4: fast right kink
    Straight(150.0),  # 11
    A(250.0, 20.0),  # 12 fast left sweeper back to west
    Straight(758.4),  # 13
    A(20.0, 150.0),  # 14 corner 5: near-hairpin
    Straight(1115.1),  # 15 long south-east straight
    A(35.0, 30.0),  # 16 corner 6
    Straight(290.2),  # 17 to the line
)

CORNER_SEGMENTS = (
    ("fast sweeper", 1),
    ("left-hander", 3),
    ("S-bend", (5, 6)),
    ("fast right kink", 10),
    ("hairpin", 14),
    ("left onto the main straight", 16),
)

TRANSITION = 30.0  # [m] clothoid length between segments


def _width(u: np.ndarray) -> np.ndarray:
    """Total width, m, over the lap fraction u: 10-12 m, narrowest at the hairpin end."""
    return 11.0 + 1.0 * np.cos(2.0 * np.pi * (3.0 * u))


def _elevation(u: np.ndarray) -> np.ndarray:
    """Height, m: a climb to the north side and a dip on the long straight, about +-5 m."""
    return 4.0 * np.sin(2.0 * np.pi * u) + 1.0 * np.sin(4.0 * np.pi * u + 1.0)


def build() -> Track:
    """Generate the expressway track (use :func:`racing_lib.tracks.expressway_track`, cached)."""
    return track_from_segments(
        LAYOUT,
        width=_width,
        elevation=_elevation,
        transition=TRANSITION,
        boundary="walls",
        name="expressway",
        corners=CORNER_SEGMENTS,
    )
