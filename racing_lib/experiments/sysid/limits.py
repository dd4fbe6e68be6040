"""The manoeuvres that find the actuators' limits, and :func:`collect_logs`, which drives them all.

Three runs a team does with a car it has never driven, beside those of
:mod:`racing_lib.experiments.sysid.manoeuvres`:

* **steering-rate**: at a low speed (the tyres stay nearly linear), large steering steps held
  open loop: a rate-limited actuator turns them into ramps, which the lateral acceleration
  shows (:func:`steering_rate_log`);
* **full-throttle**: from a moderate speed, full throttle until the speed stops rising or the time
  is up: the acceleration against speed gives the power per mass and where the car stops
  accelerating, its top speed (:func:`full_throttle_log`).

* **braking-stability**: braking from speed with the steering held: whether a small yaw dies
  out or grows by itself (:func:`braking_stability_log`).

None feeds the fits of the planning model's tyres, drag or pedal map, so adding them left the
simulated car's identification exactly as it was; they identify ``steer_rate_max``, the top speed,
the power limit (which also caps the pedal map's, when that promises more), and whether plans need a
stability margin.
"""

from __future__ import annotations

from typing import Any

from racing_lib.config import fast_mode
from racing_lib.experiments.sysid.manoeuvres import (
    CarUnderTest,
    _as_car,
    _follower,
    _proving_ground,
    _record,
    _SpeedHold,
    _start,
    _topped_out,
    _watch,
    braking_logs,
    circle_logs,
    coast_down_log,
    lap_logs,
    simulated_car,
    step_logs,
)
from racing_lib.experiments.sysid.watch import ManoeuvreSettings
from racing_lib.model.drive import Drive
from racing_lib.vehicle import VehicleParams

__all__ = ["braking_stability_log", "collect_logs", "full_throttle_log", "steering_rate_log"]


def steering_rate_log(
    car: CarUnderTest | VehicleParams | None = None,
    settings: ManoeuvreSettings | None = None,
    n_steps: int = 8,
    hold: float = 1.5,
) -> Drive:
    """Steering steps of +-``amp`` (rad), each held ``hold`` s, at ``settings.steer_rate_speed``.

    On the 1.5 km proving ground (open edges), the steering is commanded open loop: a square
    wave about the circle's own steer, so the car weaves along the circle. The amplitude asks for
    ``steer_rate_ay`` of the data sheet's ``mu g`` at the speed, kinematically
    (``amp = steer_rate_ay mu g L / v^2``, at most 0.8 of the data sheet's ``steer_max`` when it
    gives one): a swing of ``2 amp`` that a rate-limited actuator ramps through at its rate. A PI
    loop holds the speed, watched like the other manoeuvres.

    Parameters
    ----------
    car : CarUnderTest or VehicleParams, optional
        The car (default: the simulated car).
    settings : ManoeuvreSettings, optional
        Speed (m/s) and step size (share of ``mu g``); the watchdog's bands.
    n_steps : int
        Number of steps.
    hold : float
        Time each step is held, s.
    """
    st = ManoeuvreSettings() if settings is None else settings
    spec = _as_car(car)
    vp = spec.known
    L = float(vp.l_f + vp.l_r)
    v0 = float(st.steer_rate_speed)
    amp = st.steer_rate_ay * float(vp.mu) * float(vp.g) * L / v0**2
    steer_max = getattr(vp, "steer_max", None)
    if steer_max is not None:
        amp = min(amp, 0.8 * float(steer_max))
    radius = 1500.0
    track = _proving_ground(radius, 30.0, "steering-rate pad")
    plant, obs0 = _start(spec, track, start_speed=v0, seed=None)
    watch = _watch(spec, st, None, plant.dt)
    pi = _SpeedHold(dt=plant.dt)
    per = max(int(round(hold / plant.dt)), 2)
    base = L / radius  # the circle's kinematic steer

    def policy(obs: Any, k: int) -> tuple[float, float]:
        step = k // per
        steer = base if step == 0 else base + (amp if step % 2 else -amp)
        return steer, watch(obs, pi(v0, obs.vx))

    return _record(
        plant,
        obs0,
        policy,
        per * (n_steps + 1),
        f"steering steps +-{amp:.3f} rad at {v0:.0f} m/s",
        "steering-rate",
    )


