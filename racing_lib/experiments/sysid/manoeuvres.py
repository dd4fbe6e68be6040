"""The manoeuvres that identification drives, on any plant, and the logs they record."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from racing_lib.control.nominal import NominalController, NominalSettings
from racing_lib.errors import ArgumentError, ModelError, PlantError
from racing_lib.experiments.sysid.watch import ManoeuvreSettings, _Watchdog
from racing_lib.geometry import FrenetTracker, Path, Track
from racing_lib.interfaces import Plant
from racing_lib.model.drive import Drive
from racing_lib.planning.speed import speed_profile
from racing_lib.sim import SimulatedCar
from racing_lib.tracks import load_track
from racing_lib.vehicle import VehicleParams

__all__ = [
    "MANOEUVRES",
    "CarUnderTest",
    "braking_logs",
    "coast_down_log",
    "circle_logs",
    "lap_logs",
    "simulated_car",
    "step_logs",
]

#: The manoeuvres :func:`collect_logs` drives, and what each one identifies.
MANOEUVRES: dict[str, str] = {
    "laps": "nominal-controller laps of the built-in tracks at a few speed scalings (pedal map)",
    "coast-down": "pedal 0 from high speed on a long, nearly straight road (C_xw, c_rr)",
    "circles": "steady-state constant-radius circles at rising speed (Pacejka B, C, D)",
    "steps": "steps of steering and pedal around a large circle (I_zz, steering lag, pedal map)",
    "braking": "full brake from several speeds on a long, nearly straight road (braking limit)",
    "steering-rate": "large steering steps at low speed (the steering actuator's rate limit)",
    "full-throttle": "full throttle until the speed stops rising (power limit, top speed)",
    "braking-stability": "braking from speed with the steering held (does a small yaw grow?)",
}


def _record(
    plant: Any,
    obs: Any,
    policy: Callable[[Any, int], tuple[float, float]],
    n_steps: int,
    name: str,
    kind: str,
    grade: Callable[[float, float], float] | None = None,
    stop: Callable[[Any], bool] | None = None,
) -> Drive:
    """Drive ``plant`` from observation ``obs`` with ``policy(obs, k) -> (steer, pedal)``.

    The drive ends after ``n_steps`` periods (or when ``stop`` says so): ``n_steps + 1``
    observations at most, each followed by the command the policy sent after it (the last one's
    is sent too, but its outcome is not recorded), as in a lap's
    :class:`~racing_lib.model.drive.Drive`.
    """
    rows = [obs]
    cmds: list[tuple[float, float]] = []
    for k in range(n_steps):
        steer, pedal = policy(obs, k)
        steer, pedal = float(steer), float(min(max(pedal, -1.0), 1.0))
        obs = _checked_step(plant, steer, pedal, name, kind)
        cmds.append((steer, pedal))
        rows.append(obs)
        if stop is not None and stop(obs):
            break
    steer, pedal = policy(obs, len(cmds))
    steer, pedal = float(steer), float(min(max(pedal, -1.0), 1.0))
    _checked_step(plant, steer, pedal, name, kind)
    cmds.append((steer, pedal))
    arr = {key: np.array([getattr(o, key) for o in rows]) for key in ("t", "x", "y", "psi")}
    for key in ("vx", "vy", "r"):
        arr[key] = np.array([getattr(o, key) for o in rows])
    theta = np.array([grade(o.x, o.y) for o in rows]) if grade is not None else np.zeros(len(rows))
    c = np.array(cmds, dtype=float).reshape(-1, 2)
    return Drive(steer=c[:, 0], pedal=c[:, 1], theta=theta, name=name, kind=kind, **arr)


#: What to try when a manoeuvre loses the car, by manoeuvre.
_REMEDY = {
    "circles": "smaller speeds (ManoeuvreSettings.yaw_limit / slip_limit lower, so the watchdog "
    "backs off earlier) or larger circles (circle_logs(radii=...))",
    "steps": "smaller steering steps or a lower base speed (step_logs(speeds=...))",
    "braking": "a gentler back-off (ManoeuvreSettings.backoff lower) or lower speeds "
    "(braking_logs(speeds=...))",
    "coast-down": "a lower top speed (coast_down_log(v_high=...))",
    "laps": "a smaller share of the speed profile (lap_logs(scalings=...))",
    "steering-rate": "a lower speed or smaller steps (ManoeuvreSettings.steer_rate_speed, "
    "steer_rate_ay)",
    "full-throttle": "a shorter run (ManoeuvreSettings.full_throttle_time)",
    "braking-stability": "a lower speed (braking_stability_log(v_test=...)) or a tighter yaw "
    "band (ManoeuvreSettings.yaw_limit)",
}


class LostCar(PlantError):
    """A manoeuvre lost the car (it spun or left the road): the plant itself still works."""


def _checked_step(plant: Any, steer: float, pedal: float, name: str, kind: str) -> Any:
    """``plant.step(steer, pedal)``, with a failure or a non-finite observation named.

    Raises
    ------
    PlantError
        The plant raised one, or returned NaN or infinite values, during manoeuvre ``kind``.
    """
    try:
        obs = plant.step(steer, pedal)
    except PlantError as exc:
        raise LostCar(
            f"the '{kind}' manoeuvre ({name}) lost the car: {exc} Try "
            f"{_REMEDY.get(kind, 'a gentler manoeuvre')}."
        ) from exc
    values = [getattr(obs, k) for k in ("t", "x", "y", "psi", "vx", "vy", "r")]
    if not all(math.isfinite(float(v)) for v in values):
        raise PlantError(
            f"the '{kind}' manoeuvre ({name}): the plant returned a non-finite observation "
            f"(t, x, y, psi, vx, vy, r = {values}) after steer {steer:.4g} rad, pedal "
            f"{pedal:.3g}. Check the plant (its integrator and state), or try "
            f"{_REMEDY.get(kind, 'a gentler manoeuvre')}."
        )
    return obs


# --------------------------------------------------------------------------------------------------
# The car under test, on any plant
# --------------------------------------------------------------------------------------------------


def _proving_ground(radius: float, width: float, name: str) -> Track:
    """A flat, open circular test area of the given centre-line radius and total width (m)."""
    n = max(int(2.0 * math.pi * radius / 5.0), 64)
    a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return Track(
        Path(radius * np.cos(a), radius * np.sin(a)),
        width / 2.0,
        width / 2.0,
        boundary="open",
        name=name,
    )


@dataclass(frozen=True)
class CarUnderTest:
    """A car to identify: how to put it on a test track, and what its data sheet says.

    Identification needs nothing else of a car, so any :class:`~racing_lib.interfaces.Plant` can
    be identified: the simulated car (:func:`simulated_car`), another simulator, or a wrapper
    around a real car.

    Attributes
    ----------
    make_plant : callable ``(track, start_speed) -> Plant``
        The car at the start of ``track`` (arc length 0, on the centre line, heading along it) at
        ``start_speed`` m/s. Each manoeuvre calls ``reset(seed)`` on it and drives it at its own
        control period ``dt`` (s).
    known : VehicleParams or ModelParams
        What is known before any test: the friction coefficient ``mu`` (-), gravity ``g``
        (m/s^2), the axle distances ``l_f``, ``l_r`` (m) and what the quasi-steady speed profile
        needs (:func:`racing_lib.planning.speed.speed_profile`). They size the manoeuvres (target
        lateral accelerations, steering amplitudes, lap speeds); the fits never read them.
    """

    make_plant: Callable[[Any, float], Plant]
    known: Any


class _SimulatedCarAt:
    """``make_plant`` of the simulated car: a picklable callable, not a closure."""

    def __init__(self, params: VehicleParams) -> None:
        self.params = params

    def __str__(self) -> str:
        return "the simulated car"

    def __call__(self, track: Track, start_speed: float) -> Plant:
        return SimulatedCar(track, self.params, dt=0.1, start_s=0.0, start_speed=start_speed)


def simulated_car(params: VehicleParams | None = None) -> CarUnderTest:
    """The simulated car as a :class:`CarUnderTest`; its true parameters are its data sheet.

    Parameters
    ----------
    params : VehicleParams, optional
        The car's true parameters (default: the built-in car).
    """
    vp = VehicleParams() if params is None else params
    return CarUnderTest(make_plant=_SimulatedCarAt(vp), known=vp)


def _as_car(car: CarUnderTest | VehicleParams | None) -> CarUnderTest:
    """The car the manoeuvres drive: a CarUnderTest, or the simulated car with these parameters."""
    if isinstance(car, CarUnderTest):
        return car
    if car is None or isinstance(car, VehicleParams):
        return simulated_car(car)
    raise ModelError(
        f"the car to identify must be a CarUnderTest or the simulated car's VehicleParams, got "
        f"{type(car).__name__}; wrap another plant with CarUnderTest(make_plant, known)."
    )


def _start(car: CarUnderTest, track: Any, start_speed: float, seed: int | None) -> tuple[Any, Any]:
    """The car on ``track`` and its first observation (after a seeded reset)."""
    plant = car.make_plant(track, start_speed)
    return plant, plant.reset(seed=seed)


def _watch(
    car: CarUnderTest | VehicleParams | None,
    settings: ManoeuvreSettings | None,
    kappa: float | None,
    dt: float,
    slow_down: bool = False,
    yaw_extra: float = 0.0,
    watch_yaw: bool = True,
) -> _Watchdog:
    """The watchdog of one run: ``settings`` (default ones), path curvature (1/m), period (s)."""
    known = _as_car(car).known
    return _Watchdog(
        settings or ManoeuvreSettings(),
        kappa,
        dt,
        yaw_extra=yaw_extra,
        wheelbase=float(known.l_f + known.l_r),
        l_r=float(known.l_r),
        watch_yaw=watch_yaw,
        slow_down=slow_down,
    )


def _follower(track: Track) -> NominalController:
    """Pure-pursuit steering along the track's centre line (speed is commanded separately)."""
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
    car: CarUnderTest | VehicleParams | None = None,
    seed: int = 0,
    v_high: float = 42.0,
    v_low: float = 8.0,
    settings: ManoeuvreSettings | None = None,
) -> Drive:
    """Coast-down: full throttle to ``v_high`` (m/s), then pedal 0 until ``v_low`` (m/s).

    A car that cannot reach ``v_high`` coasts from its top speed (the speed full throttle stopped
    raising, :func:`_topped_out`).

    Driven on a 1.5 km radius circle (lateral acceleration below 1.2 m/s^2 at 42 m/s, so the
    steering's share of the deceleration is tiny and is still accounted for). Only the pedal-0
    part is used for drag and rolling resistance; the run-up is pedal-map data. The run-up's
    throttle is watched (:class:`~racing_lib.experiments.sysid.watch.ManoeuvreSettings`): a car
    whose driven wheels spin at full throttle is backed off.

    The car runs without its per-trial actuation noise (``reset(seed=None)``): a foot off the
    pedals is exactly pedal 0, while the simulated car's additive pedal noise would turn "0" into
    random light braking and throttle whose mean (about 0.04 m/s^2, brakes being ~5 times stronger
    per unit pedal than the engine) is as large as the rolling resistance itself. ``seed`` is
    unused and kept for a uniform signature.
    """
    track = _proving_ground(1500.0, 30.0, "coast-down circle")
    plant, obs0 = _start(_as_car(car), track, start_speed=15.0, seed=None)
    ctrl = _follower(track)
    ctrl.reset(obs0)
    phase = {"coast": False}
    watch = _watch(car, settings, 1.0 / 1500.0, plant.dt, slow_down=True)

    coast: list[float] = []  # speeds since the coast began
    run_up: list[float] = []  # speeds of the full-throttle run-up

    def policy(obs: Any, k: int) -> tuple[float, float]:
        run_up.append(float(obs.vx))
        # A car whose top speed is below v_high (CommonRoad's VW van: 41.7 m/s) coasts from
        # its top speed: without this it never coasted at all and left nothing to fit.
        if obs.vx >= min(v_high, watch.v_cap - 0.5) or _topped_out(run_up):
            phase["coast"] = True
        return watch.steer(obs, ctrl.step(obs).steer), watch(obs, 0.0 if phase["coast"] else 1.0)

    return _record(
        plant,
        obs0,
        policy,
        6000,
        f"coast-down {v_high:.0f}->{v_low:.0f} m/s",
        "coast-down",
        stop=lambda o: phase["coast"] and (o.vx < v_low or _coasts_on(o, coast)),
    )


