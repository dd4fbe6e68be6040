"""The ``racing-lib`` command.

Sub-commands (see ``racing-lib --help``): ``tracks``, ``plan``, ``lap``, ``tune``, ``ablation``.
With ``--json`` a command prints exactly one JSON object on standard output; everything meant for a
person goes to standard error. Errors of racing_lib are printed as one line (``error: ...``) with
exit status 2, never as a traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path as FilePath
from typing import Any

from racing_lib.errors import RacingLibError

DEFAULT_TRACK = "expressway"


def _say(*parts: object) -> None:
    """Human-readable output: always standard error, so that stdout stays pure JSON."""
    print(*parts, file=sys.stderr)


def _clean(obj: Any) -> Any:
    """Make an object JSON-safe: NaN and infinities become null."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    return obj


def _emit_json(obj: dict[str, Any]) -> None:
    print(json.dumps(_clean(obj), allow_nan=False))


# --------------------------------------------------------------------------------------------------
# tracks


def cmd_tracks(args: argparse.Namespace) -> int:
    """List the built-in tracks with their length, width range and boundary kind."""
    import numpy as np

    from racing_lib.track import builtin_track_names, load_track

    rows = []
    for name in builtin_track_names():
        track = load_track(name)
        s = np.linspace(0.0, track.length, 2000, endpoint=False)
        width = track.width_left(s) + track.width_right(s)
        kappa = np.abs(track.centerline.curvature(s))
        z = track.elevation(s)
        rows.append(
            {
                "name": name,
                "length_m": round(float(track.length), 1),
                "width_min_m": round(float(width.min()), 2),
                "width_max_m": round(float(width.max()), 2),
                "min_radius_m": round(float(1.0 / kappa.max()), 1),
                "elevation_range_m": round(float(z.max() - z.min()), 2),
                "boundary": track.boundary,
            }
        )
    if args.json:
        _emit_json({"tracks": rows})
    else:
        header = f"{'name':<12} {'length':>9} {'width':>13} {'min R':>8} {'dz':>7}  boundary"
        print(header)
        for r in rows:
            print(
                f"{r['name']:<12} {r['length_m']:>7.1f} m "
                f"{r['width_min_m']:>5.1f}-{r['width_max_m']:<5.1f}m "
                f"{r['min_radius_m']:>6.1f} m {r['elevation_range_m']:>5.1f} m  {r['boundary']}"
            )
    return 0


# --------------------------------------------------------------------------------------------------
# plan and lap share the way a plan is obtained


def _model_options(args: argparse.Namespace):
    from racing_lib.model import ModelOptions

    return ModelOptions(
        drag=not args.no_drag,
        longitudinal_weight_transfer=not args.no_weight_transfer,
        lateral_weight_transfer=args.lateral_weight_transfer,
    )