def full_throttle_log(
    car: CarUnderTest | VehicleParams | None = None,
    settings: ManoeuvreSettings | None = None,
    v_start: float = 15.0,
    ramp: float = 2.0,
) -> Drive:
    """Full throttle from ``v_start`` (m/s) until the speed stops rising, or the time is up.

    On the 1.5 km proving ground with pure pursuit. The throttle rises from 0 to 1 in ``ramp`` s
    (a foot that a driver can lift before the driven wheels spin up), then stays. The run ends
    when the speed gained less than 0.1 m/s in the last 2 s (the car's top speed) or after
    ``settings.full_throttle_time`` s. The throttle is watched: a car whose driven wheels spin is
    backed off
    (:class:`~racing_lib.experiments.sysid.watch.ManoeuvreSettings`).
    """
    st = ManoeuvreSettings() if settings is None else settings
    spec = _as_car(car)
    track = _proving_ground(1500.0, 30.0, "full-throttle circle")
    plant, obs0 = _start(spec, track, start_speed=v_start, seed=None)
    ctrl = _follower(track)
    ctrl.reset(obs0)
    watch = _watch(spec, st, 1.0 / 1500.0, plant.dt)
    seen: list[float] = []

    def policy(obs: Any, k: int) -> tuple[float, float]:
        throttle = min(1.0, k * plant.dt / ramp) if ramp > 0.0 else 1.0
        return watch.steer(obs, ctrl.step(obs).steer), watch(obs, throttle)

    def stop(obs: Any) -> bool:
        seen.append(float(obs.vx))
        return _topped_out(seen)

    n = int(round(st.full_throttle_time / plant.dt))
    return _record(
        plant, obs0, policy, n, f"full throttle from {v_start:.0f} m/s", "full-throttle", stop=stop
    )


def braking_stability_log(
    car: CarUnderTest | VehicleParams | None = None,
    settings: ManoeuvreSettings | None = None,
    v_test: float = 45.0,
    ramp: float = 4.0,
    kick: float = 0.03,
) -> Drive:
    """Braking with the steering held, to see whether a small yaw dies out or grows by itself.

    A car with the same tyres front and rear and a high centre of gravity unloads its rear axle
    under braking until it oversteers: any small yaw then grows by itself (CommonRoad's BMW 320i
    at 45 m/s and 3.5 m/s^2, its yaw rate doubling every 0.4 s). The plans must know, since they
    brake into corners; the tracking controller cannot always catch such a car in time.

    On the 1.5 km proving ground, full throttle from 15 m/s to ``v_test`` (m/s, or the car's top
    speed if lower) with pure pursuit; then the steering is held where the follower left it,
    with a short kick that gives a yaw rate of ``kick`` rad/s kinematically, and the brake pedal
    ramps from 0 to ``-settings.min_brake`` in ``ramp`` s. A stable car lets the kick die out; an
    unstable one turns it into a growing yaw rate until the watchdog's yaw band trips, which
    releases the brake and gives the steering back to the follower (with its yaw damper). The
    run ends at 15 m/s, or 3 s after a trip.
    """
    st = ManoeuvreSettings() if settings is None else settings
    spec = _as_car(car)
    wheelbase = float(spec.known.l_f + spec.known.l_r)
    track = _proving_ground(1500.0, 30.0, "braking-stability circle")
    plant, obs0 = _start(spec, track, start_speed=15.0, seed=None)
    ctrl = _follower(track)
    ctrl.reset(obs0)
    watch = _watch(spec, st, 1.0 / 1500.0, plant.dt)
    seen: list[float] = []
    # "trips": the watchdog's trips before the brake (a run-up that spun the wheels); only a
    # trip after it ends the braking.
    brake = {"from": -1, "steer": 0.0, "pulse": 0.0, "trip": -1, "trips": 0}
    n_kick = max(int(round(0.2 / plant.dt)), 1)

    def policy(obs: Any, k: int) -> tuple[float, float]:
        seen.append(float(obs.vx))
        follow = watch.steer(obs, ctrl.step(obs).steer)
        if brake["from"] < 0 and (obs.vx >= v_test or _topped_out(seen)):
            brake["from"], brake["steer"], brake["trips"] = k, follow, len(watch.events)
            brake["pulse"] = kick * wheelbase / max(float(obs.vx), 5.0)
        if brake["from"] < 0:
            return follow, watch(obs, 1.0)
        if len(watch.events) > brake["trips"]:
            if brake["trip"] < 0:
                brake["trip"] = k
            return follow, watch(obs, 0.0)
        age = k - brake["from"]
        steer = brake["steer"] + (brake["pulse"] if age < n_kick else 0.0)
        pedal = -st.min_brake * min(1.0, age * plant.dt / ramp)
        return steer, watch(obs, pedal)

    def stop(obs: Any) -> bool:
        if brake["trip"] >= 0:
            return (len(seen) - brake["trip"]) * plant.dt > 3.0
        return brake["from"] >= 0 and obs.vx < 15.0

    return _record(
        plant,
        obs0,
        policy,
        int(round(3.0 * st.full_throttle_time / plant.dt)),
        f"braking with the steering held from {v_test:.0f} m/s",
        "braking-stability",
        stop=stop,
    )


