"""How fast a closed-loop lap runs: the MPC step against its period, the car and the lap against
real time.

For each track, the main configuration (time-optimal plan, coupled MPC with the shipped tuned
weights, the simulated car) drives ``--repeats`` laps with seed 0. Prints the median over the
repeats of:

* the coupled-MPC step during the lap (median and 99th percentile, ms) and its median as a share
  of the control period;
* the simulated car alone (the lap's commands replayed, which reproduces it bit for bit), as a
  multiple of real time;
* the whole lap (controller, car and logging, as ``run_lap`` drives it), as a multiple of real
  time.

``--busy K`` starts K processes that spin on a core for the duration (a stand-in for a machine
that is doing something else too). Times are this machine's; never run inside the tests.

Usage::

    python benchmarks/bench_closed_loop.py                          # expressway, 3 laps
    python benchmarks/bench_closed_loop.py --tracks shortcut Spielberg.csv --busy 1
"""

from __future__ import annotations

import multiprocessing as mp
import statistics
import time
import warnings

import numpy as np
from _script import argument_parser, run

from racing_lib.experiments.configs import config_spec
from racing_lib.experiments.lap import make_car, make_controller, run_lap
from racing_lib.geometry import Track
from racing_lib.tracks import load_track


def _spin() -> None:
    while True:
        pass


def replay_factor(spec, steer: np.ndarray, pedal: np.ndarray, seed: int) -> float:
    """Simulated seconds per wall second of the car alone, replaying logged commands."""
    car = make_car(spec)
    car.reset(seed=seed)
    t0 = time.perf_counter()
    for u_s, u_p in zip(steer.tolist(), pedal.tolist(), strict=True):
        car.step(u_s, u_p)
    return len(steer) * car.dt / (time.perf_counter() - t0)


def bench_track(track: Track, repeats: int, seed: int = 0) -> dict[str, float]:
    """Medians over ``repeats`` laps of one track."""
    spec = config_spec("main", track)
    laps, steps_med, steps_p99, cars = [], [], [], []
    period = None
    for _ in range(repeats):
        car, controller = make_car(spec), make_controller(spec)
        period = car.dt
        t0 = time.perf_counter()
        res = run_lap(car, controller, spec.trajectory, track=track, seed=seed)
        wall = time.perf_counter() - t0
        log = res.log
        laps.append(float(log.t[-1] + car.dt) / wall)
        steps_med.append(float(np.median(log.solve_ms)))
        steps_p99.append(float(np.percentile(log.solve_ms, 99)))
        cars.append(replay_factor(spec, np.asarray(log.steer), np.asarray(log.pedal), seed))
    med = statistics.median
    return {
        "lap_s": float(res.metrics.lap_time_s),
        "step_med_ms": med(steps_med),
        "step_p99_ms": med(steps_p99),
        "step_share": med(steps_med) / (1e3 * period),
        "car_x": med(cars),
        "lap_x": med(laps),
    }


def main() -> None:
    """Command-line entry point."""
    parser = argument_parser(__doc__)
    parser.add_argument("--tracks", nargs="+", default=["expressway"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--busy", type=int, default=0, help="spinning processes alongside")
    args = parser.parse_args()
    tracks = [load_track(source) for source in args.tracks]  # a bad path stops here, at once
    warnings.filterwarnings("ignore")
    spinners = [mp.Process(target=_spin, daemon=True) for _ in range(args.busy)]
    for p in spinners:
        p.start()
    try:
        print(f"{args.busy} spinning process(es) alongside; medians over {args.repeats} laps")
        print(
            f"{'track':13s} {'lap s':>8s} {'step med':>9s} {'step p99':>9s} {'of period':>9s} "
            f"{'car x':>7s} {'lap x':>7s}"
        )
        for track in tracks:
            r = bench_track(track, args.repeats)
            print(
                f"{track.name:13s} {r['lap_s']:8.2f} {r['step_med_ms']:7.2f}ms "
                f"{r['step_p99_ms']:7.2f}ms {100 * r['step_share']:8.1f}% {r['car_x']:6.0f}x "
                f"{r['lap_x']:6.0f}x",
                flush=True,
            )
    finally:
        for p in spinners:
            p.terminate()


if __name__ == "__main__":
    run(main)
