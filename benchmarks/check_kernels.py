"""Do the closed-loop results hold on another machine? The same laps under two OpenBLAS kernels.

Floating-point results differ in their last bits between BLAS kernels (IPOPT's linear solver, MUMPS,
runs on BLAS), and a closed lap amplifies such differences. A result worth reporting must not
depend on them. This script plans and drives, once with the default OpenBLAS kernel and once with
``OPENBLAS_CORETYPE=Sandybridge`` (a stand-in for another machine), each in a fresh process:

* the main lap: the expressway's time-optimal plan, coupled MPC, shipped tuned weights;
* a curvature-plan lap of the expressway (coupled MPC, its tuned weights);
* three real circuits (time-optimal plan, coupled MPC), when a folder of track CSVs is given.

It prints both results side by side and checks that each lap has the same outcome (completed,
wall contacts, time off track rounded to 0.1 s) and lap times within 0.3 %. Exit status 0 when all
agree, 1 otherwise.

Usage::

    python benchmarks/check_kernels.py                          # the two expressway laps
    python benchmarks/check_kernels.py --tracks TRACKS_DIR --circuits Spielberg Sepang Montreal
    python benchmarks/check_kernels.py --seeds 0 1 2

Takes several minutes (every plan is made twice). Not part of the tests: it compares two
processes' results, it does not time anything.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from _script import argument_parser, run

KERNELS = {"default": None, "Sandybridge": "Sandybridge"}
LAP_TIME_TOLERANCE = 0.003  # relative


def _laps(tracks_dir: str | None, circuits: list[str], seeds: list[int]) -> dict[str, list[dict]]:
    """Plan and drive every case in this process; per case, one dict per seed."""
    from racing_lib.experiments.pipeline import race

    cases: list[tuple[str, str, str]] = [
        ("expressway main", "expressway", "time-optimal"),
        ("expressway curvature", "expressway", "curvature"),
    ]
    for name in circuits:
        cases.append((name, str(Path(tracks_dir or ".") / f"{name}.csv"), "time-optimal"))
    out: dict[str, list[dict]] = {}
    for label, track, method in cases:
        result = race(track, method=method, controller="coupled-mpc", seed=seeds[0],
                      trials=len(seeds))  # fmt: skip
        out[label] = [
            {
                "seed": lap.metrics.seed,
                "completed": bool(lap.metrics.completed),
                "lap_time_s": float(lap.metrics.lap_time_s),
                "walls": int(lap.metrics.wall_contacts),
                "offtrack_s": round(float(lap.metrics.offtrack_time_s), 1),
            }
            for lap in result.laps
        ]
        print(f"{label}: done", file=sys.stderr, flush=True)
    return out


def _kernel_in_use() -> str:
    try:
        from threadpoolctl import threadpool_info

        for lib in threadpool_info():
            if lib.get("internal_api") == "openblas":
                return str(lib.get("architecture"))
    except ImportError:
        pass
    return "unknown"


def _run_kernel(coretype: str | None, args: argparse.Namespace) -> dict:
    env = dict(os.environ)
    env.pop("OPENBLAS_CORETYPE", None)
    if coretype is not None:
        env["OPENBLAS_CORETYPE"] = coretype
    cmd = [sys.executable, __file__, "--worker", "--seeds", *map(str, args.seeds)]
    if args.tracks:
        cmd += ["--tracks", str(args.tracks), "--circuits", *args.circuits]
    done = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, check=True, text=True)
    return json.loads(done.stdout)


def _agree(a: dict, b: dict) -> tuple[bool, str]:
    same = all(a[k] == b[k] for k in ("completed", "walls", "offtrack_s"))
    rel = abs(a["lap_time_s"] - b["lap_time_s"]) / a["lap_time_s"]
    ok = same and rel <= LAP_TIME_TOLERANCE
    return ok, f"{100.0 * rel:.3f} %"


def main(argv: list[str] | None = None) -> int:
    ap = argument_parser(__doc__)
    ap.add_argument("--tracks", type=Path, default=None, help="folder of racetrack-database CSVs")
    ap.add_argument("--circuits", nargs="*", default=["Spielberg", "Sepang", "Montreal"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    circuits = args.circuits if args.tracks else []
    if args.worker:
        laps = _laps(str(args.tracks) if args.tracks else None, circuits, args.seeds)
        print(json.dumps({"kernel": _kernel_in_use(), "laps": laps}))
        return 0
    results = {}
    for label, coretype in KERNELS.items():
        print(f"running with the {label} OpenBLAS kernel ...", file=sys.stderr, flush=True)
        results[label] = _run_kernel(coretype, args)
    first, second = (results[k] for k in KERNELS)
    print(f"kernels: {first['kernel']} vs {second['kernel']}")
    print(f"{'lap':<24} {'seed':>4}  {'default':>26}  {'Sandybridge':>26}  {'diff':>8}  agree")
    all_ok = True
    for case, laps in first["laps"].items():
        for a, b in zip(laps, second["laps"][case], strict=True):
            ok, diff = _agree(a, b)
            all_ok &= ok

            def cell(r: dict) -> str:
                state = "done" if r["completed"] else "DNF"
                return f"{r['lap_time_s']:8.2f} s {state:>4} w{r['walls']} off{r['offtrack_s']:.1f}"

            print(f"{case:<24} {a['seed']:>4}  {cell(a):>26}  {cell(b):>26}  {diff:>8}  "
                  f"{'yes' if ok else 'NO'}")  # fmt: skip
    print(
        "same outcome and lap times within "
        f"{100 * LAP_TIME_TOLERANCE:.1f} % on both kernels: {'yes' if all_ok else 'NO'}"
    )
    return 0 if all_ok else 1


if __name__ == "__main__":
    run(main)
