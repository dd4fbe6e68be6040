"""System identification: the planning model's parameters from logs of the (simulated) car.

Taught in notebook 02 ("identifying the race vehicle model"). The paper identified its model from
data driven in Gran Turismo Sport with a simple nominal controller; we do the same with the
simulated car of :mod:`racing_lib.sim`, which is deliberately *not* the planning model (combined
slip, load-sensitive tyres, gears, power limit, steering lag), so the identified parameters are the
best planning-model fit to a different car -- as they were in the paper.

What a user of a real car has, and all we use: time, position, yaw, the body-frame velocities
``v_x, v_y``, the yaw rate ``r`` (the spatial observations of
:class:`~racing_lib.interfaces.Observation`), the commands sent (steering command and pedal), and
the track map (road pitch ``theta`` at the car's position). The car's internals (``state_info()``:
gear, actual steering angle, ...) are never used; only the report compares against the true
:class:`~racing_lib.vehicle.VehicleParams`.

Taken as known (the paper lists them as the car's data sheet): ``m, l_f, l_r, h_c, l_t, mu, g``.
Identified, in this order (each step uses the ones before it):

1. **Tyres, steady state** (constant-radius circles): with ``r_dot ~ 0`` the yaw-moment balance
   (Eq. 8) splits the measured lateral force ``m a_y`` between the axles without ``I_zz``:
   ``F_yf cos(delta) = m a_y l_r / L``, ``F_yr = m a_y l_f / L``. Each axle's force per unit load
   against its slip angle (Eq. 11) is fitted with the simplified Pacejka law (Eq. 9-10) by nonlinear
   least squares: ``B, C, D`` front and rear (``mu`` known, so ``D`` is the peak factor).
2. **Steering lag and yaw inertia, transients** (steering steps): the time constant of the
   steering actuator (a first-order lag of the command; the real angle is not observed) from the
   lateral balance ``m a_y = F_yf cos(delta) + F_yr`` (one-parameter nonlinear least squares), then
   ``I_zz`` by linear least squares from the yaw balance with the front force eliminated through the
   measured lateral balance, ``I_zz r_dot = l_f m a_y - L F_yr``. This form matters: the steering
   actuator's noise and lag act on the front axle, and with the front force eliminated they appear
   identically on both sides instead of only in ``r_dot`` (which biased ``I_zz`` 10 % low).
3. **Drag and rolling resistance** (coast-down, pedal 0): ``v_x_dot - r v_y + F_yf sin(delta)/m +
   g sin(theta) = -C_xw v_x^2 / m - c_rr g cos(theta)`` by linear least squares.
4. **Pedal map** (Appendix C; laps and pedal steps): the tyre acceleration
   ``a_x = v_x_dot - r v_y + (C_xw v_x^2 + R_x + F_yf sin(delta))/m + g sin(theta)``
   against ``[1, v_x, max(u_p, 0), min(u_p, 0)]`` by linear least squares
   (:class:`~racing_lib.model.PedalMap`).

Derivatives. The commands are held constant over each 0.1 s control period (zero-order hold) and
the plant is integrated finely in between, so the observed states are exact samples of a smooth
trajectory whose derivatives jump at every command change. The *interval* difference
``(v[k+1] - v[k]) / dt`` is then exactly the mean acceleration over the period in which command
``k`` acted, and we pair it with the period's mean state ``(v[k] + v[k+1]) / 2`` (trapezoid, second
order). A central difference or a Savitzky-Golay filter would blend two or more commands into one
derivative, which biases the pedal map and smears steering steps; they are the right choice only for
noisy measurements. The observations of the simulated car carry no measurement noise (its randomness
is in the actuation), so ``derivative="interval"`` is the default and ``derivative="savgol"``
(window 7, quadratic) is offered for noisy logs of other plants. On the same fast-mode data (seed 3)
the interval differences gave ``C_xw`` -0.0 % and ``I_zz`` -2.5 %, Savitzky-Golay -4.0 % and
+13 % (it smears the throttle-to-coast switch and the steering steps).

Data selection. Samples with the car sliding (``|v_y| > 0.1 v_x``) and the first second of each log
(unknown actuator state) are dropped everywhere; the tyre, lag and inertia fits use only the
designed manoeuvres (``circles``, ``steps``) with little longitudinal acceleration
(``|v_x_dot| < 1.5 m/s^2``), because the simulated tyres share their friction between the
longitudinal and lateral forces and laps contain wall contacts the logs cannot flag. The coast-down
also tests for engine braking at pedal 0 (a deceleration term linear in speed); the simulated car
has none, which the result's ``notes`` report.

Examples
--------
>>> from racing_lib.sysid import collect_logs, identify
>>> from racing_lib.model import identified_params
>>> from racing_lib.vehicle import VehicleParams
>>> logs = collect_logs(seed=1, fast=True)              # doctest: +SKIP
>>> result = identify(logs, truth=VehicleParams())      # doctest: +SKIP
>>> print(result.report())                              # doctest: +SKIP
>>> params = identified_params()   # the shipped fit (seed 0), what later chapters use
>>> params.pedal.m_brk > params.pedal.m_thr > 0
True

Bad input raises :class:`~racing_lib.errors.ModelError` naming the parameter that cannot be
determined and the manoeuvre that would determine it (see :data:`MANOEUVRES`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path as FsPath
from typing import Any, Literal

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from racing_lib.config import fast_mode
from racing_lib.errors import ModelError
from racing_lib.io import atomic_write_json
from racing_lib.model import ModelParams, PedalMap, X
from racing_lib.model.actuator import lagged_steering
from racing_lib.model.identified import DATA_FILE
from racing_lib.vehicle import (
    axle_cornering_stiffness,
    drag_force,
    longitudinal_load_transfer,
    pacejka_lateral,
    rolling_resistance,
    static_axle_loads,
)

__all__ = [
    "MANOEUVRES",
    "TOLERANCES",
    "DriveLog",
    "FitStats",
    "IdentificationResult",
    "coast_down_log",
    "circle_logs",
    "collect_logs",
    "identify",
    "lap_logs",
    "main",
    "pedal_map_r2",
    "run",
    "step_logs",
]

Derivative = Literal["interval", "savgol"]

#: The manoeuvres :func:`collect_logs` drives, and what each one identifies.
MANOEUVRES: dict[str, str] = {
    "laps": "nominal-controller laps of the built-in tracks at a few speed scalings (pedal map)",
    "coast-down": "pedal 0 from high speed on a long, nearly straight road (C_xw, c_rr)",
    "circles": "steady-state constant-radius circles at rising speed (Pacejka B, C, D)",
    "steps": "steps of steering and pedal around a large circle (I_zz, steering lag, pedal map)",
    "braking": "full brake from several speeds on a long, nearly straight road (braking limit)",
}

#: Relative tolerances the identification is tested against (``tests/test_sysid.py``), chosen from
#: what the data can honestly give. The simulated car's tyres are load sensitive and share their
#: friction between longitudinal and lateral force, which the planning model's do not; its nominal
#: ``B, C, D`` are therefore not exactly the best planning-model fit, and the individual ``B`` and
#: ``C`` trade against each other (so only the peak ``mu D`` and the cornering stiffness
#: ``mu F_z0 B C D`` are toleranced). The fitted peak is the *axle's* effective one: in a fast
#: corner the inner wheel carries little load and the load-sensitive tyres lose grip to the
#: transfer, so it lies below the single tyre's ``mu D``. Observed over seeds 1-4 and 7, full and
#: fast data, with the car's actuation noise: drag and rolling resistance within 0.1 %; front peak
#: -15.6 to -16.3 %; rear peak -15.7 to -17.6 % (``C`` at its lower bound of 1.2, see
#: ``_fit_axle``); cornering stiffnesses within 6 %; ``I_zz`` -3 to -5.5 %; steering lag within
#: 1.5 %.
TOLERANCES: dict[str, float] = {
    "C_xw": 0.10,
    "c_rr": 0.25,
    "I_zz": 0.15,
    "mu*D_f": 0.20,
    "mu*D_r": 0.22,
    "C_alpha_f": 0.20,
    "C_alpha_r": 0.20,
}

_MIN_SAMPLES = 50  # shortest usable set of samples for any one regression
_V_MIN = 5.0  # m/s: below this slip angles and drag are too small to be informative


# --------------------------------------------------------------------------------------------------
# Logs
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DriveLog:
    """One recorded run: observations at the control rate and the commands sent.

    Node arrays have ``N + 1`` entries (observations ``k = 0..N``); command arrays have ``N``
    (command ``k`` was sent after observation ``k`` and held until observation ``k + 1``).

    Attributes
    ----------
    name : str
        Human-readable label, e.g. ``"circle R=60 m"``.
    kind : str
        Which manoeuvre it is, a key of :data:`MANOEUVRES`.
    t : ndarray (N+1,)
        Time, s.
    x, y : ndarray (N+1,)
        Position, m.
    psi : ndarray (N+1,)
        Yaw angle, rad.
    vx, vy : ndarray (N+1,)
        Body-frame longitudinal and lateral velocity, m/s.
    r : ndarray (N+1,)
        Yaw rate, rad/s.
    theta : ndarray (N+1,)
        Road pitch at the car's position from the track map, rad (positive uphill).
    steer : ndarray (N,)
        Steering command, rad.
    pedal : ndarray (N,)
        Pedal command in [-1, 1].
    """

    name: str
    kind: str
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    r: np.ndarray
    theta: np.ndarray
    steer: np.ndarray
    pedal: np.ndarray

    def __post_init__(self) -> None:
        nodes = ("t", "x", "y", "psi", "vx", "vy", "r", "theta")
        n = np.asarray(self.t).size
        for key in (*nodes, "steer", "pedal"):
            arr = np.asarray(getattr(self, key), dtype=float).ravel()
            want = n if key in nodes else n - 1
            if arr.size != want:
                raise ModelError(
                    f"DriveLog {self.name!r}: {key} has {arr.size} samples, expected {want} "
                    "(N + 1 observations, N commands)."
                )
            if not np.all(np.isfinite(arr)):
                raise ModelError(
                    f"DriveLog {self.name!r}: {key} contains NaN or infinite values; drop the "
                    "broken part of the log."
                )
            object.__setattr__(self, key, arr)

    @property
    def duration(self) -> float:
        """Length of the log, s."""
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0


def _record(
    plant: Any,
    obs: Any,
    policy: Callable[[Any, int], tuple[float, float]],
    n_steps: int,
    name: str,
    kind: str,
    grade: Callable[[float, float], float] | None = None,
    stop: Callable[[Any], bool] | None = None,
) -> DriveLog:
    """Drive ``plant`` from observation ``obs`` with ``policy(obs, k) -> (steer, pedal)``."""
    rows = [obs]
    cmds: list[tuple[float, float]] = []
    for k in range(n_steps):
        steer, pedal = policy(obs, k)
        steer, pedal = float(steer), float(min(max(pedal, -1.0), 1.0))
        obs = plant.step(steer, pedal)
        cmds.append((steer, pedal))
        rows.append(obs)
        if stop is not None and stop(obs):
            break
    arr = {key: np.array([getattr(o, key) for o in rows]) for key in ("t", "x", "y", "psi")}
    for key in ("vx", "vy", "r"):
        arr[key] = np.array([getattr(o, key) for o in rows])
    theta = np.array([grade(o.x, o.y) for o in rows]) if grade is not None else np.zeros(len(rows))
    c = np.array(cmds, dtype=float).reshape(-1, 2)
    return DriveLog(name, kind, theta=theta, steer=c[:, 0], pedal=c[:, 1], **arr)


# --------------------------------------------------------------------------------------------------
# Data collection with the simulated car
# --------------------------------------------------------------------------------------------------


def _proving_ground(radius: float, width: float, name: str) -> Any:
    """A flat, open circular test area of the given centre-line radius and total width (m)."""
    from racing_lib.geometry import (
        Path,
        Track,
    )

    n = max(int(2.0 * math.pi * radius / 5.0), 64)
    a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return Track(
        Path(radius * np.cos(a), radius * np.sin(a)),
        width / 2.0,
        width / 2.0,
        boundary="open",
        name=name,
    )


def _car(track: Any, params: Any, start_speed: float, seed: int | None) -> tuple[Any, Any]:
    """A simulated car on ``track`` and its first observation (after a seeded reset)."""
    from racing_lib.sim import SimulatedCar

    car = SimulatedCar(track, params, dt=0.1, start_s=0.0, start_speed=start_speed)
    return car, car.reset(seed=seed)


def _follower(track: Any) -> Any:
    """Pure-pursuit steering along the track's centre line (speed is commanded separately)."""
    from racing_lib.control.nominal import NominalController

    return NominalController(track.centerline, speed=10.0)