def collect_logs(
    seed: int = 0,
    params: VehicleParams | None = None,
    fast: bool | None = None,
    car: CarUnderTest | None = None,
    settings: ManoeuvreSettings | None = None,
) -> list[Drive]:
    """Drive every manoeuvre of :data:`MANOEUVRES` with a car and return the logs.

    Parameters
    ----------
    seed : int
        Seeds the car's per-trial randomness and the random step sequences; a different seed gives
        fresh data.
    params : VehicleParams, optional
        The simulated car to drive (default: the built-in car); ignored when ``car`` is given.
    fast : bool, optional
        Collect less data (shorter laps, fewer levels); default :func:`racing_lib.config.fast_mode`.
    car : CarUnderTest, optional
        Any other plant to identify, with what is known of it beforehand.
    settings : ManoeuvreSettings, optional
        How the manoeuvres watch for and back off from the car's limits (default
        ``ManoeuvreSettings()``).

    Returns
    -------
    list of Drive
    """
    fast = fast_mode() if fast is None else fast
    test_car = car if car is not None else simulated_car(params)
    st = ManoeuvreSettings() if settings is None else settings
    logs: list[Drive] = []
    if fast:
        logs.append(coast_down_log(test_car, seed, v_high=38.0, v_low=12.0, settings=st))
        logs += circle_logs(test_car, seed, radii=(50.0, 120.0), levels=6, hold=4.0, settings=st)
        logs += step_logs(test_car, seed, speeds=(18.0, 30.0), duration=30.0, settings=st)
        logs += lap_logs(
            test_car, seed, tracks=("shortcut",), scalings=(0.8,), max_time=60.0, settings=st
        )
        logs += braking_logs(test_car, speeds=(45.0, 35.0), settings=st)
        logs.append(steering_rate_log(test_car, st))
        logs.append(full_throttle_log(test_car, st))
        logs.append(braking_stability_log(test_car, st))
    else:
        logs.append(coast_down_log(test_car, seed, settings=st))
        logs += circle_logs(test_car, seed, settings=st)
        logs += step_logs(test_car, seed, settings=st)
        logs += lap_logs(test_car, seed, settings=st)
        logs += braking_logs(test_car, settings=st)
        logs.append(steering_rate_log(test_car, st))
        logs.append(full_throttle_log(test_car, st))
        logs.append(braking_stability_log(test_car, st))
    return logs
