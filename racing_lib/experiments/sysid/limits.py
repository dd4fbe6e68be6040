"""The manoeuvres that find the actuators' limits, and :func:`collect_logs`, which drives them all.

Two runs a team does with a car it has never driven, beside those of
:mod:`racing_lib.experiments.sysid.manoeuvres`:

* **steering-rate**: at a low speed (the tyres stay nearly linear), large steering steps held
  open loop: a rate-limited actuator turns them into ramps, which the lateral acceleration
  shows (:func:`steering_rate_log`);
* **full-throttle**: from a moderate speed, full throttle until the speed stops rising or the time
  is up: the acceleration against speed gives the power per mass and where the car stops
  accelerating, its top speed (:func:`full_throttle_log`).

Neither feeds the fits of the planning model's tyres, drag or pedal map, so adding them left the
simulated car's identification exactly as it was; they identify ``steer_rate_max``, the top speed,
and the power limit when the pedal map's own data cannot tell one.
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

__all__ = ["collect_logs", "full_throttle_log", "steering_rate_log"]


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
        return len(seen) > 20 and seen[-1] - seen[-21] < 0.1

    n = int(round(st.full_throttle_time / plant.dt))
    return _record(
        plant, obs0, policy, n, f"full throttle from {v_start:.0f} m/s", "full-throttle", stop=stop
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
    else:
        logs.append(coast_down_log(test_car, seed, settings=st))
        logs += circle_logs(test_car, seed, settings=st)
        logs += step_logs(test_car, seed, settings=st)
        logs += lap_logs(test_car, seed, settings=st)
        logs += braking_logs(test_car, settings=st)
        logs.append(steering_rate_log(test_car, st))
        logs.append(full_throttle_log(test_car, st))
    return logs