def _topped_out(speeds: list[float], window: int = 20) -> bool:
    """Whether full throttle stopped adding speed: less than 0.1 m/s in ``window`` periods."""
    return len(speeds) > window and speeds[-1] - speeds[-window - 1] < 0.1


def _coasts_on(obs: Any, speeds: list[float], window: int = 200) -> bool:
    """Whether a coasting car kept its speed: it lost less than 0.1 m/s in ``window`` periods.

    ``speeds`` (m/s) collects the coast's speeds. A car without drag nor rolling resistance never
    reaches ``v_low``; 20 s at constant speed tell all there is (the resistances are 0).
    """
    speeds.append(float(obs.vx))
    return len(speeds) > window and speeds[-window - 1] - speeds[-1] < 0.1


def braking_logs(
    car: CarUnderTest | VehicleParams | None = None,
    speeds: Sequence[float] = (45.0, 35.0, 25.0),
    v_low: float = 8.0,
    settings: ManoeuvreSettings | None = None,
) -> list[Drive]:
    """Straight-line stops: full throttle to each of ``speeds`` (m/s), then full brake to ``v_low``.

    A car whose top speed lies below one of ``speeds`` brakes from its top speed.

    On the coast-down's 1.5 km circle, without actuation noise (a full stop is full brake). They
    measure the deceleration the tyres give when the brakes ask for more than the grip, which the
    brake slope of the pedal map, fitted on partial braking, cannot tell.

    A car without anti-lock brakes may lock its wheels at full brake: the watchdog
    (:class:`~racing_lib.experiments.sysid.watch.ManoeuvreSettings`) sees the car rotate off its
    path, releases the brake and brakes on at ``backoff`` times the pedal that locked it: the stop
    then measures the deceleration the car gives short of lock-up.
    """
    track = _proving_ground(1500.0, 30.0, "braking circle")
    logs = []
    for v_high in speeds:
        plant, obs0 = _start(_as_car(car), track, start_speed=15.0, seed=None)
        ctrl = _follower(track)
        ctrl.reset(obs0)
        phase = {"brake": False}
        watch = _watch(car, settings, 1.0 / 1500.0, plant.dt)

        seen: list[float] = []

        def policy(obs: Any, k: int, v_high=v_high, ctrl=ctrl, phase=phase, watch=watch, v=seen):
            v.append(float(obs.vx))
            # At v_high, or at the car's top speed if lower (no gain in the last 2 s).
            if obs.vx >= v_high or _topped_out(v):
                phase["brake"] = True
            steer = watch.steer(obs, ctrl.step(obs).steer)
            return steer, watch(obs, -1.0 if phase["brake"] else 1.0)

        logs.append(
            _record(
                plant,
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
    car: CarUnderTest | VehicleParams | None = None,
    seed: int = 0,
    radii: Sequence[float] = (40.0, 80.0, 150.0),
    levels: int = 8,
    hold: float = 5.0,
    settings: ManoeuvreSettings | None = None,
) -> list[Drive]:
    """Steady-state cornering: constant-radius circles (ISO 4138) at rising speed.

    For each radius R (m) the car follows the circle with pure pursuit at ``levels`` speeds from
    a lateral acceleration of about 0.2 g up to about 0.95 of the friction limit ``mu g``, holding
    each for ``hold`` s, so the steering settles to a constant at every level (a steady state with
    ``r_dot ~ 0``).

    The rise is a limit-seeking ramp: the watchdog
    (:class:`~racing_lib.experiments.sysid.watch.ManoeuvreSettings`) lifts the throttle when the
    car leaves the circle's steady state (power oversteer, or tyres weaker than the data sheet's
    ``mu``), then caps and slows the throttle; after ``max_trips`` trips the speed stops rising and
    holds the last level below the one that lost grip.
    """
    spec = _as_car(car)
    vp = spec.known
    mu, g = float(vp.mu), float(vp.g)
    logs = []
    for i, radius in enumerate(radii):
        track = _proving_ground(radius, 40.0, f"circle R={radius:.0f} m")
        speeds = np.sqrt(np.linspace(0.2, 0.95, levels) * mu * g * radius)
        plant, obs0 = _start(spec, track, start_speed=float(speeds[0]), seed=seed + 101 * i)
        ctrl = _follower(track)
        ctrl.reset(obs0)
        hold_steps = int(round(hold / plant.dt))
        pi = _SpeedHold(dt=plant.dt)
        watch = _watch(spec, settings, 1.0 / radius, plant.dt)
        ceiling = [len(speeds) - 1]

        def policy(
            obs: Any, k: int, speeds=speeds, ctrl=ctrl, pi=pi, h=hold_steps, w=watch, c=ceiling
        ):
            level = min(k // h, c[0])
            if len(w.events) >= w.settings.max_trips and c[0] == len(speeds) - 1:
                c[0] = level = max(level - 1, 0)  # the limit: hold the level below it
            v_target = float(speeds[level])
            return w.steer(obs, ctrl.step(obs).steer), w(obs, pi(v_target, obs.vx))

        logs.append(
            _record(plant, obs0, policy, hold_steps * levels, f"circle R={radius:.0f} m", "circles")
        )
    return logs


def step_logs(
    car: CarUnderTest | VehicleParams | None = None,
    seed: int = 0,
    speeds: Sequence[float] = (15.0, 25.0, 35.0),
    duration: float = 40.0,
    settings: ManoeuvreSettings | None = None,
) -> list[Drive]:
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
    spins it; the speed hold of the steering phases brakes no harder either (a car faster off
    the line than the simulated one ends a pedal phase well above the base speed, and a full
    brake would lock the rear wheels of a car without anti-lock brakes). ``seed`` fixes the
    random sequences. The pedal is watched for side slip
    (:class:`~racing_lib.experiments.sysid.watch.ManoeuvreSettings`) and for a yaw rate off the
    circle's by more than the steering steps explain.
    """
    spec = _as_car(car)
    vp = spec.known
    L = float(vp.l_f + vp.l_r)
    mu, g = float(vp.mu), float(vp.g)
    logs = []
    for i, v0 in enumerate(speeds):
        rng = np.random.default_rng(seed + 1000 + i)
        track = _proving_ground(300.0, 60.0, f"steps {v0:.0f} m/s")
        plant, obs0 = _start(spec, track, start_speed=float(v0), seed=seed + 2000 + i)
        ctrl = _follower(track)
        ctrl.reset(obs0)
        n = int(round(duration / plant.dt))
        # A swing of 2 amp stays inside the actuator's linear band (steer_rate_max * steer_tau).
        amp = min(0.35 * mu * g * L / v0**2, 0.04)
        # n + 1 entries: the drive's last observation is followed by a command too.
        steer_off = np.zeros(n + 1)
        pedal_lvl = np.zeros(n + 1)
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
        pi = _SpeedHold(dt=plant.dt)
        sign = [1.0]
        # The yaw rate is watched in a band widened by the steps' own kinematic yaw rate at the
        # top of the speed band.
        watch = _watch(spec, settings, 1.0 / 300.0, plant.dt, True, 1.3 * v0 * amp / L)

        def policy(
            obs: Any,
            k: int,
            ctrl=ctrl,
            so=steer_off,
            pl=pedal_lvl,
            v0=v0,
            pi=pi,
            sign=sign,
            w=watch,
        ):
            steer, pedal = _step_command(obs, k, ctrl, so, pl, v0, pi, sign)
            return w.steer(obs, steer), w(obs, pedal)

        logs.append(_record(plant, obs0, policy, n, f"steps at {v0:.0f} m/s", "steps"))
    return logs


def _step_command(
    obs: Any, k: int, ctrl: Any, so: Any, pl: Any, v0: float, pi: Any, sign: list
) -> tuple[float, float]:
    """The steps manoeuvre's command at period ``k`` (see :func:`step_logs`), rad and -."""
    phase = 100  # control periods per phase (10 s)
    steer = ctrl.step(obs).steer
    if abs(obs.vy) > 0.08 * max(obs.vx, 1.0):
        return steer, 0.0  # a slide: recover with pure pursuit alone, no pedal
    if (k // phase) % 2 == 0:  # steering phase: the speed hold brakes no harder than the steps
        return steer + so[k], max(pi(v0, obs.vx), -0.5)
    # Pedal phase: a random walk in speed, reversed at the edges of the band.
    if obs.vx < 0.7 * v0:
        sign[0] = 1.0
    elif obs.vx > 1.3 * v0:
        sign[0] = -1.0
    elif k % 30 == 0:
        sign[0] = -sign[0]
    return steer, sign[0] * pl[k] * (1.0 if sign[0] > 0.0 else 0.5)


def _lap_log(
    spec: CarUnderTest,
    seed: int,
    track: Track,
    prof: Any,
    scale: float,
    max_time: float,
    settings: ManoeuvreSettings,
) -> Drive:
    """One nominal-controller lap of ``track`` at ``scale`` of its speed profile ``prof``."""
    name = track.name
    plant, obs0 = _start(spec, track, start_speed=float(scale * prof(0.0)), seed=seed)
    ctrl = NominalController(
        track.centerline,
        lambda si, prof=prof: float(prof(si)),
        NominalSettings(speed_scale=scale),
    )
    ctrl.reset(obs0)
    tracker = FrenetTracker(track.centerline)

    def grade(x: float, y: float) -> float:
        return float(track.grade(tracker.project(x, y)[0]))

    # The yaw rate is not judged (pure pursuit cuts the corners and scrapes the walls);
    # the path's curvature sets the body-slip band and the yaw damper.
    watch = _watch(spec, settings, 0.0, plant.dt, True, watch_yaw=False)
    follow = FrenetTracker(track.centerline)

    def policy(obs: Any, k: int) -> tuple[float, float]:
        cmd = ctrl.step(obs)
        watch.kappa = float(track.centerline.curvature(follow.project(obs.x, obs.y)[0]))
        return watch.steer(obs, cmd.steer), watch(obs, cmd.pedal)

    n = int(round(min(max_time, 1.05 * prof.lap_time / scale) / plant.dt))
    return _record(plant, obs0, policy, n, f"lap {name} x{scale:.2f}", "laps", grade=grade)


def lap_logs(
    car: CarUnderTest | VehicleParams | None = None,
    seed: int = 0,
    tracks: Sequence[str] = ("expressway", "shortcut"),
    scalings: Sequence[float] = (0.6, 0.8),
    max_time: float = 200.0,
    settings: ManoeuvreSettings | None = None,
    min_scaling: float = 0.4,
) -> list[Drive]:
    """Nominal-controller laps of the built-in tracks at fractions of the track's speed profile.

    As in the paper, a simple nominal controller (pure pursuit + speed PI) drives the car along
    the centre line; ``scalings`` are fractions of the quasi-steady-state speed profile of
    :func:`racing_lib.planning.speed.speed_profile`, m/s. The pedal is watched for side slip
    beyond the kinematic slip of the centre line's curvature
    (:class:`~racing_lib.experiments.sysid.watch.ManoeuvreSettings`).

    The profile comes from the data sheet, which knows nothing of the car's handling: a lap that
    loses the car (CommonRoad's Ford Escort spins on the expressway at 0.70 and 0.75, not at 0.65)
    is driven again at ``speed_backoff`` times its share, as a test driver who spun would, down
    to ``min_scaling``; the log's name gives the share it was driven at.

    Raises
    ------
    PlantError
        A lap lost the car at every share down to ``min_scaling``.
    """
    st = settings or ManoeuvreSettings()
    if not (0.0 < st.speed_backoff < 1.0 and min_scaling > 0.0):
        raise ArgumentError(
            f"lap_logs backs a lost lap off by ManoeuvreSettings.speed_backoff (in (0, 1), got "
            f"{st.speed_backoff!r}) down to min_scaling (> 0, got {min_scaling!r}); pass such "
            "values, or the retries would never end."
        )
    spec = _as_car(car)
    logs = []
    for i, name in enumerate(tracks):
        track = load_track(name)
        s = track.centerline.sample(ds=2.0)
        known = spec.known
        prof = speed_profile(s, track.centerline.curvature(s), params=known, length=track.length)
        for j, scale in enumerate(scalings):
            while True:
                try:
                    lap = _lap_log(spec, seed + 10 * i + j, track, prof, scale, max_time, st)
                    logs.append(lap)
                    break
                except LostCar:
                    scale *= st.speed_backoff
                    if scale < min_scaling:
                        raise
    return logs
