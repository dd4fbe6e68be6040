"""Robustness at scale: the main job over many generated circuits (and any real ones).

Generates ``--circuits N`` circuits (50 by default) with :func:`racing_lib.tracks.generate`,
seeds S, S+1, ..., adds every racetrack-database CSV of the folders given, and on each one runs
the main job: the time-optimal plan driven by the coupled MPC with the shipped tuned weights, over
``--laps`` seeded laps. It prints one row per circuit (as ``bench_circuits.py`` does), then the
distribution over circuits (gap to the plan, wall contacts, time off track, QP failures), and for
every circuit that failed, where and why: the point of the lap where the car went furthest over
an edge, how far, and what the plan asks of the car on the 150 m before it
(:func:`racing_lib.planning.demands.plan_demands`, largest shares first).

Usage::

    python benchmarks/bench_robustness.py --out runs/robustness              # 50 circuits, seed 0
    python benchmarks/bench_robustness.py --circuits 10 --seed 100 --out runs/r10
    python benchmarks/bench_robustness.py --circuits 0 --out runs/real my_tracks/  # real ones only
    python benchmarks/bench_robustness.py --out runs/robustness --json > robustness.json
    python benchmarks/bench_robustness.py --laps 3 --lap-seed 10 --out runs/r3   # other laps

Every finished circuit's row is kept in ``--out`` (``rows/<name>.json``, with its plan in
``plans/``), so a stopped run resumes where it stopped; ``run.json`` records what the run is, and a
folder of another run is refused. ``--weights FILE`` drives other MPC
weights (such as those ``racing-lib tune --tracks`` writes); give such a run its own ``--out``.
About 2-5 s per circuit and seed on two cores (50 circuits, 2 seeds: 3-4 min). Never run inside
the tests: its wall times depend on the machine.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from _script import argument_parser, run
from bench_circuits import _print_table, _summary, drive_circuit

from racing_lib.errors import RacingLibError
from racing_lib.io import atomic_write_json, jsonable
from racing_lib.planning.demands import plan_demands
from racing_lib.tracks import CircuitSpec, generate, load_track

APPROACH = 150.0  # [m] stretch of the plan before a failing point whose demands are shown


def where_it_failed(track, result, reference) -> dict | None:
    """The worst excursion over an edge of the circuit's laps, and the plan's demands before it.

    None when every lap stayed inside the edges and completed.
    """
    worst = None
    for lap in result.laps:
        log, m = lap.log, lap.metrics
        if m.completed and m.wall_contacts == 0 and m.offtrack_time_s == 0.0:
            continue
        s_c, e_c = track.centerline.to_frenet_along(log.x, log.y)
        over = np.maximum(e_c - track.width_left(s_c), -track.width_right(s_c) - e_c)
        k = int(np.nanargmax(over))
        if worst is None or over[k] > worst["over_edge_m"]:
            # The plan's own arc length at that point: its nearest node.
            node = int(np.argmin(np.hypot(reference.x - log.x[k], reference.y - log.y[k])))
            worst = {
                "seed": m.seed,
                "completed": m.completed,
                "s_track_m": float(s_c[k]),
                "over_edge_m": float(over[k]),
                "speed_mps": float(log.vx[k]),
                "planned_speed_mps": float(reference.vx[node]),
                "s_plan_m": float(reference.s[node]),
            }
    if worst is None:
        return None
    s_plan = worst["s_plan_m"]
    demands = plan_demands(reference, track=track, where=(s_plan - APPROACH, s_plan))
    ranked = sorted((d for d in demands if math.isfinite(d.share)), key=lambda d: -d.share)
    worst["demands"] = [
        {"name": d.name, "peak": d.peak, "limit": d.limit, "share": d.share, "s_m": d.s}
        for d in ranked[:3]
    ]
    return worst


def circuit_files(args) -> list[Path]:
    """Generated circuits (written once into --out/circuits) and the real ones of the folders."""
    files = []
    if args.circuits > 0:
        folder = args.out / "circuits"
        folder.mkdir(parents=True, exist_ok=True)
        spec = CircuitSpec(grade=args.grade)
        for seed in range(args.seed, args.seed + args.circuits):
            target = folder / f"generated-{seed}.csv"
            if not target.exists():
                generate(seed, spec, name=target.stem).to_csv(target)
            files.append(target)
    for folder in args.real:
        found = sorted(Path(folder).glob("*.csv"))
        if not found:
            raise RacingLibError(f"no track CSV files in {folder}; give a folder of circuits.")
        files += found
    return files


def _incomplete(row: dict) -> bool:
    """Whether a lap of the circuit was not completed (``completed`` reads "done/driven")."""
    done, driven = row["completed"].split("/")
    return done != driven


def _same_run(args, seeds: list[int], weights) -> None:
    """Record what --out holds (OUT/run.json), or refuse a folder of another run.

    Its rows are reused, so they must come from the same circuits, laps and weights.
    """
    run = {
        "circuits": args.circuits,
        "seed": args.seed,
        "grade": args.grade,
        "real": sorted(str(Path(f).resolve()) for f in args.real),
        "seeds": seeds,
        "weights": weights,
    }
    marker = args.out / "run.json"
    if marker.is_file():
        if json.loads(marker.read_text()) != json.loads(json.dumps(run)):
            raise RacingLibError(
                f"{args.out} holds rows of another run (other circuits, laps or weights; see "
                f"{marker}); give another --out, or delete that folder."
            )
        return
    atomic_write_json(marker, jsonable(run))


def distribution(rows: list[dict], failed: int) -> str:
    """The spread of the results over circuits, in a few lines."""
    gaps = np.array([r["gap_pct"] for r in rows if math.isfinite(r["gap_pct"])])
    q = np.percentile(gaps, [0, 10, 50, 90, 100]) if gaps.size else [math.nan] * 5
    walls = sum(r["walls"] > 0 for r in rows)
    off = sum(r["offtrack_s"] > 0 for r in rows)
    incomplete = sum(_incomplete(r) for r in rows)
    qp = sum(r["qp_fail_per_lap"] > 1.0 for r in rows)
    return "\n".join(
        [
            f"circuits driven: {len(rows)}, not planned or not driven: {failed}",
            "gap to the plan, %: min {:+.2f}, p10 {:+.2f}, median {:+.2f}, p90 {:+.2f}, "
            "max {:+.2f}".format(*q),
            f"circuits with wall contacts: {walls}; off track: {off}; a lap not completed: "
            f"{incomplete}; more than one QP failure per lap: {qp}",
            f"clean (no contact, 0 s off, every lap completed): "
            f"{sum(r['walls'] == 0 and r['offtrack_s'] == 0 and not _incomplete(r) for r in rows)}"
            f" of {len(rows)}",
        ]
    )


def _failure_line(row: dict) -> str:
    f = row["failure"]
    asks = ", ".join(f"{d['name']} {d['share']:.2f}" for d in f["demands"])
    return (
        f"  {row['circuit']}: seed {f['seed']}, s = {f['s_track_m']:.0f} m, "
        f"{f['over_edge_m']:+.2f} m over the edge at {f['speed_mps']:.1f} m/s "
        f"(plan {f['planned_speed_mps']:.1f}); the plan's largest shares on the "
        f"{APPROACH:.0f} m before: {asks}"
    )


def _weights(path: Path) -> dict[str, float]:
    """The weights of a ``racing-lib tune`` output file (its ``weights``), or the file's dict."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise RacingLibError(f"--weights {path}: cannot read it as JSON ({exc}).") from None
    found = data.get("weights", data) if isinstance(data, dict) else None
    if not isinstance(found, dict) or not all(isinstance(v, float | int) for v in found.values()):
        raise RacingLibError(f"--weights {path}: no weights dict in it (as tune writes it).")
    return {k: float(v) for k, v in found.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argument_parser(__doc__)
    ap.add_argument("real", nargs="*", type=Path, help="folders of real circuits to add")
    ap.add_argument("--circuits", type=int, default=50, help="generated circuits (50)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first circuit (0)")
    ap.add_argument("--grade", action="store_true", help="generated circuits with hills")
    ap.add_argument("--laps", type=int, default=2, help="seeded laps per circuit (2)")
    ap.add_argument("--lap-seed", type=int, default=0, help="seed of the first lap (0)")
    ap.add_argument("--out", type=Path, required=True, help="folder that keeps every result")
    ap.add_argument(
        "--weights", type=Path, default=None,
        help="MPC weights: a JSON file as racing-lib tune writes it (default: the shipped set); "
        "use its own --out, since rows kept there are reused",
    )  # fmt: skip
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args(argv)
    weights = "tuned" if args.weights is None else _weights(args.weights)
    if args.circuits < 0 or args.laps < 1 or args.lap_seed < 0:
        raise RacingLibError("--circuits must be >= 0, --laps >= 1 and --lap-seed >= 0.")
    seeds = list(range(args.lap_seed, args.lap_seed + args.laps))
    _same_run(args, seeds, weights)
    files = circuit_files(args)
    if not files:
        raise RacingLibError("no circuits: give --circuits N > 0 or a folder of real ones.")
    rows, failed = [], 0
    for number, path in enumerate(files, start=1):
        kept = args.out / "rows" / f"{path.stem}.json"
        if kept.exists():
            rows.append(json.loads(kept.read_text()))
            continue
        t0 = time.perf_counter()
        try:
            track = load_track(path)
            row, result, reference = drive_circuit(track, seeds, args.out / "plans", weights)
        except RacingLibError as exc:
            print(f"{path.stem}: {exc}", file=sys.stderr)
            failed += 1
            continue
        row["failure"] = where_it_failed(track, result, reference)
        atomic_write_json(kept, jsonable(row))
        rows.append(row)
        print(f"[{number}/{len(files)}] {path.stem}: {time.perf_counter() - t0:.0f} s",
              file=sys.stderr, flush=True)  # fmt: skip
    failures = [r for r in rows if r.get("failure")]
    if args.json:
        print(json.dumps(jsonable({"rows": rows, "summary": _summary(rows)})))
        return 0
    _print_table(rows)
    print(_summary(rows))
    print(distribution(rows, failed))
    if failures:
        print("where and why they failed:")
        for row in failures:
            print(_failure_line(row))
    return 0


if __name__ == "__main__":
    run(main)
