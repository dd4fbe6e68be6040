"""Where an IPOPT iteration of the time-optimal NLP goes, and what makes it cheaper.

For each track the default plan (``plan(track, "time-optimal")``: cold start, compiled
derivatives, IPOPT's MUMPS, a 3 m grid) is solved, then the same plan with one thing changed:

* ``interpreted``: the derivatives evaluated by CasADi's interpreter (``jit=False``);
* ``spral``: IPOPT's linear solver SPRAL instead of MUMPS, the only other one the casadi wheel
  links (HSL's MA27/MA57 need a licence and a library of their own);
* ``4 m`` and ``5 m``: a coarser grid everywhere, fewer nodes to solve for. A grid that is
  coarser on the straights only would save less than this and change the lap less.

Per track and way it prints IPOPT iterations, the solve's wall time (s), the share of it spent
evaluating functions (the rest is IPOPT's own work, mostly the sparse factorization), seconds per
km of track, and the planned lap time's difference to the default (%); then, over tracks, the
median ratio of each way's solve time to the default's and the largest lap-time difference.
The solve's time leaves out the build (and the first compile of the derivatives). SPRAL's OpenMP
runtime needs ``OMP_CANCELLATION`` and ``OMP_PROC_BIND`` set, so this script sets them for every
way (they may move MUMPS's times a little against ``bench_plan_speed.py``'s). A way that fails
is reported and left out of the medians, and a track whose default plan fails is left out of
all of them. Times are this machine's; never run inside the tests.

Usage::

    python benchmarks/bench_nlp_iteration.py                         # the built-in tracks
    python benchmarks/bench_nlp_iteration.py TRACKS_DIR              # plus every *.csv there
    python benchmarks/bench_nlp_iteration.py TRACKS_DIR --only Sepang --ways default spral
"""

from __future__ import annotations

import os

# SPRAL's OpenMP runtime reads these when it loads, and refuses to run without them.
os.environ.setdefault("OMP_CANCELLATION", "TRUE")
os.environ.setdefault("OMP_PROC_BIND", "TRUE")

import statistics  # noqa: E402 - after the OpenMP settings, which must precede any import
import warnings  # noqa: E402

from _script import argument_parser, run, tracks_to_measure  # noqa: E402

from racing_lib.errors import PlanningError  # noqa: E402
from racing_lib.planning import TimeOptimalSettings, plan  # noqa: E402

#: Each way: (node spacing in m, time-optimal settings).
WAYS = {
    "default": (3.0, TimeOptimalSettings()),
    "interpreted": (3.0, TimeOptimalSettings(jit=False)),
    "spral": (3.0, TimeOptimalSettings(ipopt_options=(("linear_solver", "spral"),))),
    "4 m": (4.0, TimeOptimalSettings()),
    "5 m": (5.0, TimeOptimalSettings()),
}


def solve(track, way: str) -> dict:
    """One plan of ``track`` the way named: iterations, solve and evaluation time (s), lap (s).

    A way that fails (a casadi build without SPRAL, a grid too coarse for a corner) gives
    ``{"failed": message}`` instead, so that the other ways and tracks are still measured.
    """
    spacing, settings = WAYS[way]
    try:
        res = plan(track, "time-optimal", spacing=spacing, time_optimal_settings=settings).details
    except PlanningError as exc:
        return {"failed": str(exc)}
    return {
        "iterations": res.iterations,
        "solve_s": res.solve_time,
        "eval_s": res.evaluation_time,
        "lap_s": res.lap_time,
        "nodes": res.grid.n,
    }


def main() -> None:
    """Command-line entry point."""
    parser = argument_parser(__doc__)
    parser.add_argument("tracks_dir", nargs="?", help="folder of racetrack-database CSV files")
    parser.add_argument("--only", nargs="*", help="track names to keep")
    parser.add_argument("--ways", nargs="*", choices=list(WAYS), default=list(WAYS))
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    ways = ["default", *[w for w in args.ways if w != "default"]]
    tracks = tracks_to_measure(args.tracks_dir, args.only)  # a bad file stops before any solve
    print(
        f"{'track':13s} {'km':>5s} {'way':>12s} {'nodes':>6s} {'it':>4s} {'solve':>6s} "
        f"{'eval':>5s} {'s/km':>5s} {'lap':>9s} {'vs default':>10s}"
    )
    rows: dict[str, dict[str, dict]] = {}
    for track in tracks:
        km = track.length / 1000
        rows[track.name] = {way: solve(track, way) for way in ways}
        base = rows[track.name]["default"]
        for way, r in rows[track.name].items():
            if "failed" in r:
                print(f"{track.name:13s} {km:5.2f} {way:>12s} failed: {r['failed']}")
                continue
            if "failed" in base:
                print(f"{track.name:13s} {km:5.2f} {way:>12s} no default plan to compare with")
                continue
            print(
                f"{track.name:13s} {km:5.2f} {way:>12s} {r['nodes']:6d} {r['iterations']:4d} "
                f"{r['solve_s']:6.2f} {r['eval_s'] / r['solve_s']:5.0%} {r['solve_s'] / km:5.2f} "
                f"{r['lap_s']:9.3f} {100 * (r['lap_s'] / base['lap_s'] - 1):+9.3f}%",
                flush=True,
            )
    print("\nover tracks, each way against the default (3 m, compiled, MUMPS):")
    for way in ways[1:]:
        pairs = [
            (r[way], r["default"])
            for r in rows.values()
            if "failed" not in r[way] and "failed" not in r["default"]
        ]
        if not pairs:
            print(f"  {way:>12s}: failed on every track")
            continue
        ratio = statistics.median(a["solve_s"] / b["solve_s"] for a, b in pairs)
        its = statistics.median(a["iterations"] / b["iterations"] for a, b in pairs)
        gap = max(abs(a["lap_s"] / b["lap_s"] - 1) for a, b in pairs)
        print(
            f"  {way:>12s}: median solve {ratio:.2f}x, iterations {its:.2f}x; "
            f"largest lap difference {100 * gap:.3f} %"
        )
    defaults = [r["default"] for r in rows.values() if "failed" not in r["default"]]
    if not defaults:
        return
    share = statistics.median(d["eval_s"] / d["solve_s"] for d in defaults)
    print(f"  the default spends a median {share:.0%} of its solve evaluating functions")


if __name__ == "__main__":
    run(main)