class _SpeedHold:
    """A PI loop on the pedal, for manoeuvres that hold a speed while steering is commanded."""

    def __init__(self, kp: float = 0.4, ki: float = 0.15, dt: float = 0.1) -> None:
        self.kp, self.ki, self.dt = kp, ki, dt
        self.integral = 0.0

    def __call__(self, v_target: float, v: float) -> float:
        err = v_target - v
        self.integral = min(max(self.integral + err * self.dt, -4.0), 4.0)
        return min(max(self.kp * err + self.ki * self.integral, -1.0), 1.0)


def coast_down_log(
    params: Any = None, seed: int = 0, v_high: float = 42.0, v_low: float = 8.0
) -> DriveLog:
    """Coast-down: full throttle to ``v_high`` (m/s), then pedal 0 until ``v_low`` (m/s).

    Driven on a 1.5 km radius circle (lateral acceleration below 1.2 m/s^2 at 42 m/s, so the
    steering's share of the deceleration is tiny and is still accounted for). Only the pedal-0
    part is used for drag and rolling resistance; the run-up is pedal-map data.

    The car runs without its per-trial actuation noise (``reset(seed=None)``): a foot off the
    pedals is exactly pedal 0, while the simulated car's additive pedal noise would turn "0" into
    random light braking and throttle whose mean (about 0.04 m/s^2, brakes being ~5 times stronger
    per unit pedal than the engine) is as large as the rolling resistance itself. ``seed`` is
    unused and kept for a uniform signature.
    """
    track = _proving_ground(1500.0, 30.0, "coast-down circle")
    car, obs0 = _car(track, _vehicle(params), start_speed=15.0, seed=None)
    ctrl = _follower(track)
    ctrl.reset(obs0)
    phase = {"coast": False}

    def policy(obs: Any, k: int) -> tuple[float, float]:
        if obs.vx >= v_high:
            phase["coast"] = True
        return ctrl.step(obs).steer, (0.0 if phase["coast"] else 1.0)

    return _record(
        car,
        obs0,
        policy,
        6000,
        f"coast-down {v_high:.0f}->{v_low:.0f} m/s",
        "coast-down",
        stop=lambda o: phase["coast"] and o.vx < v_low,
    )


def braking_logs(
    params: Any = None, speeds: Sequence[float] = (45.0, 35.0, 25.0), v_low: float = 8.0
) -> list[DriveLog]:
    """Straight-line stops: full throttle to each of ``speeds`` (m/s), then full brake to ``v_low``.

    On the coast-down's 1.5 km circle, without actuation noise (a full stop is full brake). They
    measure the deceleration the tyres give when the brakes ask for more than the grip, which the
    brake slope of the pedal map, fitted on partial braking, cannot tell.
    """
    track = _proving_ground(1500.0, 30.0, "braking circle")
    logs = []
    for v_high in speeds:
        car, obs0 = _car(track, _vehicle(params), start_speed=15.0, seed=None)
        ctrl = _follower(track)
        ctrl.reset(obs0)
        phase = {"brake": False}

        def policy(obs: Any, k: int, v_high=v_high, ctrl=ctrl, phase=phase) -> tuple[float, float]:
            if obs.vx >= v_high:
                phase["brake"] = True
            return ctrl.step(obs).steer, (-1.0 if phase["brake"] else 1.0)

        logs.append(
            _record(
                car,
                obs0,
                policy,
                3000,
                f"full stop {v_high:.0f}->{v_low:.0f} m/s",
                "braking",
                stop=lambda o, phase=phase: phase["brake"] and o.vx < v_low,
            )
        )
    return logs