def _make_plan(args: argparse.Namespace, track):
    """Plan ``track`` with the method and model options on the command line."""
    from racing_lib.planning import plan

    return plan(track, method=args.method, options=_model_options(args))


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan a lap and optionally save it as a plan CSV."""
    from racing_lib.track import load_track

    track = load_track(args.track)
    _say(f"planning {track.name} ({track.length:.0f} m) with method '{args.method}' ...")
    result = _make_plan(args, track)
    traj = result.trajectory
    if args.out:
        traj.save_csv(args.out)
        _say(f"plan written to {args.out}")
    fields = {
        "track": track.name,
        "method": args.method,
        "length_m": float(track.length),
        "nodes": int(len(traj.s)),
        "lap_time_s": float(traj.lap_time),
        "solve_time_s": float(result.solve_time),
        "iterations": int(result.iterations),
        "status": str(result.status),
    }
    if args.json:
        _emit_json(fields)
    else:
        print(
            f"{fields['track']}: {fields['method']} plan, {fields['nodes']} nodes, planned lap "
            f"{fields['lap_time_s']:.2f} s, solved in {fields['solve_time_s']:.2f} s "
            f"({fields['iterations']} iterations, {fields['status']})"
        )
    return 0


def cmd_lap(args: argparse.Namespace) -> int:
    """Drive laps in closed loop and report their metrics."""
    from racing_lib.pipeline import race

    out_dir = FilePath(args.out) if args.out else None

    def save_log(lap) -> None:
        # Saved as each lap ends: an interrupted run of many trials keeps the laps already driven.
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            lap.log.save(str(out_dir / f"log_seed{lap.metrics.seed}.npz"))

    result = race(
        args.track,
        method=args.method,
        controller=args.controller,
        seed=args.seed,
        trials=args.trials,
        options=_model_options(args),
        smooth_transition=not args.no_smooth_transition,
        reference=args.plan,
        progress=not args.json and args.trials == 1,
        report=_say,
        on_lap=save_log,
    )
    report = result.summary()
    if out_dir is not None:
        _save_lap_outputs(out_dir, result.track, result.reference, result.laps, report)
        _say(f"figures, logs and summary written to {out_dir}/")
    if args.json:
        _emit_json(report)
    else:
        _print_summary(report)
    return 0 if result.completed else 1


def _print_summary(report: dict[str, Any]) -> None:
    s = report["summary"]
    print(f"track {report['track']}, controller {report['controller']}")
    print(f"reference lap time    {report['planned_lap_time_s']:.2f} s")
    if s["completed"]:
        print(
            f"closed-loop lap time  {s['lap_time_mean_s']:.2f} +- {s['lap_time_std_s']:.3f} s "
            f"(best {s['lap_time_min_s']:.2f} s, "
            f"{s['completed']}/{len(report['trials'])} completed)"
        )
        gap = 100.0 * (s["lap_time_mean_s"] / report["planned_lap_time_s"] - 1.0)
        print(f"gap to the plan       {gap:+.2f} %")
    else:
        print("no lap was completed")


def _save_lap_outputs(out_dir: FilePath, track, trajectory, results, report) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from racing_lib import plotting
    from racing_lib.io import atomic_write_json

    plotting.set_style()
    out_dir.mkdir(parents=True, exist_ok=True)
    trajectory.save_csv(str(out_dir / "plan.csv"))
    log = results[0].log
    ax = plotting.plot_track(track, {"plan": trajectory, "closed loop": log})
    ax.figure.savefig(out_dir / "track.png", dpi=130, bbox_inches="tight")
    plt.close(ax.figure)
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    lap = log.in_lap
    plotting.plot_profiles(
        {"plan": trajectory.s, "closed loop": log.s_ref[lap]},
        {"plan": trajectory.vx, "closed loop": log.vx[lap]},
        ax=axes[0],
        ylabel="v_x [m/s]",
    )
    plotting.plot_profiles(log.s_ref[lap], {"e_y": log.ey[lap]}, ax=axes[1], ylabel="e_y [m]")
    fig.savefig(out_dir / "profiles.png", dpi=130, bbox_inches="tight")
    plt.close(fig)
    atomic_write_json(out_dir / "summary.json", _clean(report))


def cmd_tune(args: argparse.Namespace) -> int:
    """Tune the coupled MPC's weights with CMA-ES on the time-optimal plan of a track."""
    from racing_lib.io import atomic_write_json
    from racing_lib.track import load_track
    from racing_lib.tuning import TuningSettings, config_spec, tune_weights

    track = load_track(args.track)
    _say(f"planning {track.name} time-optimally ...")
    spec = config_spec("main", track)
    out = FilePath(args.out)
    work = out.with_name(out.stem + "_checkpoints")
    _say(f"tuning with CMA-ES: {args.budget} generations, {args.workers} workers; "
         f"checkpoints in {work}/ (rerun the same command to resume)")  # fmt: skip
    result = tune_weights(
        spec,
        seeds=(args.seed,),
        settings=TuningSettings(max_generations=args.budget, seed=args.seed),
        workers=args.workers,
        out_dir=work,
        resume=True,
        progress=True,
    )
    atomic_write_json(
        out,
        {
            "track": track.name,
            "configuration": "main",
            "best_objective": result.best_objective,
            "generations": result.generations,
            "evaluations": result.evaluations,
            "weights": result.best_weights,
        },
    )
    _say(f"best objective {result.best_objective:.3f} after {result.evaluations} laps")
    print(json.dumps(_clean(result.best_weights), indent=2))
    return 0


# --------------------------------------------------------------------------------------------------
# ablation


