"""Plans as :class:`Trajectory` objects (taught in notebook 03; their file: :mod:`.plan_file`).

A trajectory is what every planner returns and what every controller follows: the line (x, y,
heading, curvature), the states along it (v_x, v_y, yaw rate r), the inputs (a_x, delta) and the
time t, all sampled at the same nodes, plus where it came from (track, method) and the model it
was made with (a :class:`~racing_lib.model.CarModel`, which the MPC that tracks it reads).
``trajectory.path`` is the line itself as a :class:`racing_lib.geometry.Path`, so a controller can
use it as its Frenet reference.

The arc length ``s`` of a trajectory is measured along its own line (the raceline), not along the
track centerline the planners work on, so ``trajectory.path`` and ``trajectory.s`` agree.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from racing_lib.errors import PlanningError, RacingLibError
from racing_lib.geometry import Path, Track
from racing_lib.geometry.path import chord_arc_length
from racing_lib.model.car_model import CarModel
from racing_lib.model.params import ModelOptions, ModelParams, PedalMap
from racing_lib.planning.plan_file import (
    PLAN_FIELDS,
    PLAN_FORMAT_VERSION,
    read_plan_file,
    write_plan_file,
)
from racing_lib.planning.speed import AccelLimits, segment_times, speed_profile


def options_to_dict(options: ModelOptions | Mapping[str, bool] | None) -> dict[str, bool]:
    """Model options as a plain dict (for metadata and JSON); ``None`` -> empty dict."""
    if options is None:
        return {}
    if isinstance(options, dict):
        return dict(options)
    if dataclasses.is_dataclass(options):
        return dataclasses.asdict(options)
    return {k: v for k, v in vars(options).items() if not k.startswith("_")}


@dataclass(frozen=True)
class TrajectoryState:
    """States of a trajectory at given arc lengths (arrays, or floats for a scalar query).

    Attributes have the meaning and units of the :class:`Trajectory` fields of the same name.
    """

    s: float | np.ndarray
    x: float | np.ndarray
    y: float | np.ndarray
    psi: float | np.ndarray
    kappa: float | np.ndarray
    vx: float | np.ndarray
    vy: float | np.ndarray
    r: float | np.ndarray
    ax: float | np.ndarray
    delta: float | np.ndarray
    t: float | np.ndarray


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A planned trajectory: line, states and inputs at N nodes of a closed lap.

    Attributes
    ----------
    s : ndarray, shape (N,)
        Arc length along the trajectory's own line, starting at 0, m.
    x, y : ndarray, shape (N,)
        Position of the centre of gravity, m.
    psi : ndarray, shape (N,)
        Heading of the line (unwrapped), rad.
    kappa : ndarray, shape (N,)
        Curvature of the line, 1/m (> 0 turning left).
    vx, vy : ndarray, shape (N,)
        Longitudinal and lateral velocity in the body frame, m/s.
    r : ndarray, shape (N,)
        Yaw rate, rad/s.
    ax : ndarray, shape (N,)
        Longitudinal tyre acceleration input a_x, m/s^2.
    delta : ndarray, shape (N,)
        Steering angle, rad.
    t : ndarray, shape (N,)
        Time at the nodes, starting at 0, s.
    track_name : str
        Name of the track planned on.
    track_checksum : str
        ``Track.checksum()`` of that track (plans are refused on another track).
    method : str
        ``'centerline'``, ``'curvature'`` or ``'time-optimal'``.
    model : CarModel or None
        The model the plan was made with (parameters, options, steering actuator, margins); the
        MPC predicts with it. None for a plan of unknown origin (an old plan file, the best lap,
        which uses the car's own equations).
    planned_lap_time : float
        Lap time of the plan, s (includes the interval from the last node back to the first).
    info : dict
        Free-form extras (solver statistics); not written to the CSV.
    line_length : float
        Length of the closed line, m (default: last s plus the closing chord).
    """

    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    kappa: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    r: np.ndarray
    ax: np.ndarray
    delta: np.ndarray
    t: np.ndarray
    track_name: str = ""
    track_checksum: str = ""
    method: str = ""
    model: CarModel | None = None
    planned_lap_time: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)
    line_length: float = float("nan")

    def __post_init__(self) -> None:
        n = None
        for name in PLAN_FIELDS:
            arr = np.asarray(getattr(self, name), dtype=float).ravel()
            object.__setattr__(self, name, arr)
            if n is None:
                n = arr.size
            if arr.size != n:
                raise PlanningError(
                    f"Trajectory field {name!r} has {arr.size} values, expected {n} like 's'; "
                    "every field needs one value per node."
                )
            if not np.all(np.isfinite(arr)):
                raise PlanningError(
                    f"Trajectory field {name!r} contains NaN or infinite values; the planner "
                    "produced an unusable plan, re-plan with another method."
                )
        if self.model is not None and not isinstance(self.model, CarModel):
            raise PlanningError(
                f"Trajectory.model must be a racing_lib.model.CarModel or None, got "
                f"{type(self.model).__name__}."
            )
        if n is None or n < 4:
            raise PlanningError("a Trajectory needs at least 4 nodes; plan on a finer grid.")
        if np.any(np.diff(self.s) <= 0):
            raise PlanningError("Trajectory s must be strictly increasing; resample the plan.")
        if not math.isfinite(self.line_length):
            chord = math.hypot(self.x[0] - self.x[-1], self.y[0] - self.y[-1])
            object.__setattr__(self, "line_length", float(self.s[-1] + chord))
        if self.line_length <= self.s[-1]:
            raise PlanningError("Trajectory line_length must exceed the last s; re-plan.")
        if not math.isfinite(self.planned_lap_time):
            # Close the lap with the last interval at the mean speed of its ends.
            gap = self.length - self.s[-1]
            v_end = 0.5 * (
                math.hypot(self.vx[-1], self.vy[-1]) + math.hypot(self.vx[0], self.vy[0])
            )
            object.__setattr__(self, "planned_lap_time", float(self.t[-1] + gap / v_end))

    @property
    def model_options(self) -> dict[str, bool]:
        """The model effects planned with, as a dict (empty when the model is unknown)."""
        return {} if self.model is None else options_to_dict(self.model.options)

    def with_model(self, model: CarModel | None) -> Trajectory:
        """The same plan, labelled with the model it was made with."""
        new = dataclasses.replace(self, model=model)
        if "path" in self.__dict__:  # the line is the same: keep the Path already built
            object.__setattr__(new, "path", self.__dict__["path"])
        return new

    # ------------------------------------------------------------------ geometry
    @cached_property
    def path(self) -> Path:
        """The line as a closed :class:`racing_lib.geometry.Path` (built from x, y)."""
        try:
            return Path(self.x, self.y)
        except RacingLibError as exc:
            raise PlanningError(
                f"the planned line cannot be made into a Path ({exc}); re-plan with a finer grid "
                "or another method."
            ) from exc

    @property
    def length(self) -> float:
        """Length of the closed line, m.

        Length of the closed line, m (the interval from the last node back to the first
        included).
        """
        return float(self.line_length)

    @property
    def lap_time(self) -> float:
        """Planned lap time, s."""
        return float(self.planned_lap_time)

    @property
    def n(self) -> int:
        """Number of nodes."""
        return int(self.s.size)

    def interpolate(self, s: ArrayLike) -> TrajectoryState:
        """States at arc lengths ``s`` (m, along the line, wrapped modulo the length).

        Linear interpolation between nodes; heading is interpolated unwrapped; time is continued
        into the next lap (t + lap time) so that it keeps increasing with s.
        """
        length = self.length
        s_arr = np.asarray(s, dtype=float)
        scalar = s_arr.ndim == 0
        sq = np.mod(np.atleast_1d(s_arr), length)
        s_ext = np.append(self.s, length)
        out: dict[str, Any] = {"s": sq}
        for name in PLAN_FIELDS[1:]:
            vals = getattr(self, name)
            if name == "t":
                end = self.planned_lap_time
            elif name == "psi":
                end = self.psi[0] + 2.0 * math.pi * round(
                    (self.psi[-1] - self.psi[0]) / (2 * math.pi)
                )
            else:
                end = vals[0]
            out[name] = np.interp(sq, s_ext, np.append(vals, end))
        if scalar:
            out = {k: float(v[0]) for k, v in out.items()}
        return TrajectoryState(**out)

    def speed(self, s: ArrayLike) -> np.ndarray:
        """Planned v_x at arc length ``s`` (m), for controllers that want a speed function."""
        return self.interpolate(s).vx

    def scale_speed(self, factor: float) -> Trajectory:
        """The same line driven ``factor`` times as fast (a gentler reference when < 1).

        Speeds and yaw rate scale with ``factor``, times with ``1 / factor`` and the longitudinal
        acceleration with ``factor**2``; the line and the steering are kept. Used for the moderate
        reference of the nominal controller (chapter 01).

        Parameters
        ----------
        factor : float
            Positive speed ratio, dimensionless.
        """
        k = float(factor)
        if not (math.isfinite(k) and k > 0.0):
            raise PlanningError(f"scale_speed needs a positive factor, got {factor!r}.")
        return dataclasses.replace(
            self,
            vx=self.vx * k,
            vy=self.vy * k,
            r=self.r * k,
            ax=self.ax * k * k,
            t=self.t / k,
            planned_lap_time=self.planned_lap_time / k,
            info={**self.info, "speed_scale": k},
        )

    # ------------------------------------------------------------------ files
    def metadata(self) -> dict[str, str | int]:
        """The metadata written in a plan file's header (the checksum line excluded)."""
        return {
            "format_version": PLAN_FORMAT_VERSION,
            "track": self.track_name,
            "track_checksum": self.track_checksum,
            "method": self.method,
            "model_options": json.dumps(self.model_options, sort_keys=True),
            "model": json.dumps(
                None if self.model is None else self.model.to_dict(), sort_keys=True
            ),
            "planned_lap_time_s": f"{self.planned_lap_time:.6f}",
            "length_m": f"{self.line_length:.6f}",
            "nodes": self.n,
        }

    def save_csv(self, path: str | os.PathLike[str]) -> None:
        """Write the plan file atomically: metadata, the model, the nodes and a checksum.

        The format is :mod:`racing_lib.planning.plan_file`'s; :meth:`load_csv` reads it back,
        the model bit for bit.
        """
        data = np.column_stack([getattr(self, name) for name in PLAN_FIELDS])
        write_plan_file(path, self.metadata(), data)

    @classmethod
    def load_csv(cls, path: str | os.PathLike[str], track: Track | None = None) -> Trajectory:
        """Read a plan file written by :meth:`save_csv`, refusing any that is not intact.

        See :func:`racing_lib.planning.plan_file.read_plan_file`: a plan truncated, edited by hand,
        spliced from two files or made for another track than ``track`` raises a
        :class:`PlanningError` that names the file and says what to do.
        """
        f = read_plan_file(path, track)
        return cls(
            **f.columns,
            track_name=f.track_name,
            track_checksum=f.track_checksum,
            method=f.method,
            model=f.model,
            planned_lap_time=f.planned_lap_time,
            line_length=f.line_length,
        )

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_states(
        cls,
        x: ArrayLike,
        y: ArrayLike,
        vx: ArrayLike,
        vy: ArrayLike,
        r: ArrayLike,
        ax: ArrayLike,
        delta: ArrayLike,
        dt: ArrayLike,
        *,
        track: Track | None = None,
        method: str = "",
        model: CarModel | None = None,
        info: Mapping[str, object] | None = None,
    ) -> Trajectory:
        """Build a trajectory from positions, states and the time of each interval.

        The line's arc length, heading and curvature come from a Path through (x, y); ``dt[k]`` is
        the time from node k to node k+1 (the last one closes the lap), s. ``model`` is the model
        the states were planned with.
        """
        x = np.asarray(x, float)
        y = np.asarray(y, float)
        dt = np.asarray(dt, float)
        if np.any(~np.isfinite(dt)) or np.any(dt <= 0):
            raise PlanningError(
                "the plan has non-positive or NaN interval times (the speed is zero or negative "
                "somewhere); re-plan, e.g. with a warm start from the curvature plan."
            )
        try:
            path = Path(x, y)
        except RacingLibError as exc:
            raise PlanningError(
                f"the planned line cannot be made into a Path ({exc}); re-plan with a finer grid."
            ) from exc
        s = _node_arc_length(path, x, y)
        t = np.concatenate(([0.0], np.cumsum(dt[:-1])))
        traj = cls(
            s=s,
            x=x,
            y=y,
            psi=np.unwrap(np.asarray(path.heading(s), float)),
            kappa=np.asarray(path.curvature(s), float),
            vx=vx,
            vy=vy,
            r=r,
            ax=ax,
            delta=delta,
            t=t,
            track_name=getattr(track, "name", "") if track is not None else "",
            track_checksum=track.checksum() if track is not None else "",
            method=method,
            model=model,
            planned_lap_time=float(np.sum(dt)),
            info=dict(info or {}),
            line_length=float(path.length),
        )
        object.__setattr__(traj, "path", path)  # reuse the Path just built
        return traj

    @classmethod
    def from_centerline(
        cls,
        track: Track,
        params: ModelParams,
        pedal_map: PedalMap | AccelLimits | None = None,
        options: ModelOptions | None = None,
        spacing: float = 3.0,
        v_top: float | None = None,
    ) -> Trajectory:
        """The 'centerline' plan: drive the track centerline at its quasi-steady speed profile.

        Parameters
        ----------
        track : Track
            The track.
        params : ModelParams
            Planning model parameters, as they are (no grip margin is applied here; see
            :func:`racing_lib.planning.plan`).
        pedal_map : PedalMap, optional
            a_x limits (default: ``params.pedal_map`` if present).
        options : ModelOptions, optional
            Model options (the drag switch matters here).
        spacing : float
            Node spacing along the centerline, m.
        v_top : float, optional
            Top speed, m/s.
        """
        params, pedal_map, options = model_inputs(
            params, pedal_map, options, "Trajectory.from_centerline"
        )
        line = track.centerline
        n = max(8, int(round(line.length / spacing)))
        s = np.asarray(line.sample(n=n), float)
        theta = np.asarray(track.grade(s), float)
        return cls.at_speed_profile(
            track, line, s, theta, params, pedal_map, options, v_top, method="centerline"
        )

    @classmethod
    def at_speed_profile(
        cls,
        track: Track,
        path: Path,
        s: np.ndarray,
        theta: np.ndarray,
        params: ModelParams,
        pedal_map: PedalMap | AccelLimits | None,
        options: ModelOptions | None,
        v_top: float | None,
        method: str,
    ) -> Trajectory:
        """A closed line driven at its quasi-steady speed profile.

        Parameters
        ----------
        track : Track
            The track the line lies on (the plan's metadata).
        path : Path
            The closed line.
        s : ndarray
            Arc length of the nodes along ``path``, m, from 0.
        theta : ndarray
            Road grade at the nodes, rad.
        params, pedal_map, options, v_top
            As for :func:`racing_lib.planning.speed.speed_profile`.
        method : str
            Label stored in the trajectory's ``method``.

        Returns
        -------
        Trajectory
            ``v_y`` is zero and ``delta`` the kinematic steering angle of the line.
        """
        kappa = np.asarray(path.curvature(s), float)
        prof = speed_profile(
            s, kappa, params, pedal_map, theta, v_top, options, length=float(path.length)
        )
        x, y = path.position(s)
        v = prof.v
        wheelbase = float(params.l_f + params.l_r)
        return cls.from_states(
            x,
            y,
            vx=v,
            vy=np.zeros(len(s)),
            r=v * kappa,
            ax=prof.a_x,
            delta=np.arctan(wheelbase * kappa),  # kinematic steering angle of the arc
            dt=segment_times(np.diff(np.append(s, path.length)), v, np.roll(v, -1)),
            track=track,
            method=method,
            # A line judged with ad-hoc parameters (a point mass, say) has no model to carry.
            model=CarModel(params, options) if isinstance(params, ModelParams) else None,
            info={"speed_profile_success": prof.success},
        )


