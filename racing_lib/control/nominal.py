"""The nominal controller: pure pursuit for steering and a PI loop on speed for the pedal.

It is the simple driver of the early chapters (taught in notebook 01) and the data-collection
driver of chapter 02, as the paper collected its identification data with "a simple nominal
controller". It needs no vehicle model beyond the wheelbase.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from racing_lib.errors import ControlError
from racing_lib.geometry import (
    FrenetTracker,
    Path,
)
from racing_lib.interfaces import Command, Observation
from racing_lib.vehicle.params import VehicleParams

SpeedFunction = Callable[[float], float]

#: Fraction of a plan's speed the nominal controller is asked to drive at by default: pure pursuit
#: has no model of grip, so it laps the built-in tracks cleanly only with a margin (chapter 01).
MODERATE_SPEED_SCALE = 0.75


#: The car whose data sheet gives the default wheelbase and steering limit.
_CAR = VehicleParams()


@dataclass(frozen=True)
class NominalSettings:
    """Gains of the nominal controller.

    Attributes
    ----------
    wheelbase : float
        l_f + l_r of the car, m (default: the simulated car's, 2.5701 m).
    lookahead_min : float
        Pure-pursuit look-ahead distance at standstill, m.
    lookahead_time : float
        Look-ahead grows with speed by this many seconds of travel, s.
    max_steer : float
        Steering command limit, rad.
    kp : float
        Proportional gain of the speed loop, pedal per m/s.
    ki : float
        Integral gain of the speed loop, pedal per m.
    preview_time : float
        The speed target is read this far ahead, s, so braking starts before the corner.
    speed_scale : float
        Fraction of the reference speed to drive at (1.0 = as given), dimensionless.
    dt : float
        Control period the integrator assumes, s (the simulated car's 0.1 s).
    """

    wheelbase: float = _CAR.wheelbase
    lookahead_min: float = 4.0
    lookahead_time: float = 0.3
    max_steer: float = _CAR.steer_max
    kp: float = 0.5
    ki: float = 0.05
    preview_time: float = 0.6
    speed_scale: float = 1.0
    dt: float = 0.1


class NominalController:
    """Pure pursuit + speed PI along a reference path.

    Parameters
    ----------
    path : Path
        The line to follow (a track centerline or a planned trajectory's path).
    speed : callable or float
        Target speed v(s) in m/s as a function of the arc length s (m) of ``path``, or a constant.
    settings : NominalSettings, optional
        Gains; defaults suit the built-in car and tracks.

    Examples
    --------
    >>> from racing_lib.tracks import load_track
    >>> track = load_track("expressway")
    >>> ctrl = NominalController(track.centerline, speed=20.0)
    """

    def __init__(
        self,
        path: Path,
        speed: SpeedFunction | float,
        settings: NominalSettings | None = None,
    ) -> None:
        self.path = path
        self.settings = settings or NominalSettings()
        if callable(speed):
            self._speed = speed
        else:
            v = float(speed)
            if not math.isfinite(v) or v <= 0.0:
                raise ControlError(
                    f"NominalController needs a positive target speed, got {speed!r}; "
                    "pass a speed in m/s or a function s -> v."
                )
            self._speed = lambda _s, v=v: v
        self._tracker = FrenetTracker(path)
        self._integral = 0.0

    @classmethod
    def from_trajectory(cls, trajectory, settings: NominalSettings | None = None):
        """Follow a planned :class:`~racing_lib.planning.trajectory.Trajectory` at its speed.

        Parameters
        ----------
        trajectory : Trajectory
            A plan with ``path``, ``s`` (m) and ``vx`` (m/s) arrays.
        settings : NominalSettings, optional
            Gains.
        """
        s = np.asarray(trajectory.s, dtype=float)
        vx = np.asarray(trajectory.vx, dtype=float)
        length = float(trajectory.path.length)

        def speed(si: float) -> float:
            return float(np.interp(si % length, s, vx, period=length))

        return cls(trajectory.path, speed, settings)

    def reset(self, obs: Observation) -> None:
        """Start a new lap from ``obs``: forget the integral and search the path globally."""
        self._tracker.reset()
        self._integral = 0.0
        self._tracker.project(obs.x, obs.y)

    def target_speed(self, s: float, v: float) -> float:
        """The speed target at arc length ``s`` (m) for a car at speed ``v`` (m/s), with preview."""
        st = self.settings
        return st.speed_scale * self._speed((s + st.preview_time * v) % self.path.length)

    def step(self, obs: Observation) -> Command:
        """One control period: steering from pure pursuit, pedal from the speed PI loop."""
        st = self.settings
        s, _ = self._tracker.project(obs.x, obs.y)
        v = max(obs.vx, 0.0)

        # Pure pursuit: aim at the path point one look-ahead distance ahead; the arc through it
        # has curvature 2 sin(alpha) / L_d, and a bicycle turns on that arc with
        # delta = atan(wheelbase * curvature).
        lookahead = st.lookahead_min + st.lookahead_time * v
        gx, gy = self.path.position((s + lookahead) % self.path.length)
        alpha = math.atan2(float(gy) - obs.y, float(gx) - obs.x) - obs.psi
        dist = math.hypot(float(gx) - obs.x, float(gy) - obs.y)
        steer = math.atan2(2.0 * st.wheelbase * math.sin(alpha), max(dist, 1e-3))
        steer = min(max(steer, -st.max_steer), st.max_steer)

        # Speed PI with a clamped integrator (anti-windup): the pedal saturates at +-1 anyway.
        err = self.target_speed(s, v) - v
        self._integral = min(max(self._integral + err * st.dt, -10.0), 10.0)
        pedal = st.kp * err + st.ki * self._integral
        pedal = min(max(pedal, -1.0), 1.0)
        return Command(steer=steer, pedal=pedal)

    def stats(self) -> dict[str, float]:
        """No counters worth reporting."""
        return {}
