"""Wall time of the paper's Table I and Table II recomputed from scratch on two cores.

Every row is planned (the best possible lap of the expressway takes minutes) and driven for its
seeded trials on a local pool of worker processes, in a fresh cache folder, so nothing is reused.
Prints, per row, the planning time, the time of its trials, the mean wall time of one lap and the
row's wall time, then the total and the table itself.

Usage::

    python benchmarks/bench_ablation.py                        # every row, 10 trials, 2 workers
    python benchmarks/bench_ablation.py --trials 2 --rows main,decoupled
    python benchmarks/bench_ablation.py --track shortcut --workers 1

Never run inside the tests: timings depend on the machine and its load.
"""

from __future__ import annotations

import logging
import tempfile
import time

from _script import argument_parser, run

from racing_lib.experiments.ablation.rows import default_trials
from racing_lib.experiments.ablation.runner import run_ablation
from racing_lib.experiments.ablation.table import format_table


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--rows", help="comma-separated row names (default: all)")
    parser.add_argument("--track", help="only the rows of this track")
    parser.add_argument("--trials", type=int, default=default_trials(), help="trials per row")
    parser.add_argument("--workers", type=int, default=2, help="lap worker processes")
    parser.add_argument("--spacing", type=float, help="plan node spacing, m (default 3)")
    parser.add_argument(
        "--out", help="cache folder to keep (default: a temporary one, so nothing is reused)"
    )
    args = parser.parse_args()
    logging.disable(logging.WARNING)  # MPC fallbacks of the ablations are expected

    names = args.rows.split(",") if args.rows else None
    print(f"{args.trials} trials per row on {args.workers} worker process(es)")
    print(
        f"{'row':<34} {'plan [s]':>9} {'trials [s]':>11} {'lap [s]':>8} {'row [s]':>8}"
        f" {'planned':>8} {'closed loop':>12}"
    )
    last = time.perf_counter()
    plans: set[str] = set()

    def report(row: dict, reused: bool) -> None:
        nonlocal last
        now = time.perf_counter()
        mean = row["lap_time_mean_s"]
        # A plan shared with an earlier row (same method and options) is not planned again.
        key = row["plan"]["key"]
        plan = "reused" if reused else "shared" if key in plans else f"{row['planning_time_s']:.1f}"
        plans.add(key)
        print(
            f"{row['name']:<34} {plan:>9} {row['trials_wall_time_s']:>11.1f} "
            f"{row['lap_wall_time_mean_s']:>8.2f} {now - last:>8.1f} "
            f"{row['planned_lap_time_s']:>8.2f} "
            + (f"{mean:>12.2f}" if mean is not None else f"{'-':>12}"),
            flush=True,
        )
        last = now

    with tempfile.TemporaryDirectory(prefix="bench_ablation_") as tmp:
        tic = time.perf_counter()
        rows = run_ablation(
            names,
            track=args.track,
            trials=args.trials,
            out_dir=args.out or tmp,
            workers=args.workers,
            spacing=args.spacing,
            progress=False,
            on_row=report,
        )
        total = time.perf_counter() - tic
    print(f"total wall time: {total:.1f} s ({total / 60:.1f} min) for {len(rows)} rows")
    print()
    print(format_table(rows))


if __name__ == "__main__":
    run(main)