def model_inputs(
    params: ModelParams | None,
    pedal_map: PedalMap | AccelLimits | None,
    options: ModelOptions | None,
    who: str,
) -> tuple[ModelParams, PedalMap | AccelLimits, ModelOptions]:
    """The planners' model inputs, checked: ``params`` is required, the rest defaults.

    No planner picks a model of its own (the default is decided once, by
    :func:`racing_lib.planning.plan` and the other entry points); ``options`` defaults to
    ``ModelOptions()`` and ``pedal_map`` to ``params.pedal``.

    Raises
    ------
    PlanningError
        ``params`` is missing (``who`` names the planner in the message).
    """
    if params is None:
        raise PlanningError(
            f"{who} needs the model's parameters (a racing_lib.model.ModelParams): pass params, "
            "for example racing_lib.model.identified_params(), or plan with "
            "racing_lib.planning.plan(track), which uses the default model."
        )
    if options is None:
        options = ModelOptions()
    if pedal_map is None:
        pedal_map = params.pedal
    return params, pedal_map, options


def _node_arc_length(path: Path, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Arc length of the nodes (x, y) along ``path`` (a Path through them), m, starting at 0."""
    nodes = getattr(path, "s_nodes", None)
    if nodes is not None and len(nodes) == len(x):
        s = np.asarray(nodes, float)
        return s - s[0]
    return chord_arc_length(x, y, float(path.length))
