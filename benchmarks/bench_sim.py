"""Speed of the simulated car (run: ``python benchmarks/bench_sim.py [TRACK]``).

A lap is first driven once by the nominal controller (pure pursuit + speed PI on a speed profile
limited by 0.8 g lateral and 0.8 g braking), recording its commands. The timed runs replay those
commands with the same seed, which reproduces the lap bit for bit, so the timing covers the
simulator alone (integration, powertrain, Frenet tracking, walls). Prints the median over several
runs of the CPU seconds per 100 s of simulated driving and the real-time factor. TRACK is a
built-in track name or a racetrack-database CSV file (default: the built-in ``expressway``).

Times are order-of-magnitude on a shared machine; no assertion is made on them.
"""

from __future__ import annotations

import math
import statistics
import time

import numpy as np
from _script import argument_parser, run

from racing_lib.geometry import Track
from racing_lib.sim import SimulatedCar
from racing_lib.tracks import load_track

SEED = 7
RUNS = 5


def _speed_profile(track: Track, a_lat: float, a_brake: float, v_max: float) -> tuple:
    """Target speed on a 2 m grid: lateral limit, then a backward pass for braking (periodic)."""
    s = track.centerline.sample(ds=2.0)
    kappa = np.abs(np.asarray(track.centerline.curvature(s)))
    v = np.minimum(np.sqrt(a_lat / np.maximum(kappa, 1e-6)), v_max)
    ds = float(s[1] - s[0])
    for _ in range(2):  # twice around, so braking zones wrap over the start line
        for i in range(len(v) - 1, -1, -1):
            nxt = v[(i + 1) % len(v)]
            v[i] = min(v[i], math.sqrt(nxt * nxt + 2.0 * a_brake * ds))
    return s, v, kappa


def record_commands(car: SimulatedCar, duration: float) -> list[tuple[float, float]]:
    """Drive `duration` seconds and return the commands.

    The driver is the library's nominal controller (pure pursuit + speed PI) on a 0.8 g speed
    profile; if it cannot be imported, a Frenet-feedback law on the simulator's own (s, e_y, e_psi).
    """
    track = car.track
    g = car.params.g
    try:
        from racing_lib.control.nominal import NominalController
    except ImportError:
        NominalController = None  # noqa: N806
    if NominalController is not None:
        s_grid, v_grid, _ = _speed_profile(track, 0.8 * g, 0.8 * g, 60.0)
        ctrl = NominalController(
            track.centerline,
            lambda si: float(np.interp(si, s_grid, v_grid, period=track.length)),
        )
        obs = car.reset(SEED)
        ctrl.reset(obs)
        cmds = []
        for _ in range(int(round(duration / car.dt))):
            cmd = ctrl.step(obs)
            cmds.append((cmd.steer, cmd.pedal))
            obs = car.step(cmd.steer, cmd.pedal)
        return cmds
    s_grid, v_grid, _ = _speed_profile(track, 0.7 * g, 0.6 * g, 60.0)
    ds = float(s_grid[1] - s_grid[0])
    wheelbase = car.params.l_f + car.params.l_r
    car.reset(SEED)
    cmds = []
    obs = None
    for _ in range(int(round(duration / car.dt))):
        info = car.state_info()
        s, e_y, e_psi = info["s"], info["e_y"], info["e_psi"]
        v = obs.vx if obs is not None else car.start_speed
        s_ahead = s + 0.5 * v
        kappa = float(track.centerline.curvature(s_ahead % track.length))
        steer = wheelbase * kappa - 0.05 * e_y - 0.5 * e_psi
        v_target = float(v_grid[int((s_ahead % track.length) / ds) % len(v_grid)])
        pedal = max(-1.0, min(1.0, 0.4 * (v_target - v)))
        cmds.append((steer, pedal))
        obs = car.step(steer, pedal)
    return cmds


def replay(car: SimulatedCar, cmds: list[tuple[float, float]]) -> float:
    """CPU seconds to replay the commands (reset included)."""
    t0 = time.process_time()
    car.reset(SEED)
    for steer, pedal in cmds:
        car.step(steer, pedal)
    return time.process_time() - t0


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("track", nargs="?", default="expressway", help="track name or CSV file")
    track = load_track(parser.parse_args().track)
    car = SimulatedCar(track, start_speed=20.0)
    duration = 100.0
    cmds = record_commands(car, duration)
    info = car.state_info()
    print(
        f"track {track.name}: {duration:.0f} s driven, s = {info['s']:.0f} m, "
        f"wall contacts {car.wall_contacts}, off-track {car.offtrack_time:.1f} s"
    )
    times = [replay(car, cmds) for _ in range(RUNS)]
    per_100 = statistics.median(times) * 100.0 / duration
    print(
        f"sim only: {per_100:.3f} s CPU per 100 s simulated (median of {RUNS}), "
        f"real-time factor {100.0 / per_100:.0f}x"
    )


if __name__ == "__main__":
    run(main)
