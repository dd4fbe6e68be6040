"""How fast the time-optimal plan is: warm against cold, the default against the previous default.

For each track, ``plan(track, "time-optimal")`` is run as a user runs it (curvature QP, NLP build
and solve, nothing cached from an earlier track) in four ways:

* ``previous``: the planner as it was before issue 14: one flat CasADi SX graph differentiated
  by CasADi (``graph="sx"``), IPOPT's own starting point (``mu_init`` 0.1, bound multipliers 1),
  warm-started from the QP;
* ``warm``: the structured NLP with :data:`~racing_lib.planning.time_optimal.STARTING_BARRIER`,
  warm-started from the QP (the paper's two stages);
* ``cold``: the same NLP from the centerline at 10 m/s, which is ``plan``'s default
  (:data:`~racing_lib.planning.DEFAULT_START`), chosen because it was the faster of the two;
* ``interpreted``: the cold start with the derivatives evaluated by CasADi's interpreter
  (``TimeOptimalSettings(jit=False)``), as the planner ran before they were compiled.

Per track it prints IPOPT iterations, the build time, the wall time of the whole call (median
over ``--repeats``), the share of the solve spent evaluating functions (``eval``) and the planned
lap time of each; then the medians over tracks of the ratios
that matter: warm/cold iterations and wall time, interpreted/compiled solve and wall time and the
share of the solve spent in function evaluations (the rest is IPOPT's own linear algebra),
seconds per km, previous/new (new: the default) wall time and iterations, and the largest
lap-time difference between the ways. The first plan of a parameter set on a machine compiles
its derivatives (about a second, then cached on disk): run once before timing, or read the build
column. Times are this machine's; never run inside the tests.

Usage::

    python benchmarks/bench_plan_speed.py                           # the built-in tracks
    python benchmarks/bench_plan_speed.py TRACKS_DIR --repeats 3    # plus every *.csv there
    python benchmarks/bench_plan_speed.py TRACKS_DIR --only Monza Spa --skip-previous
"""

from __future__ import annotations

import statistics
import time
import warnings

from _script import argument_parser, run, tracks_to_measure

from racing_lib.planning import DEFAULT_START, TimeOptimalSettings, plan
from racing_lib.planning.time_optimal import clear_cache
from racing_lib.planning.time_optimal_nlp import clear_interval_caches

#: The defaults before the structured NLP (both options are IPOPT's own defaults).
PREVIOUS = TimeOptimalSettings(
    graph="sx", ipopt_options=(("mu_init", 0.1), ("bound_mult_init_method", "constant"))
)
WAYS = {
    "previous": (PREVIOUS, "warm"),
    "warm": (TimeOptimalSettings(), "warm"),
    "cold": (TimeOptimalSettings(), "cold"),
    "interpreted": (TimeOptimalSettings(jit=False), "cold"),
}


def run_once(track, settings: TimeOptimalSettings, start: str) -> dict:
    """One plan from nothing cached: iterations, build and wall time (s), lap time (s)."""
    clear_cache()
    clear_interval_caches()
    t0 = time.perf_counter()
    res = plan(track, "time-optimal", start=start, time_optimal_settings=settings)
    wall = time.perf_counter() - t0
    nlp = res.details
    return {
        "iterations": int(res.iterations),
        "build_s": float(nlp.build_time),
        "solve_s": float(nlp.solve_time),
        "eval_s": float(nlp.evaluation_time),
        "wall_s": wall,
        "lap_s": float(nlp.lap_time),
        "status": res.status,
    }


def bench_track(track, ways: list[str], repeats: int) -> dict[str, dict]:
    """Each way's result on one track, wall times the median of ``repeats`` runs."""
    out = {}
    for way in ways:
        settings, start = WAYS[way]
        runs = [run_once(track, settings, start) for _ in range(repeats)]
        row = dict(runs[0])
        row["wall_s"] = statistics.median(r["wall_s"] for r in runs)
        row["solve_s"] = statistics.median(r["solve_s"] for r in runs)
        row["build_s"] = statistics.median(r["build_s"] for r in runs)
        row["eval_s"] = statistics.median(r["eval_s"] for r in runs)
        out[way] = row
    return out


