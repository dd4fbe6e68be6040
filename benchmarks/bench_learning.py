"""Learning from laps, measured (``python benchmarks/bench_learning.py``).

Runs ``racing_lib.experiments.learning.learn`` on a track (default: the expressway, the simulated
car): iteration 0 drives the model as identified with its blanket margins, each later iteration
fits a GP correction of the model on every clean lap so far, re-plans with it (its uncertainty as
the margin) and drives again. Then the model of the fastest clean iteration drives ``--final``
laps on seeds no iteration used, the measure of the result.

Prints one row per iteration: planned and driven lap (mean over its seeds), the gap to the best
possible lap (where known: the shipped table's NLP on the car's own equations), walls, time off
track, the one-period prediction error of v_x, v_y (m/s^2) and r (rad/s^2) on the iteration's
own laps, which no fit had seen (identified -> learned), the residual samples fitted on, and the
wall time of fitting, planning and driving. Then the final laps: mean, spread, walls, time off
track and the gap.

The run is kept in ``--out`` (default runs/learning_TRACK) and resumes where it stopped; delete
the folder to start again. Its summary, the final laps included, is written to OUT/result.json
(chapter 09 ships the expressway's as racing_lib/data/learning_expressway.json).

Example: python benchmarks/bench_learning.py --iterations 5 --seeds 4 --final 10

``--inducing M`` sets the inducing inputs of each GP (default 40). They are picked by
farthest-point sampling, which spreads them to the extremes of the data; as laps accumulate, fewer
sit near the racing line, the posterior standard deviation there grows, and so does the plan's
uncertainty margin: with 40, iteration 5 of the run shipped on 2026-12-06 planned 104.51 s, with 80
on the same data 103.68 s, but each NLP takes three to four times longer.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

from _script import argument_parser, run

from racing_lib.experiments.learning import LearnSettings, check_best, learn
from racing_lib.io import atomic_write_json
from racing_lib.tracks import load_track


def _errors(it) -> str:
    before = it.prediction_error.get("identified") or {}
    after = it.prediction_error.get("learned") or {}
    parts = []
    for key in ("v_x", "v_y", "r"):
        if key not in before:
            parts.append("   -")
        elif key in after:
            parts.append(f"{before[key]:.2f}>{after[key]:.2f}")
        else:
            parts.append(f"{before[key]:.2f}     ")
    return " ".join(parts)


def main() -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--track", default="expressway", help="track (default expressway)")
    parser.add_argument("--iterations", type=int, default=5, help="learning iterations (5)")
    parser.add_argument("--seeds", type=int, default=4, help="laps per iteration (4)")
    parser.add_argument("--final", type=int, default=10, help="laps of the final check (10)")
    parser.add_argument("--out", help="folder of the run (default runs/learning_TRACK)")
    parser.add_argument(
        "--inducing", type=int, default=LearnSettings.inducing,
        help=f"inducing inputs per GP ({LearnSettings.inducing}; more: closer plans, slower NLPs)",
    )  # fmt: skip
    args = parser.parse_args()
    track = load_track(args.track)
    out = args.out or f"runs/learning_{track.name}"
    settings = LearnSettings(iterations=args.iterations, seeds=args.seeds, inducing=args.inducing)
    print(f"learning on {track.name}: {args.iterations} iterations x {args.seeds} laps, "
          f"kept in {out}/", flush=True)  # fmt: skip
    result = learn(track, settings, out=out, report=lambda line: print("  " + line, flush=True))
    best_lap = result.best_possible_lap_s
    print()
    print(f"{'it':>2} {'plan s':>8} {'driven s':>9} {'gap %':>6} {'walls':>5} {'off s':>5} "
          f"{'pred. error v_x v_y r (identified>learned)':<43} {'samples':>7} "
          f"{'fit s':>5} {'plan s':>6} {'laps s':>6}")  # fmt: skip
    for it in result.iterations:
        driven = "-" if it.driven_lap_s is None else f"{it.driven_lap_s:.2f}"
        gap = "-" if it.gap_to_best_pct is None else f"{it.gap_to_best_pct:+.2f}"
        fit, plan_s, laps_s = (it.wall_time_s.get(k, 0.0) for k in ("fit", "plan", "laps"))
        print(f"{it.iteration:>2} {it.planned_lap_s:>8.2f} {driven:>9} {gap:>6} {it.walls:>5} "
              f"{it.offtrack_s:>5.1f} {_errors(it):<43} {it.samples:>7} "
              f"{fit:>5.1f} {plan_s:>6.1f} {laps_s:>6.1f}")  # fmt: skip
    best = result.best()
    if best is None:
        print("no clean iteration")
        return 1
    t0 = time.perf_counter()
    final = check_best(result, track, settings, laps=args.final)
    done = [t for t in final["lap_times_s"] if t is not None]
    mean = statistics.fmean(done) if done else float("nan")
    spread = statistics.pstdev(done) if done else float("nan")
    gap = "" if best_lap is None else f", {100 * (mean / best_lap - 1):+.2f} % on the best lap"
    print()
    print(f"final: the model of iteration {best.iteration} on {args.final} new seeds: "
          f"{len(done)}/{args.final} completed, {mean:.2f} +- {spread:.2f} s{gap}, "
          f"{final['walls']} wall contacts, {final['offtrack_s']:.1f} s off track "
          f"({time.perf_counter() - t0:.0f} s)")  # fmt: skip
    if best_lap is not None:
        print(f"best possible lap {best_lap:.2f} s; the paper's gap to the human best: +1.41 %")
    summary = {**result.to_dict(), "final": final}
    atomic_write_json(Path(out) / "result.json", summary)
    print(f"written: {Path(out) / 'result.json'}")
    return 0


if __name__ == "__main__":
    run(main)
