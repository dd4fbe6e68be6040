"""Real circuits: plan each one time-optimally and drive it with the coupled MPC over several seeds.

For every racetrack-database CSV file in a folder, prints one row: length, planned lap time, IPOPT
iterations and planning wall time, the closed-loop mean and best lap over the seeds, the mean gap
to the plan, wall contacts, time off track, the largest |e_y| from the plan's line, QP failures
and rescues (QPs OSQP failed, handed to Clarabel) per lap, and the MPC step's median and p99.
A summary line follows, with the aims of the real-circuit issue (0 contacts, 0 s off track, mean
gap <= 2 %, <= 1 QP failure per lap).

Usage::

    python benchmarks/bench_circuits.py TRACKS_DIR                 # every *.csv, seeds 0 1 2
    python benchmarks/bench_circuits.py TRACKS_DIR --seeds 0 --only Spielberg Monza
    python benchmarks/bench_circuits.py TRACKS_DIR --plans runs/plans   # reuse saved plans
    python benchmarks/bench_circuits.py TRACKS_DIR --json > circuits.json

``TRACKS_DIR`` is any folder of racetrack-database files (``# x_m,y_m,w_tr_right_m,w_tr_left_m``).
With ``--plans`` each plan is saved there after planning and reused by later runs (a plan file is
refused if its track changed). The laps use the weights ``racing-lib lap`` would use (the shipped
tuned set for the time-optimal plan). Never run inside the tests: timings depend on the machine.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from _script import argument_parser, run

from racing_lib.errors import RacingLibError
from racing_lib.experiments.pipeline import race
from racing_lib.planning import plan
from racing_lib.planning.trajectory import Trajectory
from racing_lib.tracks import load_track

COLUMNS = (
    ("circuit", "{:<13}"),
    ("length_km", "{:>6.2f}"),
    ("planned_s", "{:>8.2f}"),
    ("nlp_iter", "{:>5d}"),
    ("plan_wall_s", "{:>6.1f}"),
    ("lap_mean_s", "{:>8.2f}"),
    ("lap_best_s", "{:>8.2f}"),
    ("gap_pct", "{:>+6.2f}"),
    ("walls", "{:>5d}"),
    ("offtrack_s", "{:>6.1f}"),
    ("ey_max_m", "{:>6.2f}"),
    ("qp_fail_per_lap", "{:>5.1f}"),
    ("qp_rescue_per_lap", "{:>5.1f}"),
    ("step_med_ms", "{:>6.2f}"),
    ("step_p99_ms", "{:>6.2f}"),
    ("completed", "{:>4}"),
)


def _reference(track, plans_dir: Path | None) -> tuple[Trajectory, int, float]:
    """The time-optimal plan of ``track`` (from ``plans_dir`` when saved there), its IPOPT
    iterations and planning wall time (0 and 0.0 for a reused plan)."""
    saved = plans_dir / f"{track.name}.plan.csv" if plans_dir is not None else None
    if saved is not None and saved.exists():
        try:
            return Trajectory.load_csv(saved, track=track), 0, 0.0
        except RacingLibError as exc:
            print(f"{track.name}: saved plan refused ({exc}); planning again", file=sys.stderr)
    t0 = time.perf_counter()
    result = plan(track, method="time-optimal")
    wall = time.perf_counter() - t0
    if saved is not None:
        saved.parent.mkdir(parents=True, exist_ok=True)
        result.trajectory.save_csv(saved)
    return result.trajectory, int(result.iterations), wall


def circuit_row(path: Path, seeds: list[int], plans_dir: Path | None) -> dict:
    """Plan and drive one circuit; the row of the table as a dict."""
    return drive_circuit(load_track(path), seeds, plans_dir)[0]


def drive_circuit(
    track, seeds: list[int], plans_dir: Path | None, weights: str | dict = "tuned"
) -> tuple[dict, object, object]:
    """Plan and drive one circuit: the row of the table, the race result and the plan.

    ``weights``: the MPC weights, as :func:`racing_lib.experiments.pipeline.race` takes them.
    """
    reference, iterations, plan_wall = _reference(track, plans_dir)
    result = race(track, controller="coupled-mpc", reference=reference, seed=seeds[0],
                  trials=len(seeds), weights=weights)  # fmt: skip
    metrics = [lap.metrics for lap in result.laps]
    done = [m for m in metrics if m.completed]
    laps = np.array([m.lap_time_s for m in done]) if done else np.array([np.nan])
    steps = np.concatenate([lap.log.solve_ms for lap in result.laps])
    stats = [m.controller_stats for m in metrics]
    n = len(metrics)
    return (
        {
            "circuit": track.name,
            "length_km": track.length / 1000.0,
            "planned_s": reference.lap_time,
            "nlp_iter": iterations,
            "plan_wall_s": plan_wall,
            "lap_mean_s": float(np.mean(laps)),
            "lap_best_s": float(np.min(laps)),
            "gap_pct": 100.0 * (float(np.mean(laps)) / reference.lap_time - 1.0),
            "walls": int(sum(m.wall_contacts for m in metrics)),
            "offtrack_s": float(sum(m.offtrack_time_s for m in metrics)),
            "ey_max_m": float(max(m.ey_max_m for m in metrics)),
            "qp_fail_per_lap": sum(s.get("qp_failures", 0.0) for s in stats) / n,
            "qp_rescue_per_lap": sum(s.get("qp_rescues", 0.0) for s in stats) / n,
            "step_med_ms": float(np.median(steps)),
            "step_p99_ms": float(np.percentile(steps, 99)),
            "completed": f"{len(done)}/{n}",
            "weights": result.weights_source,
        },
        result,
        reference,
    )


def _print_table(rows: list[dict]) -> None:
    head = "  ".join(f"{name:>{len(fmt.format(0) if 'd' in fmt else fmt.format(0.0))}}"
                     if name != "circuit" else f"{name:<13}" for name, fmt in COLUMNS)  # fmt: skip
    print(head)
    for row in rows:
        print("  ".join(fmt.format(row[name]) for name, fmt in COLUMNS))


def _summary(rows: list[dict]) -> str:
    walls = sum(r["walls"] for r in rows)
    off = sum(r["offtrack_s"] for r in rows)
    gaps = [r["gap_pct"] for r in rows]
    worst_gap = max(gaps) if gaps else float("nan")
    fails = max((r["qp_fail_per_lap"] for r in rows), default=0.0)
    ok = walls == 0 and off == 0.0 and worst_gap <= 2.0 and fails <= 1.0
    return (
        f"{len(rows)} circuits: {walls} wall contacts, {off:.1f} s off track, mean gap "
        f"{np.mean(gaps):+.2f} % (median {np.median(gaps):+.2f} %, worst {worst_gap:+.2f} %), "
        f"at most {fails:.1f} QP failures per lap -> aims "
        f"{'met' if ok else 'NOT met'} (0 contacts, 0 s off, gap <= 2 %, <= 1 failure per lap)"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argument_parser(__doc__)
    ap.add_argument("tracks_dir", type=Path, help="folder of racetrack-database CSV files")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--only", nargs="+", default=None, help="circuit names (file stems)")
    ap.add_argument("--plans", type=Path, default=None, help="folder to save and reuse plans")
    ap.add_argument("--json", action="store_true", help="print the rows as one JSON object")
    args = ap.parse_args(argv)
    files = sorted(args.tracks_dir.glob("*.csv"))
    if args.only:
        wanted = {name.lower() for name in args.only}
        files = [f for f in files if f.stem.lower() in wanted]
    if not files:
        print(f"error: no track CSV files in {args.tracks_dir}", file=sys.stderr)
        return 2
    rows = []
    for path in files:
        t0 = time.perf_counter()
        try:
            rows.append(circuit_row(path, args.seeds, args.plans))
        except RacingLibError as exc:
            print(f"{path.stem}: {exc}", file=sys.stderr)
            continue
        print(f"{path.stem}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps({"seeds": args.seeds, "rows": rows, "summary": _summary(rows)}))
    else:
        _print_table(rows)
        print(_summary(rows))
    return 0


if __name__ == "__main__":
    run(main)
