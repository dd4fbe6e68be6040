"""How long one CMA-ES generation of MPC-weight tuning takes, serially and on 2 worker processes.

One generation evaluates ``popsize`` candidate weight sets, one closed-loop lap each, on a short
walled track (about 800 m, two hairpins) with the coupled MPC; its plan is the centerline at the
identified model's speed profile with some grip in reserve. The process pool is made once: its
first generation ("cold") includes starting the workers and building the MPC's CasADi functions
in each; the median is over the warm repeats.

Usage: ``python benchmarks/bench_tuning.py [--repeats 3] [--popsize 9]``
"""

from __future__ import annotations

import functools
import logging
import statistics
import time
from concurrent.futures import Executor, ProcessPoolExecutor

from _script import argument_parser, run

from racing_lib.experiments.lap import LapSpec
from racing_lib.experiments.tuning import (
    evaluate_weights,
    mpc_weight_space,
)
from racing_lib.model import CarModel
from racing_lib.model.identified import identified_params
from racing_lib.optim.cmaes import (
    CmaTuner,
    TuningSettings,
)
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tracks import Arc, Straight, track_from_segments


def stadium_spec() -> LapSpec:
    """The short walled track of tests/test_tuning.py with the coupled MPC."""
    track = track_from_segments(
        [Straight(250.0), Arc.degrees(50.0, 180.0), Straight(250.0), Arc.degrees(50.0, 180.0)],
        width=10.0,
        boundary="walls",
        name="stadium",
    )
    # The MPC predicts with the identified set; the plan keeps a fifth of its grip (mu 1.0).
    model = CarModel(identified_params(), grip_margin=0.2)
    plan = Trajectory.from_centerline(track, model.planning_params()).with_model(model)
    return LapSpec(track=track, trajectory=plan, controller="coupled-mpc", run_up=50.0)


def one_generation(tuner: CmaTuner, executor: Executor | None) -> float:
    """Wall time of one generation (ask, evaluate all candidates, tell), s."""
    tic = time.perf_counter()
    tuner.run(executor=executor, workers=1, progress=False)
    return time.perf_counter() - tic


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--repeats", type=int, default=3, help="timed generations per executor")
    parser.add_argument("--popsize", type=int, default=9, help="candidates per generation")
    args = parser.parse_args()
    repeats, popsize = args.repeats, args.popsize
    logging.disable(logging.WARNING)  # MPC fallbacks of bad candidates are expected here
    spec = stadium_spec()
    evaluate = functools.partial(evaluate_weights, spec, seeds=(0,))
    settings = TuningSettings(popsize=popsize, max_generations=1, seed=0)
    tuner = CmaTuner(evaluate, mpc_weight_space(), settings)
    print(f"one generation = {popsize} MPC laps of {spec.track.length:.0f} m")
    print(f"{'executor':<22} {'cold [s]':>9} {'warm median [s]':>16} {'per lap [s]':>12}")

    evaluate({})  # build the MPC's functions in this process once (the pool's workers do too)
    serial = [one_generation(tuner, None) for _ in range(repeats)]
    med = statistics.median(serial)
    print(f"{'serial':<22} {serial[0]:>9.2f} {med:>16.2f} {med / popsize:>12.2f}")

    with ProcessPoolExecutor(max_workers=2) as pool:
        times = [one_generation(tuner, pool) for _ in range(repeats + 1)]
    med2 = statistics.median(times[1:])
    print(f"{'ProcessPool, 2 workers':<22} {times[0]:>9.2f} {med2:>16.2f} {med2 / popsize:>12.2f}")
    print(f"speed-up (warm): {med / med2:.2f}x")


if __name__ == "__main__":
    run(main)
