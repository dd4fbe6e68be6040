"""Learning from laps, measured (``python benchmarks/bench_learning.py``).

Runs ``racing_lib.experiments.learning.learn`` on a track (default: the expressway, the simulated
car): iteration 0 drives the model as identified with its blanket margins, each later iteration
fits a GP correction of the model on every clean lap so far, re-plans with it (its uncertainty as
the margin) and drives again. Then the model of the fastest clean iteration whose laps stayed
within their edge margins drives ``--final`` laps on seeds no iteration used, the measure of the
result.

Prints one row per iteration: planned and driven lap (mean over its seeds), the gap to the best
possible lap (where known: the shipped table's NLP on the car's own equations), walls, time off
track, how far the laps strayed beyond the edge margins their plan kept (m; "-": within them),
the one-period prediction error of v_x, v_y (m/s^2) and r (rad/s^2) on the iteration's own laps,
which no fit had seen (identified -> learned), the residual samples fitted on, and the wall time of
fitting, planning and driving. Then the final laps: mean, spread, walls, time off
track and the gap.

The run is kept in ``--out`` (default runs/learning_TRACK) and resumes where it stopped; delete
the folder to start again. Its summary, the final laps included, is written to OUT/result.json
(chapter 09 ships the expressway's as racing_lib/data/learning_expressway.json).

Example: python benchmarks/bench_learning.py --iterations 5 --seeds 4 --final 10

On a track whose best possible lap is not shipped (any CSV), it is planned after the loop (an NLP
on the simulated car's equations; minutes on a long circuit), and several tracks end with a
summary table: python benchmarks/bench_learning.py --track A.csv B.csv C.csv --out runs/circuits

``--inducing M`` sets the inducing inputs of each GP (default 40). They are picked by
farthest-point sampling, which spreads them to the extremes of the data; as laps accumulate, fewer
sit near the racing line, the posterior standard deviation there grows, and so does the plan's
uncertainty margin: with 40, iteration 5 of a run of 2026-12-06 (before the margins followed the
laps) planned 104.51 s, with 80 on the same data 103.68 s, but each NLP takes three to four times
longer.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path

from _script import argument_parser, run

from racing_lib.errors import RacingLibError
from racing_lib.experiments.learning import LearnSettings, check_best, learn
from racing_lib.experiments.learning_results import beyond_text
from racing_lib.geometry import Track
from racing_lib.io import atomic_write_json
from racing_lib.planning.best_lap import solve_best_lap
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


def _gap(lap_s: float, best_s: float) -> float:
    """How much slower ``lap_s`` is than the best possible lap ``best_s``, %."""
    return 100.0 * (lap_s / best_s - 1.0)


def _best_possible_lap(track: Track, known: float | None) -> float:
    """The shipped best possible lap, or one planned now (an NLP on the car's own equations).

    A solve that does not converge raises PlanningError (one line on stderr, exit status 2):
    no gap is measured against a lap that was not found.
    """
    if known is not None:
        return known
    t0 = time.perf_counter()
    best = solve_best_lap(track)
    print(f"best possible lap of {track.name}: {best.lap_time:.2f} s ({best.status}, "
          f"{time.perf_counter() - t0:.0f} s to plan)", flush=True)  # fmt: skip
    return float(best.lap_time)


def _one_track(track: Track, args: argparse.Namespace, settings: LearnSettings) -> dict:
    """Learn on one track, print its table and final check; return its summary."""
    out = args.out if args.out and len(args.track) == 1 else None
    out = out or f"{args.out or 'runs'}/learning_{track.name}"
    print(f"learning on {track.name}: {args.iterations} iterations x {args.seeds} laps, "
          f"kept in {out}/", flush=True)  # fmt: skip
    result = learn(track, settings, out=out, report=lambda line: print("  " + line, flush=True))
    best_lap = _best_possible_lap(track, result.best_possible_lap_s)
    print()
    print(f"{'it':>2} {'plan s':>8} {'driven s':>9} {'gap %':>6} {'walls':>5} {'off s':>5} "
          f"{'beyond m':>8} {'pred. error v_x v_y r (identified>learned)':<43} {'samples':>7} "
          f"{'fit s':>5} {'plan s':>6} {'laps s':>6}")  # fmt: skip
    for it in result.iterations:
        driven = "-" if it.driven_lap_s is None else f"{it.driven_lap_s:.2f}"
        gap = "-" if it.driven_lap_s is None else f"{_gap(it.driven_lap_s, best_lap):+.2f}"
        fit, plan_s, laps_s = (it.wall_time_s.get(k, 0.0) for k in ("fit", "plan", "laps"))
        beyond = beyond_text(it.margin_excess_m).removesuffix(" m")
        print(f"{it.iteration:>2} {it.planned_lap_s:>8.2f} {driven:>9} {gap:>6} {it.walls:>5} "
              f"{it.offtrack_s:>5.1f} {beyond:>8} {_errors(it):<43} {it.samples:>7} "
              f"{fit:>5.1f} {plan_s:>6.1f} {laps_s:>6.1f}")  # fmt: skip
    summary = {**result.to_dict(), "best_possible_lap_s": best_lap}
    for it in summary["iterations"]:  # where the loop did not know the best lap, it is known now
        if it["driven_lap_s"] is not None:
            it["gap_to_best_pct"] = _gap(it["driven_lap_s"], best_lap)
    best = result.best()
    if best is None:
        print("no clean iteration")
        return {**summary, "final": None}
    t0 = time.perf_counter()
    final = check_best(result, track, settings, laps=args.final)
    done = [t for t in final["lap_times_s"] if t is not None]
    mean = statistics.fmean(done) if done else float("nan")
    spread = statistics.pstdev(done) if done else float("nan")
    print()
    print(f"final: the model of iteration {best.iteration} on {args.final} new seeds: "
          f"{len(done)}/{args.final} completed, {mean:.2f} +- {spread:.2f} s, "
          f"{_gap(mean, best_lap):+.2f} % on the best lap, "
          f"{final['walls']} wall contacts, {final['offtrack_s']:.1f} s off track "
          f"({time.perf_counter() - t0:.0f} s)")  # fmt: skip
    print(f"best possible lap {best_lap:.2f} s; the paper's gap to the human best: +1.41 %")
    summary["final"] = final
    atomic_write_json(Path(out) / "result.json", summary)
    print(f"written: {Path(out) / 'result.json'}", flush=True)
    return summary


def main() -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--track", nargs="+", default=["expressway"],
                        help="tracks: names or CSV files (default expressway)")  # fmt: skip
    parser.add_argument("--iterations", type=int, default=5, help="learning iterations (5)")
    parser.add_argument("--seeds", type=int, default=4, help="laps per iteration (4)")
    parser.add_argument("--final", type=int, default=10, help="laps of the final check (10)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first lap (0)")
    parser.add_argument(
        "--out",
        help="folder of the run (default runs/learning_TRACK); with several tracks, the folder "
        "that holds one run per track",
    )
    parser.add_argument(
        "--inducing", type=int, default=LearnSettings.inducing,
        help=f"inducing inputs per GP ({LearnSettings.inducing}; more: closer plans, slower NLPs)",
    )  # fmt: skip
    args = parser.parse_args()
    tracks = [load_track(name) for name in args.track]  # every name checked before any work
    settings = LearnSettings(
        iterations=args.iterations, seeds=args.seeds, seed=args.seed, inducing=args.inducing
    )
    summaries = []
    for track in tracks:
        try:
            summaries.append(_one_track(track, args, settings))
        except RacingLibError as exc:
            # One circuit that fails (a plan that cannot be solved) does not stop the others.
            print(f"{track.name}: stopped: {exc}", flush=True)
            summaries.append({"best_possible_lap_s": math.nan, "iterations": [], "final": None})
    if len(summaries) > 1:
        print()
        print(f"{'track':<14} {'best s':>8} {'identified':>10} {'learned (final)':>16} "
              f"{'walls':>5} {'off s':>5}")  # fmt: skip
        for track, summary in zip(tracks, summaries, strict=True):
            best_lap = summary["best_possible_lap_s"]
            its = summary["iterations"]
            first = its[0]["driven_lap_s"] if its else None
            final = summary["final"]
            done = [t for t in (final or {}).get("lap_times_s", []) if t is not None]
            learned = f"{_gap(statistics.fmean(done), best_lap):+.2f} %" if done else "-"
            ident = "-" if first is None else f"{_gap(first, best_lap):+.2f} %"
            walls = "-" if final is None else final["walls"]
            off = "-" if final is None else f"{final['offtrack_s']:.1f}"
            print(f"{track.name:<14} {best_lap:>8.2f} {ident:>10} {learned:>16} {walls:>5} "
                  f"{off:>5}")  # fmt: skip
    return 0 if all(summary["final"] is not None for summary in summaries) else 1


if __name__ == "__main__":
    run(main)
