"""The planning grid the curvature QP, the time-optimal NLP and the best lap share.

:class:`TrackGrid` samples a track's centerline at equally spaced nodes and turns its widths into
bounds on the car's lateral offset e_y: half the car's width (:data:`DEFAULT_CAR_WIDTH`) and a
clearance to the edge (:data:`WALL_MARGIN` beside a wall, :data:`OPEN_MARGIN` on an open track)
come off each side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from racing_lib.errors import PlanningError
from racing_lib.geometry import Track
from racing_lib.geometry.path import Path, chord_arc_length
from racing_lib.vehicle.params import VehicleParams

__all__ = ["DEFAULT_CAR_WIDTH", "OPEN_MARGIN", "WALL_MARGIN", "TrackGrid", "default_margin"]

#: Body width of the default car (racing_lib.vehicle.VehicleParams.width), m.
DEFAULT_CAR_WIDTH = VehicleParams().width
#: Default clearance between the car's side and a wall, m. A wall costs speed, so the plan leaves
#: room for the coupled MPC's tracking error where the line passes a wall (about 0.4 m at most on
#: the expressway; with 0.5 m the car brushed the wall after corner 3 in every seed).
WALL_MARGIN = 0.8
#: Default clearance between the car's side and the edge of an open track, m. Beyond the edge
#: the wheels lose grip, and a car that slides there at a hairpin exit spins: with 0.3 m, real
#: circuits (Austin, Spielberg) were left for seconds at their slow corners, where the car runs
#: half a metre wide of the plan.
OPEN_MARGIN = 0.8


def default_margin(track: Track) -> float:
    """The clearance to the edges a plan keeps on ``track`` when given none, m.

    :data:`WALL_MARGIN` on a track with walls, :data:`OPEN_MARGIN` on an open one.
    """
    return WALL_MARGIN if getattr(track, "boundary", "open") == "walls" else OPEN_MARGIN


@dataclass(frozen=True)
class TrackGrid:
    """The planning grid: N equally spaced nodes along the track centerline.

    Attributes
    ----------
    s : ndarray (N,)
        Arc length of the nodes along the centerline, m.
    ds : ndarray (N,)
        Distance from node k to node k+1 (the last wraps to node 0), m.
    kappa, theta : ndarray (N,)
        Centerline curvature (1/m) and road grade (rad) at the nodes.
    ey_min, ey_max : ndarray (N,)
        Bounds on the lateral offset e_y of the car's centre, m (right edge + clearance, left edge -
        clearance).
    length : float
        Lap length along the centerline, m.
    """

    s: np.ndarray
    ds: np.ndarray
    kappa: np.ndarray
    theta: np.ndarray
    ey_min: np.ndarray
    ey_max: np.ndarray
    length: float
    track: Track | None = None

    @property
    def n(self) -> int:
        """Number of nodes."""
        return int(self.s.size)

    @classmethod
    def from_track(
        cls,
        track: Track,
        spacing: float = 3.0,
        car_width: float = DEFAULT_CAR_WIDTH,
        margin: float | None = None,
    ) -> TrackGrid:
        """Sample ``track`` every ``spacing`` m and compute the e_y bounds.

        Parameters
        ----------
        track : Track
            The track.
        spacing : float
            Node spacing, m (rounded so the nodes divide the lap evenly).
        car_width : float
            Body width of the car, m.
        margin : float, optional
            Clearance between the car's side and the edge, m
            (default :data:`WALL_MARGIN` with walls, :data:`OPEN_MARGIN` open, both 0.8).

        Raises
        ------
        PlanningError
            If the track is narrower than the car plus the margins somewhere.
        """
        if not spacing > 0:
            raise PlanningError(f"grid spacing must be positive, got {spacing!r} m.")
        line = track.centerline
        n = max(16, int(round(line.length / spacing)))
        s = np.asarray(line.sample(n=n), float)
        if margin is None:
            margin = default_margin(track)
        half = 0.5 * car_width + margin
        wl = np.asarray(track.width_left(s), float)
        wr = np.asarray(track.width_right(s), float)
        ey_max = wl - half
        ey_min = -(wr - half)
        room = ey_max - ey_min
        if np.any(room < 0.05):
            k = int(np.argmin(room))
            raise PlanningError(
                f"track {getattr(track, 'name', '?')!r} is too narrow for the car near s = "
                f"{s[k]:.0f} m: {wl[k] + wr[k]:.2f} m wide, but the car needs "
                f"{car_width:.2f} m plus {margin:.2f} m clearance on each side; no planner can "
                "keep it on the track. Use a smaller car_width/margin or fix the track widths."
            )
        return cls(
            s=s,
            ds=np.diff(np.append(s, line.length)),
            kappa=np.asarray(line.curvature(s), float),
            theta=np.asarray(track.grade(s), float),
            ey_min=ey_min,
            ey_max=ey_max,
            length=float(line.length),
            track=track,
        )

    def line_xy(
        self, e_y: np.ndarray, e_psi: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cartesian (x, y, psi) of a line given by its offsets e_y (m) at the nodes."""
        return self.track.centerline.to_cartesian(self.s, e_y, e_psi)

    def line_curvature(self, e_y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Curvature (1/m) at the nodes of the line with offsets e_y, from a spline through it.

        Returns the curvature, the nodes' arc length along the line (m) and its length (m).
        """
        x, y, _ = self.line_xy(e_y)
        path = Path(x, y, check=False)
        s_line = chord_arc_length(x, y, path.length)
        return np.asarray(path.curvature(s_line), float), s_line, path.length
