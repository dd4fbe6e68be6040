"""Speed of the plants nobody here wrote (run: ``python benchmarks/bench_plants.py [TRACK]``).

CommonRoad's single-track drift model (``racing_lib.plants.commonroad.CommonRoadCar``, the BMW
320i, vehicle 2) is first driven round a flying lap by the coupled MPC on the centerline plan at
80 % of its speed, planned with the BMW's data sheet (``data_sheet``); the lap's commands are
recorded. The timed runs replay those commands (no noise: the same lap each time), so the timing
covers the plant alone (RK4 substeps, the command mapping, Frenet tracking, walls), for each
engine: the CasADi transcription compiled (the default), the same interpreted by CasADi
(``jit=False``), and the package's own ``vehicle_dynamics_std`` in Python (``engine="python"``).
Prints, per engine, the median over several runs of the CPU seconds per 100 s of simulated
driving and the real-time factor at the 0.1 s control period, with the simulated car
(``racing_lib.sim.SimulatedCar``, replaying the same commands) for comparison. TRACK is a
built-in track name or a racetrack-database CSV file (default: the built-in ``shortcut``).

Needs the optional extra: pip install "racing-lib[commonroad]".

Times are order-of-magnitude on a shared machine; no assertion is made on them.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
from _script import argument_parser, run

from racing_lib.control import build_controller
from racing_lib.experiments.lap import run_lap
from racing_lib.model import CarModel
from racing_lib.planning import plan
from racing_lib.sim import SimulatedCar
from racing_lib.tracks import load_track

RUNS = 5
BMW = 2


def record_lap(track, car_class, data_sheet, vehicle_parameters):
    """The BMW's flying lap with the coupled MPC: (start arc length, m; speed, m/s; commands)."""
    p = vehicle_parameters(BMW)
    model = CarModel(
        data_sheet(BMW), steer_tau=0.05, steer_max=p.steering.max, steer_rate_max=p.steering.v_max
    )
    planned = plan(track, "centerline", model)
    traj = planned.trajectory.scale_speed(0.8)
    s0 = traj.path.length - 150.0
    v0 = float(np.interp(s0, traj.s, traj.vx, period=traj.path.length))
    car = car_class(track, BMW, start_s=s0, start_speed=v0)
    controller = build_controller("coupled-mpc", traj, track=track, model=model)
    lap = run_lap(car, controller, traj, track=track, seed=0)
    commands = list(zip(lap.log.steer.tolist(), lap.log.pedal.tolist(), strict=True))
    return s0, v0, commands, lap.metrics


def replay(car, commands) -> float:
    """CPU seconds to replay the commands (reset included)."""
    t0 = time.process_time()
    car.reset()
    for steer, pedal in commands:
        car.step(steer, pedal)
    return time.process_time() - t0


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("track", nargs="?", default="shortcut", help="track name or CSV file")
    track = load_track(parser.parse_args().track)
    from racing_lib.plants.commonroad import CommonRoadCar, data_sheet, vehicle_parameters

    s0, v0, commands, m = record_lap(track, CommonRoadCar, data_sheet, vehicle_parameters)
    duration = len(commands) * 0.1
    print(
        f"track {track.name}: the BMW's lap with the coupled MPC at 80 %: completed {m.completed}, "
        f"{m.lap_time_s:.2f} s, {duration:.0f} s driven in all, wall contacts {m.wall_contacts}"
    )
    cars = {
        "CommonRoad std, compiled": CommonRoadCar(track, BMW, start_s=s0, start_speed=v0),
        "CommonRoad std, CasADi interpreter": CommonRoadCar(
            track, BMW, start_s=s0, start_speed=v0, jit=False
        ),
        "CommonRoad std, the package's Python": CommonRoadCar(
            track, BMW, start_s=s0, start_speed=v0, engine="python"
        ),
        "SimulatedCar (same commands)": SimulatedCar(track, start_s=s0, start_speed=v0),
    }
    for name, car in cars.items():
        times = [replay(car, commands) for _ in range(RUNS)]
        per_100 = statistics.median(times) * 100.0 / duration
        print(
            f"{name:38s}: {per_100:7.3f} s CPU per 100 s simulated (median of {RUNS}), "
            f"real-time factor {100.0 / per_100:6.0f}x"
        )


if __name__ == "__main__":
    run(main)
