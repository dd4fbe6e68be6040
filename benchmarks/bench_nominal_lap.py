"""How long a full closed-loop lap of the nominal controller takes to simulate.

Prints the median wall time of a whole lap (controller + simulated car + lap runner) on each
built-in track, and the real-time factor. Aim (issue 2): under 2 s for a lap of about 100 s.

Usage: ``python benchmarks/bench_nominal_lap.py [--repeats 5]``
"""

from __future__ import annotations

import statistics
import time

from _script import argument_parser, run

from racing_lib.experiments.lap import (
    LapSpec,
    drive_lap,
)
from racing_lib.model import identified_params
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tracks import (
    builtin_track_names,
    load_track,
)

SPEED_SCALE = 0.75  # the moderate reference of chapter 01


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--repeats", type=int, default=5, help="laps per track (seeds 0, 1, ...)")
    repeats = parser.parse_args().repeats
    print(f"{'track':<12} {'lap [s]':>8} {'wall median [s]':>16} {'min':>7} {'real-time x':>12}")
    for name in builtin_track_names():
        track = load_track(name)
        reference = Trajectory.from_centerline(track, identified_params()).scale_speed(SPEED_SCALE)
        spec = LapSpec(track=track, trajectory=reference, controller="nominal")
        walls, lap = [], float("nan")
        for seed in range(repeats):
            tic = time.perf_counter()
            metrics = drive_lap(spec, seed=seed).metrics
            walls.append(time.perf_counter() - tic)
            lap = metrics.lap_time_s
        med = statistics.median(walls)
        # The run includes the run-up before the line (150 m), a few percent of the lap.
        print(f"{name:<12} {lap:>8.2f} {med:>16.3f} {min(walls):>7.3f} {lap / med:>12.0f}")


if __name__ == "__main__":
    run(main)