def cmd_ablation(args: argparse.Namespace) -> int:
    """The paper's Table I and Table II on the simulated car (cached rows are reused)."""
    from racing_lib.ablation import DEFAULT_OUT, format_table, run_ablation

    names = [n.strip() for n in args.rows.split(",") if n.strip()] if args.rows else None
    rows = run_ablation(
        names,
        track=args.track,
        trials=args.ablation_trials,
        seed=args.seed,
        out_dir=args.out or DEFAULT_OUT,
        workers=args.workers,
        spacing=args.spacing,
        progress=False,
        log=_say,
    )
    if args.json:
        # The per-row files in --out hold the profiles; stdout stays a table of numbers.
        _emit_json({"rows": [{k: v for k, v in r.items() if k != "profile"} for r in rows]})
    else:
        print(format_table(rows))
    return 0


# --------------------------------------------------------------------------------------------------
# argument parsing


def _add_track(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--track",
        default=DEFAULT_TRACK,
        help=f"built-in track name or a track CSV file (default: {DEFAULT_TRACK})",
    )


def _add_model_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-drag", action="store_true", help="plan without aerodynamic drag")
    p.add_argument(
        "--no-weight-transfer",
        action="store_true",
        help="plan without longitudinal weight transfer",
    )
    p.add_argument(
        "--lateral-weight-transfer",
        action="store_true",
        help="use the double-track model with lateral weight transfer",
    )


METHODS = ("centerline", "curvature", "time-optimal")
CONTROLLERS = ("nominal", "coupled-mpc", "decoupled-mpc")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``racing-lib`` (exposed for the docs and the tests)."""
    parser = argparse.ArgumentParser(
        prog="racing-lib",
        description="Model-based planning and control for time-trial racing (racing-lab course).",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("tracks", help="list the built-in tracks")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_tracks)

    p = sub.add_parser("plan", help="plan a lap of a track")
    _add_track(p)
    p.add_argument("--method", choices=METHODS, default="time-optimal")
    _add_model_flags(p)
    p.add_argument("--out", help="write the plan to this CSV file")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser("lap", help="drive laps in closed loop (no arguments: the main job)")
    _add_track(p)
    group = p.add_mutually_exclusive_group()
    group.add_argument("--plan", help="a plan CSV made by 'racing-lib plan --out'")
    group.add_argument("--method", choices=METHODS, default="time-optimal")
    _add_model_flags(p)
    p.add_argument("--controller", choices=CONTROLLERS, default="coupled-mpc")
    p.add_argument(
        "--no-smooth-transition",
        action="store_true",
        help="MPC ablation: linearize along the reference itself",
    )
    p.add_argument("--trials", type=int, default=1, help="number of seeded trials (default 1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first trial (default 0)")
    p.add_argument("--out", help="folder for figures, logs, the plan and summary.json")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_lap)

    p = sub.add_parser("tune", help="tune the coupled MPC's weights with CMA-ES")
    _add_track(p)
    p.add_argument("--budget", type=int, default=20, help="CMA-ES generations (default 20)")
    p.add_argument("--workers", type=int, default=2, help="parallel lap processes (default 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of CMA-ES and of the laps")
    p.add_argument("--out", default="tuned_weights.json", help="where to write the weights")
    p.set_defaults(func=cmd_tune)

    p = sub.add_parser("ablation", help="the paper's Table I and II (cached rows are reused)")
    p.add_argument("--track", help="only the rows of this track (expressway or shortcut)")
    p.add_argument("--rows", help="comma-separated row names, e.g. main,no-drag (default: all)")
    # Its own dest: the default (10, or 2 in fast mode) is decided by racing_lib.ablation.
    p.add_argument(
        "--trials",
        dest="ablation_trials",
        type=int,
        metavar="N",
        help="seeded trials per row (default 10; 2 in fast mode)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the first trial (default 0)")
    p.add_argument("--workers", type=int, default=2, help="parallel lap processes (default 2)")
    p.add_argument("--out", help="cache folder of rows and plans (default runs/ablation)")
    p.add_argument(
        "--spacing", type=float, help="plan node spacing in m (default: the planners' 3 m)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_ablation)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``racing-lib`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "trials", 1) < 1:
        parser.error("--trials must be at least 1")
    try:
        return int(args.func(args))
    except RacingLibError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            "interrupted: files already written are complete (writes are atomic)", file=sys.stderr
        )
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