def circle_logs(
    params: Any = None,
    seed: int = 0,
    radii: Sequence[float] = (40.0, 80.0, 150.0),
    levels: int = 8,
    hold: float = 5.0,
) -> list[DriveLog]:
    """Steady-state cornering: constant-radius circles (ISO 4138) at rising speed.

    For each radius R (m) the car follows the circle with pure pursuit at ``levels`` speeds from
    a lateral acceleration of about 0.2 g up to about 0.95 of the friction limit ``mu g``, holding
    each for ``hold`` s, so the steering settles to a constant at every level (a steady state with
    ``r_dot ~ 0``).
    """
    vp = _vehicle(params)
    mu, g = float(vp.mu), float(vp.g)
    logs = []
    for i, radius in enumerate(radii):
        track = _proving_ground(radius, 40.0, f"circle R={radius:.0f} m")
        speeds = np.sqrt(np.linspace(0.2, 0.95, levels) * mu * g * radius)
        car, obs0 = _car(track, vp, start_speed=float(speeds[0]), seed=seed + 101 * i)
        ctrl = _follower(track)
        ctrl.reset(obs0)
        hold_steps = int(round(hold / 0.1))
        pi = _SpeedHold()

        def policy(obs: Any, k: int, speeds=speeds, ctrl=ctrl, pi=pi, h=hold_steps):
            v_target = float(speeds[min(k // h, len(speeds) - 1)])
            return ctrl.step(obs).steer, pi(v_target, obs.vx)

        logs.append(
            _record(car, obs0, policy, hold_steps * levels, f"circle R={radius:.0f} m", "circles")
        )
    return logs


def step_logs(
    params: Any = None,
    seed: int = 0,
    speeds: Sequence[float] = (15.0, 25.0, 35.0),
    duration: float = 40.0,
) -> list[DriveLog]:
    """Steering steps and pedal steps around a 300 m radius circle, 60 m wide.

    At each base speed (m/s) the log alternates 10 s phases. *Steering phases*: a PI loop holds
    the speed while random steering offsets (held 0.5-1.5 s, up to the kinematic steer of
    0.35 mu g at that speed and at most 0.04 rad, so that the actuator stays below its rate
    limit) are added to pure pursuit: yaw transients with little longitudinal force, for ``I_zz``
    and the steering lag. *Pedal phases*: pure pursuit steers while random pedal
    levels (held 1-3 s; throttle in [0, 1], brake in [-0.5, 0], the sign keeping the speed within
    +-30 % of the base) excite the powertrain and brakes, for the pedal map. Keeping the two apart
    matters: the simulated tyres share their friction between longitudinal and lateral force (which
    the planning model does not), so yaw transients under hard throttle or braking would bias the
    tyre and inertia fits. Braking stays below half pedal because harder braking overloads the
    simulated car's rear brakes (a 75 % front share against the load transfer of a ~1 g stop) and
    spins it. ``seed`` fixes the random sequences.
    """
    vp = _vehicle(params)
    L = float(vp.l_f + vp.l_r)
    mu, g = float(vp.mu), float(vp.g)
    phase = 100  # control periods per phase (10 s)
    logs = []
    for i, v0 in enumerate(speeds):
        rng = np.random.default_rng(seed + 1000 + i)
        track = _proving_ground(300.0, 60.0, f"steps {v0:.0f} m/s")
        car, obs0 = _car(track, vp, start_speed=float(v0), seed=seed + 2000 + i)
        ctrl = _follower(track)
        ctrl.reset(obs0)
        n = int(round(duration / 0.1))
        # A swing of 2 amp stays inside the actuator's linear band (steer_rate_max * steer_tau).
        amp = min(0.35 * mu * g * L / v0**2, 0.04)
        steer_off = np.zeros(n)
        pedal_lvl = np.zeros(n)
        k = 0
        while k < n:
            hold = int(rng.integers(5, 16))
            steer_off[k : k + hold] = rng.uniform(-amp, amp) if rng.random() < 0.7 else 0.0
            k += hold
        k = 0
        while k < n:
            hold = int(rng.integers(10, 31))
            pedal_lvl[k : k + hold] = rng.uniform(0.0, 1.0)
            k += hold
        pi = _SpeedHold()
        sign = [1.0]

        def policy(
            obs: Any, k: int, ctrl=ctrl, so=steer_off, pl=pedal_lvl, v0=v0, pi=pi, sign=sign
        ):
            steer = ctrl.step(obs).steer
            if abs(obs.vy) > 0.08 * max(obs.vx, 1.0):
                return steer, 0.0  # a slide: recover with pure pursuit alone, no pedal
            if (k // phase) % 2 == 0:  # steering phase
                return steer + so[k], pi(v0, obs.vx)
            # Pedal phase: a random walk in speed, reversed at the edges of the band.
            if obs.vx < 0.7 * v0:
                sign[0] = 1.0
            elif obs.vx > 1.3 * v0:
                sign[0] = -1.0
            elif k % 30 == 0:
                sign[0] = -sign[0]
            return steer, sign[0] * pl[k] * (1.0 if sign[0] > 0.0 else 0.5)

        logs.append(_record(car, obs0, policy, n, f"steps at {v0:.0f} m/s", "steps"))
    return logs


def lap_logs(
    params: Any = None,
    seed: int = 0,
    tracks: Sequence[str] = ("expressway", "shortcut"),
    scalings: Sequence[float] = (0.6, 0.8),
    max_time: float = 200.0,
) -> list[DriveLog]:
    """Nominal-controller laps of the built-in tracks at fractions of the track's speed profile.

    As in the paper, a simple nominal controller (pure pursuit + speed PI) drives the car along
    the centre line; ``scalings`` are fractions of the quasi-steady-state speed profile of
    :func:`racing_lib.planning.speed.speed_profile`, m/s.
    """
    from racing_lib.control.nominal import NominalController, NominalSettings
    from racing_lib.geometry import FrenetTracker
    from racing_lib.planning.speed import speed_profile
    from racing_lib.tracks import load_track

    vp = _vehicle(params)
    logs = []
    for i, name in enumerate(tracks):
        track = load_track(name)
        s = track.centerline.sample(ds=2.0)
        prof = speed_profile(s, track.centerline.curvature(s), params=vp, length=track.length)
        for j, scale in enumerate(scalings):
            car, obs0 = _car(
                track, vp, start_speed=float(scale * prof(0.0)), seed=seed + 10 * i + j
            )
            ctrl = NominalController(
                track.centerline,
                lambda si, prof=prof: float(prof(si)),
                NominalSettings(speed_scale=scale),
            )
            ctrl.reset(obs0)
            tracker = FrenetTracker(track.centerline)

            def grade(x: float, y: float, tracker=tracker, track=track) -> float:
                return float(track.grade(tracker.project(x, y)[0]))

            def policy(obs: Any, k: int, ctrl=ctrl) -> tuple[float, float]:
                cmd = ctrl.step(obs)
                return cmd.steer, cmd.pedal

            n = int(round(min(max_time, 1.05 * prof.lap_time / scale) / 0.1))
            logs.append(
                _record(car, obs0, policy, n, f"lap {name} x{scale:.2f}", "laps", grade=grade)
            )
    return logs


def _vehicle(params: Any) -> Any:
    from racing_lib.vehicle import VehicleParams

    return VehicleParams() if params is None else params


def collect_logs(seed: int = 0, params: Any = None, fast: bool | None = None) -> list[DriveLog]:
    """Drive every manoeuvre of :data:`MANOEUVRES` with the simulated car and return the logs.

    Parameters
    ----------
    seed : int
        Seeds the car's per-trial randomness and the random step sequences; a different seed gives
        fresh data.
    params : VehicleParams, optional
        The car to drive (default: the built-in car).
    fast : bool, optional
        Collect less data (shorter laps, fewer levels); default :func:`racing_lib.config.fast_mode`.

    Returns
    -------
    list of DriveLog
    """
    fast = fast_mode() if fast is None else fast
    logs: list[DriveLog] = []
    if fast:
        logs.append(coast_down_log(params, seed, v_high=38.0, v_low=12.0))
        logs += circle_logs(params, seed, radii=(50.0, 120.0), levels=6, hold=4.0)
        logs += step_logs(params, seed, speeds=(18.0, 30.0), duration=30.0)
        logs += lap_logs(params, seed, tracks=("shortcut",), scalings=(0.8,), max_time=60.0)
        logs += braking_logs(params, speeds=(45.0, 35.0))
    else:
        logs.append(coast_down_log(params, seed))
        logs += circle_logs(params, seed)
        logs += step_logs(params, seed)
        logs += lap_logs(params, seed)
        logs += braking_logs(params)
    return logs


# --------------------------------------------------------------------------------------------------
# Samples: one per control period
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Samples:
    """Per-control-period quantities of all logs, concatenated (arrays of shape (M,))."""

    kind: np.ndarray  # manoeuvre of the log the sample came from
    log: np.ndarray  # index of that log
    vx: np.ndarray  # mean states over the period, m/s, m/s, rad/s
    vy: np.ndarray
    r: np.ndarray
    theta: np.ndarray  # road pitch, rad
    dvx: np.ndarray  # mean derivatives over the period, m/s^2, m/s^2, rad/s^2
    dvy: np.ndarray
    dr: np.ndarray
    steer: np.ndarray  # steering command, rad
    pedal: np.ndarray  # pedal command, -
    settled: np.ndarray  # True when the steering command has been steady for 1 s
    age: np.ndarray  # index of the sample within its log
    bounds: tuple[tuple[int, int], ...]  # [start, stop) of each log's samples

    @property
    def valid(self) -> np.ndarray:
        """Samples inside the planning model's domain: moving forward, not sliding sideways.

        A body slip ``|v_y| > 0.1 v_x`` (about 6 degrees) means a spin or a slide: the model's tyres
        and small-angle slip are not meant for it, so such samples are left out of every fit.
        The first second of each log is left out too: the actuator's state when the log starts is
        unknown, so the steering-lag reconstruction needs that long to forget it.
        """
        moving = (self.vx > 1.0) & (np.abs(self.vy) <= 0.1 * np.maximum(self.vx, 1.0))
        return moving & (self.age >= 10)

    @property
    def a_y(self) -> np.ndarray:
        """Lateral acceleration of the centre of gravity, v_y_dot + r v_x, m/s^2."""
        return self.dvy + self.r * self.vx

    def steer_effective(self, tau: float, dt: float = 0.1) -> np.ndarray:
        """Mean actual steering angle over each period for a first-order actuator lag ``tau`` (s).

        The angle obeys ``tau delta_dot = delta_cmd - delta`` with the command held over the period;
        each log starts settled (``delta = delta_cmd[0]``).
        """
        if tau <= 1e-4:
            return self.steer
        out = np.empty_like(self.steer)
        for start, stop in self.bounds:
            out[start:stop] = lagged_steering(self.steer[start:stop], tau, dt)
        return out


def _samples(logs: Sequence[DriveLog], derivative: Derivative) -> _Samples:
    if derivative not in ("interval", "savgol"):
        raise ModelError(f"unknown derivative method {derivative!r}; use 'interval' or 'savgol'.")
    cols: dict[str, list[np.ndarray]] = {k: [] for k in _Samples.__dataclass_fields__}
    bounds = []
    start = 0
    for i, log in enumerate(logs):
        n = log.steer.size
        if n < 8:
            continue  # too short to differentiate; the total length is checked by the caller
        dt = np.diff(log.t)
        if np.any(dt <= 0.0):
            raise ModelError(f"DriveLog {log.name!r}: time must increase strictly.")
        nodes = {"vx": log.vx, "vy": log.vy, "r": log.r, "theta": log.theta}
        for key in ("vx", "vy", "r"):
            v = nodes[key]
            if derivative == "interval":
                # Exact mean derivative over the period in which command k was held.
                d = np.diff(v) / dt
                m = 0.5 * (v[:-1] + v[1:])
            else:
                h = float(np.median(dt))
                d_nodes = savgol_filter(v, 7, 2, deriv=1, delta=h, mode="interp")
                v_nodes = savgol_filter(v, 7, 2, mode="interp")
                d = 0.5 * (d_nodes[:-1] + d_nodes[1:])
                m = 0.5 * (v_nodes[:-1] + v_nodes[1:])
            cols[key].append(m)
            cols["d" + key].append(d)
        cols["theta"].append(0.5 * (log.theta[:-1] + log.theta[1:]))
        cols["steer"].append(log.steer)
        cols["pedal"].append(log.pedal)
        # Steady steering: the command moved less than 5 mrad over the last 10 periods.
        s = log.steer
        settled = np.zeros(n, dtype=bool)
        for k in range(10, n):
            settled[k] = np.ptp(s[k - 10 : k + 1]) < 5e-3
        cols["settled"].append(settled)
        cols["age"].append(np.arange(n))
        cols["kind"].append(np.full(n, log.kind, dtype=object))
        cols["log"].append(np.full(n, i))
        bounds.append((start, start + n))
        start += n
    if not bounds:
        return _Samples(
            **{k: np.zeros(0) for k in cols if k != "bounds"},
            bounds=(),
        )
    return _Samples(
        **{k: np.concatenate(v) for k, v in cols.items() if k != "bounds"},
        bounds=tuple(bounds),
    )


# --------------------------------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------------------------------


def _missing(what: str, detail: str, manoeuvre: str) -> ModelError:
    """The error for data that cannot determine ``what``: names the manoeuvre that would."""
    return ModelError(
        f"cannot identify {what}: {detail}. Add the '{manoeuvre}' manoeuvre "
        f"({MANOEUVRES[manoeuvre]}) to the logs, e.g. with racing_lib.sysid.collect_logs()."
    )


def _condition(A: np.ndarray) -> float:
    """Condition number of the regressor with its columns scaled to unit norm (scale-free)."""
    norms = np.linalg.norm(A, axis=0)
    if np.any(norms == 0.0):
        return math.inf
    return float(np.linalg.cond(A / norms))


def _check_regressor(A: np.ndarray, names: Sequence[str], what: str, manoeuvre: str) -> float:
    """Raise if the columns of ``A`` are nearly linearly dependent; return the condition number."""
    cond = _condition(A)
    if not math.isfinite(cond) or cond > 1e4:
        norms = np.linalg.norm(A, axis=0)
        weakest = names[int(np.argmin(norms))] if np.any(norms == 0.0) else "/".join(names)
        raise _missing(
            what,
            f"the regressors {list(names)} are nearly collinear (condition number {cond:.3g} "
            f"> 1e4; weakest: {weakest})",
            manoeuvre,
        )
    return cond


def _r2(y: np.ndarray, residual: np.ndarray) -> float:
    ss = float(np.sum((y - np.mean(y)) ** 2))
    return 1.0 - float(np.sum(residual**2)) / ss if ss > 0.0 else float("nan")


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else float("nan")


# --------------------------------------------------------------------------------------------------
# Fits
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FitStats:
    """Quality of one regression.

    Attributes
    ----------
    name : str
        Which fit (e.g. ``"tyres (steady state)"``).
    n : int
        Number of samples used.
    rms : float
        Root-mean-square residual, in ``unit``.
    unit : str
        Unit of the residual.
    r2 : float
        Coefficient of determination of the fitted quantity (held-out data for the pedal map).
    cond : float
        Condition number of the (column-scaled) regressor or Jacobian at the solution.
    """

    name: str
    n: int
    rms: float
    unit: str
    r2: float
    cond: float


def _axle_loads(kp: ModelParams, S: _Samples) -> tuple[np.ndarray, np.ndarray]:
    """Axle loads (N) with the longitudinal load transfer of the measured v_x_dot (Eq. 12)."""
    F_zf0, F_zr0 = static_axle_loads(kp.m, kp.l_f, kp.l_r, kp.g, S.theta)
    dW = longitudinal_load_transfer(kp.m, S.dvx, kp.h_c, kp.l_f, kp.l_r)
    return F_zf0 - dW, F_zr0 + dW


def _slip(kp: ModelParams, S: _Samples, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slip angles alpha_f, alpha_r (Eq. 11), rad."""
    vx = np.maximum(S.vx, 1.0)
    return delta - (S.vy + kp.l_f * S.r) / vx, -(S.vy - kp.l_r * S.r) / vx


def _jac_condition(jac: Any) -> float:
    J = np.asarray(jac.todense() if hasattr(jac, "todense") else jac)
    return _condition(J)


def _fit_axle(alpha: np.ndarray, phi: np.ndarray, mu: float) -> tuple[np.ndarray, Any]:
    """Pacejka B, C, D of one axle from force per unit load ``phi`` at slip ``alpha``.

    ``C`` is kept at or above 1.2 so that the fitted curve has a force peak (at
    ``tan(pi / (2 C)) / B``), which the planner and the MPC use as their slip bound. The simulated
    car's axles are broad (the inner wheel, nearly unloaded in a fast corner, peaks early, the
    outer one late), and with ``C`` free the fit drifts to ``C ~ 1``, a curve without a peak, for
    an RMS residual only about 1 % smaller.
    """
    best = None
    for C0 in (1.3, 1.9):
        res = least_squares(
            lambda p: pacejka_lateral(alpha, 1.0, mu, p[0], p[1], p[2]) - phi,
            x0=[10.0, C0, 1.0],
            bounds=([1.0, 1.2, 0.2], [60.0, 1.99, 3.0]),
            x_scale=[10.0, 1.0, 1.0],
        )
        if best is None or res.cost < best.cost:
            best = res
    return best.x, best


def _fit_lateral(
    kp: ModelParams, S: _Samples, fit_lag: bool
) -> tuple[dict[str, float], dict[str, FitStats]]:
    """Steps 1 and 2: tyres from the steady state, then the steering lag and I_zz from all data."""
    g, mu = kp.g, kp.mu
    # Little longitudinal force: the car's tyres share friction between x and y, the model's don't.
    # Designed manoeuvres only: laps add wall contacts and kerb-to-kerb slides the logs cannot flag.
    designed = (S.kind == "circles") | (S.kind == "steps")
    lat = designed & S.valid & (S.vx > _V_MIN) & (np.abs(S.dvx) < 1.5)
    if not np.any(designed):
        raise _missing(
            "the Pacejka tyre parameters B, C, D and the yaw inertia I_zz",
            "the logs hold no steady-state circles and no steering steps (laps are not used for "
            "the tyres: wall contacts and slides would corrupt them)",
            "circles",
        )
    if not np.any(lat) or (
        np.max(np.abs(S.steer[lat])) < 0.01 and np.max(np.abs(S.a_y[lat])) < 1.0
    ):
        raise _missing(
            "the Pacejka tyre parameters B, C, D and the yaw inertia I_zz",
            "the logs contain no steering (|delta| < 0.01 rad and |a_y| < 1 m/s^2 throughout)",
            "circles",
        )
    ss = lat & S.settled & (np.abs(S.dr) < 0.03) & (np.abs(S.dvy) < 0.1) & (np.abs(S.dvx) < 0.5)
    ss &= np.abs(S.a_y) > 0.3
    a_y_max = float(np.max(np.abs(S.a_y[ss]))) if np.any(ss) else 0.0
    if np.count_nonzero(ss) < 30 or a_y_max < 0.55 * mu * g:
        raise _missing(
            "the Pacejka tyre parameters B, C, D",
            f"{np.count_nonzero(ss)} steady-state cornering samples reaching |a_y| = "
            f"{a_y_max:.1f} m/s^2; the peak factor D needs >= 30 samples up to at least "
            f"{0.55 * mu * g:.1f} m/s^2 (0.55 mu g)",
            "circles",
        )

    # Step 1: steady state (r_dot ~ 0): the yaw balance splits m a_y between the axles.
    F_zf, F_zr = _axle_loads(kp, S)
    L = kp.wheelbase
    a_f, a_r = _slip(kp, S, S.steer)
    phi_f = kp.m * S.a_y * kp.l_r / L / np.cos(S.steer) / F_zf
    phi_r = kp.m * S.a_y * kp.l_f / L / F_zr
    (Bf, Cf, Df), res_f = _fit_axle(a_f[ss], phi_f[ss], mu)
    (Br, Cr, Dr), res_r = _fit_axle(a_r[ss], phi_r[ss], mu)
    stats = {
        "tyres (steady state)": FitStats(
            "tyres (steady state)",
            int(np.count_nonzero(ss)),
            _rms(np.concatenate([res_f.fun * F_zf[ss], res_r.fun * F_zr[ss]])) / kp.m,
            "m/s^2",
            _r2(np.concatenate([phi_f[ss], phi_r[ss]]), np.concatenate([res_f.fun, res_r.fun])),
            max(_jac_condition(res_f.jac), _jac_condition(res_r.jac)),
        )
    }

    # Step 2a: the steering lag from the lateral balance m a_y = F_yf(delta) cos(delta) + F_yr, with
    # the steady-state tyres (a one-parameter nonlinear least-squares fit). The tyre curves stay
    # those of the steady state, which sees them cleanly.
    tr = lat & (np.abs(S.dr) > 0.2)
    if np.count_nonzero(tr) < 20:
        raise _missing(
            "the yaw inertia I_zz",
            f"only {np.count_nonzero(tr)} samples with |r_dot| > 0.2 rad/s^2 (need >= 20): the "
            "logs have no yaw transients",
            "steps",
        )
    idx = np.flatnonzero(lat)
    Ssub = _subset(S, idx)
    F_zf_s, F_zr_s = F_zf[idx], F_zr[idx]

    def front_rear(tau: float) -> tuple[np.ndarray, np.ndarray]:
        delta = S.steer_effective(tau)[idx]
        af, ar = _slip(kp, Ssub, delta)
        fyf = pacejka_lateral(af, F_zf_s, mu, Bf, Cf, Df) * np.cos(delta)
        return fyf, pacejka_lateral(ar, F_zr_s, mu, Br, Cr, Dr)

    def lateral_residual(q: np.ndarray) -> np.ndarray:
        fyf, fyr = front_rear(float(q[0]))
        return (fyf + fyr) / kp.m - Ssub.a_y

    if fit_lag:
        res = least_squares(lateral_residual, [0.05], bounds=([0.0], [0.5]), x_scale=[0.05])
        tau = float(res.x[0])
    else:
        tau = 0.0

    # Step 2b: I_zz by linear least squares from the yaw balance with the front force eliminated
    # through the measured lateral balance: I_zz r_dot = l_f m a_y - L F_yr. The front axle carries
    # the steering, so its force is where the actuator noise and lag enter; in this form that noise
    # appears identically on both sides (l_f dF_yf) instead of only in r_dot, which would bias I_zz
    # low (errors in the regressor). Only the rear tyre model enters.
    fyf, fyr = front_rear(tau)
    rd = Ssub.dr
    y_rear = kp.l_f * kp.m * Ssub.a_y - L * fyr
    A = rd[:, None]
    I_zz = float(np.linalg.lstsq(A, y_rear, rcond=None)[0][0])
    if not I_zz > 0.0:
        raise _missing(
            "the yaw inertia I_zz",
            f"the yaw-balance fit gave a non-positive inertia ({I_zz:.3g} kg m^2)",
            "steps",
        )
    n = idx.size
    e_lat = (fyf + fyr) / kp.m - Ssub.a_y
    e_yaw = (kp.l_f * fyf - kp.l_r * fyr) / I_zz - rd  # the full model's yaw-acceleration error
    stats["lateral balance (all data)"] = FitStats(
        "lateral balance (all data)", n, _rms(e_lat), "m/s^2", _r2(Ssub.a_y, e_lat), 1.0
    )
    stats["yaw balance (all data)"] = FitStats(
        "yaw balance (all data)",
        n,
        _rms(e_yaw),
        "rad/s^2",
        _r2(rd, e_yaw),
        1.0,  # one regressor (r_dot); its excitation was checked above
    )
    full = np.array([Bf, Cf, Df, Br, Cr, Dr, I_zz / 1000.0, tau])
    p = full
    names = ("B_f", "C_f", "D_f", "B_r", "C_r", "D_r")
    out = {k: float(v) for k, v in zip(names, p[:6], strict=True)}
    out["I_zz"] = float(p[6] * 1000.0)
    out["steer_tau"] = float(p[7])
    return out, stats


def _subset(S: _Samples, idx: np.ndarray) -> _Samples:
    """The samples ``idx`` (the lag filter must run on the full samples: index its output)."""
    fields_ = {k: getattr(S, k)[idx] for k in S.__dataclass_fields__ if k != "bounds"}
    return _Samples(**fields_, bounds=())


def _front_force_sin(kp: ModelParams, S: _Samples, tyres: dict[str, float]) -> np.ndarray:
    """``F_yf sin(delta)`` (N) with the identified tyres and steering lag: the steering's drag."""
    delta = S.steer_effective(tyres["steer_tau"])
    F_zf, _ = _axle_loads(kp, S)
    a_f, _ = _slip(kp, S, delta)
    return pacejka_lateral(a_f, F_zf, kp.mu, tyres["B_f"], tyres["C_f"], tyres["D_f"]) * np.sin(
        delta
    )


def _fit_coast_down(
    kp: ModelParams, S: _Samples, fyf_sin: np.ndarray
) -> tuple[dict[str, float], dict[str, FitStats]]:
    """Step 3: C_xw and c_rr from the pedal-0 samples of coast-downs (linear least squares)."""
    cd = S.valid & (S.kind == "coast-down") & (S.pedal == 0.0) & (S.vx > _V_MIN)
    n = int(np.count_nonzero(cd))
    v = S.vx[cd]
    if n < _MIN_SAMPLES:
        raise _missing(
            "the drag C_xw and rolling resistance c_rr",
            f"only {n} pedal-0 coast-down samples above {_V_MIN:.0f} m/s (need >= {_MIN_SAMPLES})",
            "coast-down",
        )
    spread = (np.max(v**2) - np.min(v**2)) / np.max(v**2)
    if spread < 0.5:
        raise _missing(
            "the drag C_xw and rolling resistance c_rr",
            f"the coast-down speed only spans {np.min(v):.1f}-{np.max(v):.1f} m/s: at "
            "near-constant speed drag (v^2) and rolling resistance (constant) cannot be told apart",
            "coast-down",
        )
    # Measured resistance: what is left of v_x_dot after the kinematic, steering and grade terms.
    y = S.dvx[cd] - S.r[cd] * S.vy[cd] + fyf_sin[cd] / kp.m + kp.g * np.sin(S.theta[cd])
    A = np.column_stack(
        [
            -drag_force(v, 1.0) / kp.m,  # per unit C_xw
            -rolling_resistance(kp.m * kp.g * np.cos(S.theta[cd]), 1.0) / kp.m,  # per unit c_rr
        ]
    )
    cond = _check_regressor(A, ["v_x^2 (drag)", "1 (rolling)"], "C_xw and c_rr", "coast-down")
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    e = y - A @ coef
    # Engine braking check: a powertrain that drags at pedal 0 adds a deceleration growing with
    # engine speed, i.e. roughly linear in v_x within a gear. Fit that term too; if it matters, keep
    # drag and rolling resistance from the extended fit and leave the engine braking to the pedal
    # map's state term m_0 + m_vx v_x (the measured a_x the map is fitted to includes it). Its
    # constant part cannot be told apart from rolling resistance with pedal-0 data alone.
    A3 = np.column_stack([A, v])
    coef3, *_ = np.linalg.lstsq(A3, y, rcond=None)
    e3 = y - A3 @ coef3
    linear = float(coef3[2] * np.mean(v))  # m/s^2 at the mean coast-down speed
    engine_braking = abs(linear) > 0.01 and _rms(e3) < 0.8 * _rms(e)
    if engine_braking:
        coef, e = coef3[:2], e3
        cond = _condition(A3)
        note = (
            f"engine braking at pedal 0 detected (speed-linear deceleration {linear:+.3f} m/s^2 at "
            f"{np.mean(v):.0f} m/s): drag and rolling resistance from the extended coast-down fit; "
            "the engine braking is left to the pedal map's state term"
        )
    else:
        note = (
            f"no engine braking at pedal 0 (speed-linear term {linear:+.4f} m/s^2 at "
            f"{np.mean(v):.0f} m/s, below 0.01): the coast-down is drag + rolling resistance only"
        )
    stats = {"coast-down": FitStats("coast-down", n, _rms(e), "m/s^2", _r2(y, e), cond)}
    return {"C_xw": float(coef[0]), "c_rr": float(coef[1]), "note": note}, stats


def _pedal_regressor(S: _Samples, v_corner: float | None) -> np.ndarray:
    """Columns ``1, v_x, max(u_p, 0) min(1, v_corner / v_x), min(u_p, 0)``.

    For a fixed corner speed ``v_corner`` (where the power hyperbola meets the torque-limited
    gain ``m_thr``) the map is linear in its coefficients; None: no power limit.
    """
    throttle = np.maximum(S.pedal, 0.0)
    if v_corner is not None:
        throttle = throttle * np.minimum(1.0, v_corner / np.maximum(S.vx, 1.0))
    return np.column_stack([np.ones_like(S.vx), S.vx, throttle, np.minimum(S.pedal, 0.0)])


def _best_corner_speed(S: _Samples, y: np.ndarray) -> float | None:
    """The corner speed ``p_thr / m_thr`` (m/s) that fits ``y`` best, or None for no power limit.

    A one-dimensional search (the rest is linear least squares): a grid, then a bounded refinement.
    None when the best corner lies above the data's speeds, i.e. the engine never ran out of power.
    """
    from scipy.optimize import minimize_scalar

    def sse(v_corner: float) -> float:
        A = _pedal_regressor(S, v_corner)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        return float(np.sum((y - A @ coef) ** 2))

    v_top = float(np.percentile(S.vx[S.pedal > 0.2], 95))
    grid = np.geomspace(3.0, max(v_top, 4.0), 40)
    costs = [sse(v) for v in grid]
    k = int(np.argmin(costs))
    if k == grid.size - 1:
        return None
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    return float(minimize_scalar(sse, bounds=(lo, hi), method="bounded").x)


def _tyre_ax(kp: ModelParams, S: _Samples, fyf_sin: np.ndarray) -> np.ndarray:
    """Measured tyre acceleration a_x (m/s^2): Eq. 5 solved for a_x."""
    resist = drag_force(S.vx, kp.C_xw) + rolling_resistance(kp.m * kp.g * np.cos(S.theta), kp.c_rr)
    return S.dvx - S.r * S.vy + (resist + fyf_sin) / kp.m + kp.g * np.sin(S.theta)


def _fit_pedal(
    kp: ModelParams, S: _Samples, fyf_sin: np.ndarray
) -> tuple[PedalMap, dict[str, FitStats]]:
    """Step 4: the pedal map by linear least squares, with a held-out R^2."""
    # Stops at full brake are saturated by the tyres, not by the brakes: they are for the
    # braking limit (_fit_brake_limit), not for the slope.
    use = S.valid & (S.vx > 3.0) & (S.kind != "braking")
    thr = np.count_nonzero(use & (S.pedal > 0.2))
    brk = np.count_nonzero(use & (S.pedal < -0.2))
    if thr < 20 or brk < 20:
        raise _missing(
            "the pedal map (throttle and brake slopes)",
            f"{thr} throttle samples (u_p > 0.2) and {brk} brake samples (u_p < -0.2); each "
            "needs >= 20",
            "steps",
        )
    idx = np.flatnonzero(use)
    Su = _subset(S, idx)
    y = _tyre_ax(kp, Su, fyf_sin[idx])
    v_corner = _best_corner_speed(Su, y)
    A = _pedal_regressor(Su, v_corner)
    names = ["1", "v_x", "max(u_p, 0) (power-limited)", "min(u_p, 0)"]
    cond = _check_regressor(A, names, "the pedal map", "steps")
    # Hold out every fifth block of 50 periods (5 s) to judge the map on data it was not fit to.
    test = (np.arange(idx.size) // 50) % 5 == 4
    coef_train, *_ = np.linalg.lstsq(A[~test], y[~test], rcond=None)
    e_test = y[test] - A[test] @ coef_train
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    e = y - A @ coef
    if coef[2] <= 0.0 or coef[3] <= 0.0:
        raise _missing(
            "the pedal map",
            f"the fitted throttle/brake slopes ({coef[2]:.3g}, {coef[3]:.3g} m/s^2) are not both "
            "positive",
            "steps",
        )
    m_xi = np.zeros(len(X))
    m_xi[X.VX] = coef[1]  # only the speed drives the powertrain; other states would fit noise
    p_thr = None if v_corner is None else float(coef[2] * v_corner)
    pedal = PedalMap(m_0=coef[0], m_xi=tuple(m_xi), m_thr=coef[2], m_brk=coef[3], p_thr=p_thr)
    stats = {
        "pedal map": FitStats("pedal map", idx.size, _rms(e), "m/s^2", _r2(y, e), cond),
        "pedal map (held out)": FitStats(
            "pedal map (held out)",
            int(np.count_nonzero(test)),
            _rms(e_test),
            "m/s^2",
            _r2(y[test], e_test),
            cond,
        ),
    }
    return pedal, stats


def _fit_brake_limit(kp: ModelParams, S: _Samples, fyf_sin: np.ndarray) -> tuple[float | None, str]:
    """Step 4b: the tyres' deceleration limit (m/s^2) from the full stops, or None without them.

    The median tyre deceleration over the full-brake samples above 10 m/s (below, the brakes
    fade out towards standstill).
    """
    idx = np.flatnonzero(S.valid & (S.kind == "braking") & (S.pedal <= -0.999) & (S.vx > 10.0))
    if idx.size < _MIN_SAMPLES:
        return None, (
            f"no braking limit: {idx.size} full-brake samples above 10 m/s (need >= "
            f"{_MIN_SAMPLES}); add the 'braking' manoeuvre to bound a_min by the tyres"
        )
    decel = -_tyre_ax(kp, _subset(S, idx), fyf_sin[idx])
    limit = float(np.median(decel))
    spread = float(np.percentile(decel, 90) - np.percentile(decel, 10))
    return limit, (
        f"braking limit {limit:.2f} m/s^2 from {idx.size} full-brake samples "
        f"(10-90 % spread {spread:.2f} m/s^2)"
    )


def pedal_map_r2(params: ModelParams, logs: Sequence[DriveLog], steer_tau: float = 0.0) -> float:
    """R^2 of ``params.pedal`` predicting the measured tyre acceleration a_x of ``logs``.

    Uses the same measured a_x as the fit (Eq. 5 solved for a_x with ``params``' drag, rolling
    resistance and tyres); pass logs the map was not fitted to for an honest score.
    """
    S = _samples(logs, "interval")
    tyres = {k: getattr(params, k) for k in ("B_f", "C_f", "D_f")}
    tyres["steer_tau"] = steer_tau
    fyf_sin = _front_force_sin(params, S, tyres)
    idx = np.flatnonzero(S.valid & (S.vx > 3.0))
    S = _subset(S, idx)
    y = _tyre_ax(params, S, fyf_sin[idx])
    xi = np.zeros((S.vx.size, len(X)))
    xi[:, X.VX], xi[:, X.VY], xi[:, X.R] = S.vx, S.vy, S.r
    return _r2(y, y - params.pedal.ax(xi, S.pedal))


# --------------------------------------------------------------------------------------------------
# Result and entry points
# --------------------------------------------------------------------------------------------------


def _truth_params(truth: Any) -> tuple[ModelParams | None, float | None]:
    if truth is None:
        return None, None
    tp = truth if isinstance(truth, ModelParams) else ModelParams.from_vehicle(truth)
    tau = getattr(truth, "steer_tau", None)
    return tp, (float(tau) if tau is not None else None)


def _derived(p: ModelParams) -> dict[str, float]:
    """Quantities that decide the car's behaviour more directly than B, C, D alone."""
    F_zf, F_zr = p.static_loads()
    return {
        "mu*D_f": p.mu * p.D_f,
        "mu*D_r": p.mu * p.D_r,
        "C_alpha_f": axle_cornering_stiffness(F_zf, p.mu, p.B_f, p.C_f, p.D_f),
        "C_alpha_r": axle_cornering_stiffness(F_zr, p.mu, p.B_r, p.C_r, p.D_r),
    }


@dataclass(frozen=True)
class IdentificationResult:
    """What :func:`identify` found.

    Attributes
    ----------
    params : ModelParams
        The identified parameter set (known values ``m, l_f, l_r, h_c, l_t, mu, g`` passed through),
        with its :class:`~racing_lib.model.PedalMap`.
    steer_tau : float
        Identified time constant of the steering actuator, s (not part of the planning model; the
        controller may compensate it).
    fits : dict of FitStats
        Residuals, R^2 and conditioning of each regression.
    rows : list of dict
        The report table: ``name, unit, fitted, true, error_pct, fit, manoeuvre`` per value.
    notes : tuple of str
        Findings worth reading (e.g. whether the car has engine braking at pedal 0).
    n_samples : int
        Control periods in the logs.
    elapsed : float
        Wall time of the identification, s.
    """

    params: ModelParams
    steer_tau: float
    fits: dict[str, FitStats]
    rows: list[dict[str, Any]] = field(default_factory=list)
    notes: tuple[str, ...] = ()
    n_samples: int = 0
    elapsed: float = 0.0

    def value(self, name: str) -> float:
        """A fitted value by its report name (e.g. ``"C_xw"``, ``"mu*D_f"``, ``"C_alpha_r"``)."""
        for row in self.rows:
            if row["name"] == name:
                return float(row["fitted"])
        raise ModelError(f"no identified value {name!r}; known: {[r['name'] for r in self.rows]}.")

    def errors(self) -> dict[str, float]:
        """Relative error ``fitted / true - 1`` of every value that has a true counterpart."""
        return {
            r["name"]: r["fitted"] / r["true"] - 1.0
            for r in self.rows
            if r["true"] is not None and r["true"] != 0.0
        }

    def within_tolerance(self, tolerances: dict[str, float] | None = None) -> dict[str, bool]:
        """Per toleranced value (default :data:`TOLERANCES`): is ``|fitted/true - 1| <= tol``?"""
        tol = TOLERANCES if tolerances is None else tolerances
        err = self.errors()
        missing = sorted(set(tol) - set(err))
        if missing:
            raise ModelError(
                f"no true value for {missing}: pass truth=VehicleParams(...) to identify()."
            )
        return {k: abs(err[k]) <= t for k, t in tol.items()}

    def report(self) -> str:
        """The fitted-vs-true table and the fit statistics as aligned text."""
        head = ("value", "unit", "fitted", "true", "error", "from")
        lines = []
        for r in self.rows:
            true = "-" if r["true"] is None else f"{r['true']:.5g}"
            err = "-" if r["error_pct"] is None else f"{r['error_pct']:+.1f} %"
            lines.append((r["name"], r["unit"], f"{r['fitted']:.5g}", true, err, r["manoeuvre"]))
        widths = [max(len(x[i]) for x in [head, *lines]) for i in range(len(head))]
        fmt = "  ".join(f"{{:<{w}}}" for w in widths)
        out = [fmt.format(*head), fmt.format(*("-" * w for w in widths))]
        out += [fmt.format(*x) for x in lines]
        out.append("")
        fhead = ("fit", "samples", "RMS residual", "R^2", "cond")
        flines = [
            (f.name, str(f.n), f"{f.rms:.4g} {f.unit}", f"{f.r2:.4f}", f"{f.cond:.3g}")
            for f in self.fits.values()
        ]
        fw = [max(len(x[i]) for x in [fhead, *flines]) for i in range(len(fhead))]
        ffmt = "  ".join(f"{{:<{w}}}" for w in fw)
        out += [ffmt.format(*fhead), ffmt.format(*("-" * w for w in fw))]
        out += [ffmt.format(*x) for x in flines]
        out += ["", *(f"note: {n}" for n in self.notes)]
        out.append(f"{self.n_samples} control periods, identified in {self.elapsed:.1f} s.")
        return "\n".join(out)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (parameters, steering lag, table, fit statistics)."""
        return {
            "model_params": self.params.to_dict(),
            "steer_tau": self.steer_tau,
            "rows": self.rows,
            "fits": {k: dict(vars(v)) for k, v in self.fits.items()},
            "notes": list(self.notes),
            "n_samples": self.n_samples,
        }


def identify(
    logs: Sequence[DriveLog],
    known: ModelParams | None = None,
    truth: Any = None,
    derivative: Derivative = "interval",
    fit_steer_lag: bool = True,
) -> IdentificationResult:
    """Identify the planning model's parameters from driving logs.

    Parameters
    ----------
    logs : sequence of DriveLog
        Logs of the manoeuvres in :data:`MANOEUVRES` (see :func:`collect_logs`).
    known : ModelParams, optional
        Supplies the values taken as known: ``m, l_f, l_r, h_c, l_t, mu, g`` (default: the paper's
        table, ``ModelParams()``).
    truth : VehicleParams or ModelParams, optional
        The true car, only for the report's "true" column.
    derivative : {"interval", "savgol"}
        How derivatives are taken (see the module docstring).
    fit_steer_lag : bool
        Identify a first-order steering-actuator lag with the lateral parameters (recommended:
        otherwise the lag is mistaken for yaw inertia).

    Returns
    -------
    IdentificationResult

    Raises
    ------
    ModelError
        Logs too short, or lacking the excitation some parameter needs (the message names the
        parameter and the manoeuvre to add).
    """
    t0 = time.perf_counter()
    kp = ModelParams() if known is None else known
    if not isinstance(kp, ModelParams):
        raise ModelError(f"known must be a ModelParams; got {type(kp).__name__}.")
    logs = list(logs)
    bad = [type(x).__name__ for x in logs if not isinstance(x, DriveLog)]
    if bad:
        raise ModelError(f"identify() takes DriveLog objects; got {sorted(set(bad))}.")
    S = _samples(logs, derivative)
    if S.vx.size < 10 * _MIN_SAMPLES:
        raise ModelError(
            f"the logs are too short: {S.vx.size} control periods ({S.vx.size * 0.1:.0f} s) in "
            f"logs of >= 8 periods, need >= {10 * _MIN_SAMPLES}. Record the manoeuvres "
            f"{sorted(MANOEUVRES)} (racing_lib.sysid.collect_logs())."
        )
    tyres, fits = _fit_lateral(kp, S, fit_steer_lag)
    fyf_sin = _front_force_sin(kp, S, tyres)
    resist, f2 = _fit_coast_down(kp, S, fyf_sin)
    notes = [str(resist.pop("note"))]
    fits |= f2
    fitted = kp.replace(**{k: v for k, v in tyres.items() if k != "steer_tau"}, **resist)
    pedal, f3 = _fit_pedal(fitted, S, fyf_sin)
    fits |= f3
    a_brk_max, brake_note = _fit_brake_limit(fitted, S, fyf_sin)
    notes.append(brake_note)
    pedal = dataclasses.replace(pedal, a_brk_max=a_brk_max)
    fitted = fitted.replace(pedal=pedal)

    tp, tau_true = _truth_params(truth)
    lat, yaw = fits["lateral balance (all data)"], fits["yaw balance (all data)"]
    spec = [
        ("C_xw", "kg/m", "coast-down"),
        ("c_rr", "-", "coast-down"),
        ("B_f", "1/rad", "circles+steps"),
        ("C_f", "-", "circles+steps"),
        ("D_f", "-", "circles+steps"),
        ("B_r", "1/rad", "circles+steps"),
        ("C_r", "-", "circles+steps"),
        ("D_r", "-", "circles+steps"),
        ("mu*D_f", "-", "circles+steps"),
        ("mu*D_r", "-", "circles+steps"),
        ("C_alpha_f", "N/rad", "circles+steps"),
        ("C_alpha_r", "N/rad", "circles+steps"),
        ("I_zz", "kg m^2", "steps"),
        ("steer_tau", "s", "steps"),
        ("pedal m_0", "m/s^2", "laps+steps"),
        ("pedal m_vx", "1/s", "laps+steps"),
        ("pedal m_thr", "m/s^2", "laps+steps"),
        ("pedal m_brk", "m/s^2", "laps+steps"),
        ("pedal p_thr", "W/kg", "laps+steps"),
        ("pedal a_brk_max", "m/s^2", "braking"),
    ]
    fd = _derived(fitted)
    td = _derived(tp) if tp is not None else {}
    pedal_vals = {
        "pedal m_0": pedal.m_0,
        "pedal m_vx": pedal.m_xi[X.VX],
        "pedal m_thr": pedal.m_thr,
        "pedal m_brk": pedal.m_brk,
        "pedal p_thr": pedal.p_thr if pedal.p_thr is not None else float("nan"),
        "pedal a_brk_max": pedal.a_brk_max if pedal.a_brk_max is not None else float("nan"),
    }
    fit_of = {
        "coast-down": f"RMS {fits['coast-down'].rms:.3g} m/s^2",
        "circles+steps": f"RMS lat {lat.rms:.3g} m/s^2",
        "steps": f"RMS yaw {yaw.rms:.3g} rad/s^2",
        "laps+steps": f"held-out R^2 {fits['pedal map (held out)'].r2:.3f}",
        "braking": "median of the full stops",
    }
    rows = []
    for name, unit, man in spec:
        if name in fd:
            val, true = fd[name], td.get(name)
        elif name == "steer_tau":
            val, true = tyres["steer_tau"], tau_true
        elif name == "pedal p_thr":
            # The one pedal-map number with a true value: engine power at the wheels per kg.
            val = pedal_vals[name]
            true = (
                truth.power_max * truth.driveline_efficiency / truth.m
                if hasattr(truth, "power_max")
                else None
            )
        elif name in pedal_vals:
            val, true = pedal_vals[name], None  # the powertrain is nonlinear: no true map
        else:
            val = getattr(fitted, name)
            true = getattr(tp, name) if tp is not None else None
        err = 100.0 * (val / true - 1.0) if true else None
        rows.append(
            {
                "name": name,
                "unit": unit,
                "fitted": float(val),
                "true": None if true is None else float(true),
                "error_pct": err,
                "fit": fit_of[man],
                "manoeuvre": man,
            }
        )
    return IdentificationResult(
        params=fitted,
        steer_tau=tyres["steer_tau"],
        fits=fits,
        rows=rows,
        notes=tuple(notes),
        n_samples=int(S.vx.size),
        elapsed=time.perf_counter() - t0,
    )


def run(seed: int = 0, fast: bool | None = None, out: str | None = None) -> IdentificationResult:
    """Collect logs with the built-in car, identify, and write the JSON parameter file.

    Parameters
    ----------
    seed : int
        Seed of the data collection (the shipped file uses 0; tests use other seeds).
    fast : bool, optional
        Less data (default: :func:`racing_lib.config.fast_mode`).
    out : str, optional
        Output path (default: the package's ``data/identified_params.json``); ``""`` writes nothing.
    """
    from racing_lib.vehicle import VehicleParams

    t0 = time.perf_counter()
    logs = collect_logs(seed=seed, fast=fast)
    t_collect = time.perf_counter() - t0
    result = identify(logs, truth=VehicleParams())
    if out != "":
        target = FsPath(out) if out else FsPath(__file__).parent / "data" / DATA_FILE
        payload = result.to_dict() | {
            "seed": seed,
            "fast": fast_mode() if fast is None else fast,
            "collect_time_s": round(t_collect, 2),
            "fit_time_s": round(result.elapsed, 2),
            "generated_by": "python -m racing_lib.sysid",
            # The car the data came from: a changed VehicleParams means this file is stale.
            "vehicle_params": dataclasses.asdict(VehicleParams()),
        }
        atomic_write_json(target, payload)
    return result


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m racing_lib.sysid [--seed S] [--fast] [--out FILE]``: regenerate the JSON file."""
    ap = argparse.ArgumentParser(prog="python -m racing_lib.sysid", description=main.__doc__)
    ap.add_argument("--seed", type=int, default=0, help="data-collection seed (default 0)")
    ap.add_argument("--fast", action="store_true", help="collect less data")
    ap.add_argument("--out", default=None, help="output JSON (default: the package's data file)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    result = run(seed=args.seed, fast=True if args.fast else None, out=args.out)
    print(result.report())
    print(f"total (collection + fit): {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