def main() -> None:
    """Command-line entry point."""
    parser = argument_parser(__doc__)
    parser.add_argument("tracks_dir", nargs="?", help="folder of racetrack-database CSV files")
    parser.add_argument("--only", nargs="*", help="track names to keep")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--skip-previous", action="store_true", help="skip the slow old default")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    tracks = tracks_to_measure(args.tracks_dir, args.only)
    ways = [w for w in WAYS if not (args.skip_previous and w == "previous")]
    header = f"{'track':13s} {'km':>5s}"
    for way in ways:
        header += f" | {way + ' it':>14s} {'build':>5s} {'wall':>5s} {'eval':>4s} {'lap':>8s}"
    print(header)
    rows = {}
    km = {track.name: track.length / 1000 for track in tracks}
    for track in tracks:
        row = bench_track(track, ways, args.repeats)
        rows[track.name] = row
        line = f"{track.name:13s} {km[track.name]:5.2f}"
        for way in ways:
            r = row[way]
            share = r["eval_s"] / r["solve_s"]
            line += (
                f" | {r['iterations']:14d} {r['build_s']:5.2f} {r['wall_s']:5.1f} {share:4.0%}"
                f" {r['lap_s']:8.3f}"
            )
        print(line, flush=True)
    med = statistics.median
    new = DEFAULT_START  # the way plan() runs unless told otherwise
    worst_wall = max(r[new]["wall_s"] for r in rows.values())
    worst_it = max(r[new]["iterations"] for r in rows.values())
    print(
        f"\nthe default ({new} start), worst track: {worst_it} iterations, {worst_wall:.1f} s wall"
    )
    its = med(r["warm"]["iterations"] / r["cold"]["iterations"] for r in rows.values())
    wall = med(r["warm"]["wall_s"] / r["cold"]["wall_s"] for r in rows.values())
    faster = [name for name, r in rows.items() if r["warm"]["wall_s"] < r["cold"]["wall_s"]]
    print(
        f"median warm/cold: iterations {its:.2f}, wall {wall:.2f}; "
        f"warm faster on {faster or 'none'}"
    )
    solve = med(r["interpreted"]["solve_s"] / r["cold"]["solve_s"] for r in rows.values())
    wall = med(r["interpreted"]["wall_s"] / r["cold"]["wall_s"] for r in rows.values())
    share = {w: med(r[w]["eval_s"] / r[w]["solve_s"] for r in rows.values()) for w in ways}
    print(
        f"median interpreted/compiled: solve {solve:.2f}x, wall {wall:.2f}x; share of the "
        f"solve in evaluations: interpreted {share['interpreted']:.0%}, compiled "
        f"{share['cold']:.0%}"
    )
    per_km = {w: med(r[w]["wall_s"] / km[name] for name, r in rows.items()) for w in ways}
    its_km = med(r[new]["iterations"] / km[name] for name, r in rows.items())
    print(
        "median wall s per km: "
        + ", ".join(f"{w} {v:.2f}" for w, v in per_km.items())
        + f"; default iterations per km {its_km:.1f}"
    )
    if "previous" in ways:
        wall = med(r["previous"]["wall_s"] / r[new]["wall_s"] for r in rows.values())
        its = med(r["previous"]["iterations"] / r[new]["iterations"] for r in rows.values())
        build = med(r["previous"]["build_s"] / r[new]["build_s"] for r in rows.values())
        print(f"median previous/new: wall {wall:.1f}x, iterations {its:.1f}x, build {build:.0f}x")
    gap = max(
        abs(r[a]["lap_s"] - r[new]["lap_s"]) / r[new]["lap_s"] for r in rows.values() for a in ways
    )
    print(f"largest planned-lap difference between the ways: {100 * gap:.4f} %")


if __name__ == "__main__":
    run(main)
