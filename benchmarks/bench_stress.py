"""The controller ablations at the limit (``python benchmarks/bench_stress.py``).

Plans the time-optimal lap once per grip margin, drives that one plan with main (coupled MPC,
smooth transition), the decoupled pair of MPCs and the coupled MPC without the smooth transition,
each with its own tuned weights, over the same seeds, and weighs each ablation against main with
a 95 % Welch interval (``racing_lib.experiments.ablation.stress``). By default it runs the
pipeline's margin and none, the stress setting of chapter 07.

Prints per margin: one row per configuration (completed laps, mean lap and spread, gap to the
plan, v_x and e_y MAE, wall contacts, time off track), then each ablation's difference to main
with its interval and verdict (worse / better / indistinguishable), and the wall time.

Example: python benchmarks/bench_stress.py --seeds 10 --margins 0 0.05 --workers 2
"""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor

from _script import argument_parser, run

from racing_lib.experiments.ablation.stress import compare_to_main, stress_run, stress_table
from racing_lib.face.notebook import Table
from racing_lib.model.identified import GRIP_MARGIN
from racing_lib.tracks import load_track


def main() -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--track", default="expressway", help="track (default expressway)")
    parser.add_argument("--seeds", type=int, default=10, help="laps per configuration (10)")
    parser.add_argument(
        "--margins", type=float, nargs="+", default=[GRIP_MARGIN, 0.0],
        help=f"grip margins to plan with, shares ({GRIP_MARGIN:g} and 0)",
    )  # fmt: skip
    parser.add_argument("--workers", type=int, default=2, help="laps in parallel (2)")
    args = parser.parse_args()
    track = load_track(args.track)
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for margin in args.margins:
            t0 = time.perf_counter()
            result = stress_run(track, grip_margin=margin, seeds=args.seeds, executor=pool)
            print(f"\n{track.name}, grip margin {100 * margin:.1f} %: plan "
                  f"{result.planned_lap_s:.2f} s, {args.seeds} seeds")  # fmt: skip
            print(repr(Table(*stress_table(result))))
            for c in compare_to_main(result):
                print(f"  {c.config:<22} {c.measure:<14} {c.ablation_mean:8.2f} vs "
                      f"{c.main_mean:8.2f} {c.unit:<8} difference {c.low:+.2f}..{c.high:+.2f}: "
                      f"{c.verdict}")  # fmt: skip
            print(f"  ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    run(main)
