"""The time trial as a Gymnasium environment, and the planner with the coupled MPC as its policy.

One episode is one lap: the car starts on the centerline at the start line, heading along it, at
``start_speed`` (30 m/s by default: a rolling start), and the episode ends when it has driven a
lap.

Observation, a float32 vector (all in SI units):

====== ==========================================================================
index  what
====== ==========================================================================
0-2    v_x, v_y (m/s, body frame), yaw rate r (rad/s)
3-4    heading error e_psi (rad) and lateral offset e_y (m, > 0 left) on the centerline
5      progress: the share of the lap driven (0 at the start, 1 at the line; below 0 when
       the car drives backwards)
6-7    room to the left and to the right edge from the car's centre, m
8-9    the previous action (normalised steering, pedal)
10-    curvature of the centerline ahead (1/m, > 0 left) at ``lookahead`` distances (m)
====== ==========================================================================

Each entry is clipped to the observation space's bounds (120 m/s, 60 m/s, 20 rad/s, pi rad,
100 m, 2, 100 m, 100 m, 1, 1, then 1/m), which a car on the road never reaches.

Action: ``(steering, pedal)`` in [-1, 1]^2; steering is the share of the car's steering-angle
limit (left positive), pedal is throttle (> 0) or brake (< 0), as the :class:`Plant` takes it.

Reward: the progress along the centerline in the step, m (so a lap's return is its length).

Termination: the lap is complete (``info["lap_time_s"]``), the car touched a wall, its centre left
the road, or it spun (heading more than 90 degrees off the centerline). Truncation: the time limit
(default: long enough for a lap at 5 m/s). ``info["end"]`` says which.

Stepping after the episode ended is refused: call ``reset()``. ``info["observation"]`` holds the
plant's own :class:`~racing_lib.interfaces.Observation`, so that
the library's controllers, which work in the plane, can act: see :class:`MPCPolicy`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from racing_lib.errors import ArgumentError
from racing_lib.experiments.configs import tuned_weights
from racing_lib.experiments.own_car import named_car
from racing_lib.geometry import FrenetTracker, Track
from racing_lib.geometry.spline import wrap_angle
from racing_lib.interfaces import Observation, Plant
from racing_lib.tracks import CircuitSpec, generate, load_track
from racing_lib.vehicle import VehicleParams

__all__ = ["LOOKAHEAD", "MPCPolicy", "TimeTrialEnv"]

#: Distances ahead at which the observation samples the centerline's curvature, m.
LOOKAHEAD = tuple(float(d) for d in range(10, 201, 10))
_SPIN = math.pi / 2.0  # [rad] heading error beyond which the car has spun
# Bounds of the observation's first ten entries (and 1/m for the curvature: a 1 m radius); an
# observation is clipped to them (a car beyond them has long left the road).
_HIGH = np.array([120.0, 60.0, 20.0, math.pi, 100.0, 2.0, 100.0, 100.0, 1.0, 1.0])


class TimeTrialEnv(gymnasium.Env):
    """One lap of a circuit with a car, behind Gymnasium's ``Env`` API (see the module notes).

    Parameters
    ----------
    track : str, Track or "generated"
        A built-in track name, a racetrack-database CSV file, a Track, or ``"generated"``: a new
        circuit per episode from :func:`racing_lib.tracks.generate`, its seed drawn from the
        episode's random stream (so ``reset(seed=...)`` fixes it too).
    plant : str or callable
        ``"sim"`` (the simulated car), a car name of :data:`racing_lib.plants.CARS` such as
        ``"commonroad:vehicle2"``, or a factory ``(track, start_speed) -> Plant`` that puts the
        car at the start line heading along the track (like
        :class:`racing_lib.plants.commonroad.CommonRoadAt`).
    steer_max : float, optional
        The steering angle an action of 1 asks for, rad (default: a named car's own limit, and
        the simulated car's 0.5 rad for a factory). It is in every ``info`` as ``steer_max``.
    start_speed : float
        Speed at the start, m/s. (The MPC of :class:`MPCPolicy` tracks a plan made for flying
        laps; from 30 m/s it drives every track of the tests, from 10 m/s it can lose the car.)
    time_limit_s : float, optional
        Truncate after this simulated time, s (default: the lap at 5 m/s, plus 30 s).
    lookahead : sequence of float
        Distances ahead for the curvature in the observation, m.
    circuits : CircuitSpec, optional
        What ``track="generated"`` draws from (default: :class:`CircuitSpec`'s ranges).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        track: str | Track = "expressway",
        plant: str | Callable[[Track, float], Plant] = "sim",
        *,
        steer_max: float | None = None,
        start_speed: float = 30.0,
        time_limit_s: float | None = None,
        lookahead: Sequence[float] = LOOKAHEAD,
        circuits: CircuitSpec | None = None,
        render_mode: str | None = None,
    ) -> None:
        if render_mode is not None:
            raise ArgumentError(
                f"render_mode={render_mode!r}: this environment does not render; draw a lap from "
                "info['observation'] with racing_lib.face.plotting."
            )
        self.render_mode = None
        self._make_plant, car_steer_max = _plant_factory(plant)
        self.steer_max = _positive("steer_max", car_steer_max if steer_max is None else steer_max)
        self.start_speed = _positive("start_speed", start_speed, below=80.0)
        self._time_limit = None if time_limit_s is None else _positive("time_limit_s", time_limit_s)
        try:
            self.lookahead = np.asarray(lookahead, dtype=float)
        except (TypeError, ValueError):
            self.lookahead = np.full(1, np.nan)
        if not (self.lookahead.ndim == 1 and np.all(np.isfinite(self.lookahead))
                and np.all(self.lookahead >= 0.0)):  # fmt: skip
            raise ArgumentError(
                f"lookahead must be a list of distances ahead >= 0 m, got {lookahead!r}."
            )
        self._generated = isinstance(track, str) and track == "generated"
        if circuits is not None and not self._generated:
            raise ArgumentError(
                "circuits= says what track='generated' draws; with a fixed track it would be "
                "ignored: pass track='generated', or drop circuits."
            )
        if circuits is not None and not isinstance(circuits, CircuitSpec):
            raise ArgumentError(
                f"circuits must be a racing_lib.tracks.CircuitSpec, got {type(circuits).__name__}."
            )
        self._circuits = circuits if circuits is not None else CircuitSpec()
        if self._generated:
            self._circuits.check()
            self.track: Track | None = None
        else:
            if not isinstance(track, (str, os.PathLike, Track)):
                raise ArgumentError(
                    "track must be a track name, a CSV file, a Track or 'generated', got "
                    f"{type(track).__name__}."
                )
            self.track = track if isinstance(track, Track) else load_track(track)
        high = np.concatenate([_HIGH, np.ones(self.lookahead.size)]).astype(np.float32)
        self.observation_space = spaces.Box(-high, high, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._plant: Any = None
        self._plant_track: Track | None = None

    # ----------------------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a lap; ``seed`` fixes the car's randomness (and a generated circuit)."""
        super().reset(seed=seed)
        if self._generated:
            circuit_seed = int(self.np_random.integers(2**31 - 1))
            self.track = generate(circuit_seed, self._circuits)
        if self._plant is None or self._plant_track is not self.track:
            self._plant = self._make_plant(self.track, self.start_speed)
            self._plant_track = self.track
            self._tracker = FrenetTracker(self.track.centerline)
        obs = self._plant.reset(seed=int(self.np_random.integers(2**31 - 1)))
        self._tracker.reset()
        self._driven = 0.0
        self._t0 = obs.t
        self._last_action = np.zeros(2)
        self._walls = int(getattr(self._plant, "wall_contacts", 0))
        self._limit = (
            self._time_limit if self._time_limit is not None else self.track.length / 5.0 + 30.0
        )
        self._ended = False
        self._where = self._frenet(obs)
        return self._observe(obs), self._info(obs, end=None)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Send one command for one control period of the car (the plant's ``dt``)."""
        if self._plant is None or self._ended:
            raise ArgumentError(
                "call reset() first: " + ("no episode has started." if self._plant is None
                                          else "the episode has ended.")
            )  # fmt: skip
        try:
            a = np.asarray(action, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            a = np.full(1, np.nan)
        if a.size != 2 or not np.all(np.isfinite(a)):
            raise ArgumentError(
                f"an action is (steering, pedal), two finite numbers in [-1, 1]; got {action!r}."
            )
        a = np.clip(a, -1.0, 1.0)
        obs = self._plant.step(float(a[0]) * self.steer_max, float(a[1]))
        self._last_action = a
        s_before = self._where[0]
        self._where = self._frenet(obs)
        length = self.track.length
        progress = (self._where[0] - s_before + 0.5 * length) % length - 0.5 * length
        self._driven += progress
        end = self._end(obs)
        self._ended = end is not None
        info = self._info(obs, end)
        if end == "lap":
            info["lap_time_s"] = float(obs.t - self._t0)
        truncated = end == "time limit"
        return (
            self._observe(obs),
            float(progress),
            end is not None and not truncated,
            truncated,
            info,
        )

    # ----------------------------------------------------------------------------------------
    def _frenet(self, obs: Observation) -> tuple[float, float, float]:
        """Arc length (m), lateral offset (m) and heading error (rad) on the centerline.

        One projection per step: every later use reads ``self._where``.
        """
        s, e_y = self._tracker.project(obs.x, obs.y)
        return s, e_y, float(wrap_angle(obs.psi - self._tracker.heading))

    def _observe(self, obs: Observation) -> np.ndarray:
        s, e_y, e_psi = self._where
        line = self.track
        ahead = (s + self.lookahead) % line.length
        room_left = float(line.width_left(s)) - e_y
        room_right = float(line.width_right(s)) + e_y
        head = [obs.vx, obs.vy, obs.r, e_psi, e_y, self._driven / line.length]
        head += [room_left, room_right, *self._last_action]
        vector = np.concatenate([head, line.curvature(ahead)]).astype(np.float32)
        return np.clip(vector, self.observation_space.low, self.observation_space.high)

    def _end(self, obs: Observation) -> str | None:
        """Why the episode ends after this step, or None."""
        if self._driven >= self.track.length:
            return "lap"
        if int(getattr(self._plant, "wall_contacts", 0)) > self._walls:
            return "wall"
        s, e_y, e_psi = self._where
        if e_y > float(self.track.width_left(s)) or -e_y > float(self.track.width_right(s)):
            return "off track"
        if abs(e_psi) > _SPIN:
            return "spin"
        if obs.t - self._t0 >= self._limit:
            return "time limit"
        return None

    def _info(self, obs: Observation, end: str | None) -> dict[str, Any]:
        return {
            "observation": obs,
            "track": self.track.name,
            "driven_m": float(self._driven),
            "steer_max": self.steer_max,
            "time_s": float(obs.t - self._t0),
            "end": end,
        }


def _positive(name: str, value: Any, below: float = math.inf) -> float:
    """``value`` as a float in (0, below), or one ArgumentError naming ``name``."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if not (ok and math.isfinite(value) and 0.0 < value < below):
        span = "> 0" if below == math.inf else f"in (0, {below:g})"
        raise ArgumentError(f"{name} must be a number {span}, got {value!r}.")
    return float(value)


def _plant_factory(plant: Any) -> tuple[Callable[[Track, float], Plant], float]:
    """The plant factory and the car's steering-angle limit (rad) of ``plant``."""
    if isinstance(plant, str):
        car = named_car(plant)  # ArgumentError for an unknown name, with the known ones
        steer = car.steer_max if car.steer_max is not None else VehicleParams().steer_max
        return car.car.make_plant, float(steer)
    if callable(plant):
        return plant, VehicleParams().steer_max
    raise ArgumentError(
        f"plant must be a car name (e.g. 'sim', 'commonroad:vehicle2') or a factory "
        f"(track, start_speed) -> Plant, got {type(plant).__name__}."
    )


class MPCPolicy:
    """The course's driver as a policy of :class:`TimeTrialEnv`.

    A time-optimal plan of the episode's circuit, tracked by the coupled MPC with the shipped tuned
    weights. Use it as the baseline a learned policy is measured against::

        env = gymnasium.make("racing_lib/TimeTrial-v0", track="shortcut")
        policy = MPCPolicy()
        obs, info = env.reset(seed=0)
        policy.reset(env.unwrapped.track, info)
        while True:
            obs, reward, terminated, truncated, info = env.step(policy(obs, info))
            if terminated or truncated:
                break

    Parameters
    ----------
    model : CarModel, optional
        The model to plan and predict with (default: the identified model of the simulated car).
    weights : dict, optional
        MPC weights (default: the shipped tuned set).
    """

    def __init__(self, model: Any = None, weights: dict[str, float] | None = None) -> None:
        self.model = model
        self.weights = weights if weights is not None else tuned_weights()
        self._plans: dict[str, Any] = {}
        self._controller: Any = None
        self._steer_max = math.nan

    def reset(self, track: Track, info: dict[str, Any]) -> None:
        """Plan ``track`` (once per circuit) and start the MPC from the episode's first state.

        ``info`` is the one ``env.reset`` returned: its ``observation`` starts the MPC, and its
        ``steer_max`` (rad) turns the MPC's steering angle into the environment's action.
        """
        from racing_lib.control import build_controller
        from racing_lib.planning import plan

        key = track.checksum()
        if key not in self._plans:
            self._plans[key] = plan(track, "time-optimal", self.model).trajectory
        self._controller = build_controller(
            "coupled-mpc", self._plans[key], track=track, weights=self.weights
        )
        self._controller.reset(info["observation"])
        self._steer_max = float(info["steer_max"])

    def __call__(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        """The action for the state in ``info["observation"]`` (normalised steering, pedal)."""
        if self._controller is None:
            raise ArgumentError("call MPCPolicy.reset(track, info) at the start of each episode.")
        command = self._controller.step(info["observation"])
        steer = np.clip(command.steer / self._steer_max, -1.0, 1.0)
        return np.array([steer, np.clip(command.pedal, -1.0, 1.0)], dtype=np.float32)
