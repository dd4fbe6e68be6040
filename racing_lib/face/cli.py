"""The ``racing-lib`` command.

Sub-commands (see ``racing-lib --help``): ``tracks``, ``plan``, ``lap``, ``tune``, ``ablation``,
``learn``.
With ``--json`` a command prints exactly one JSON object on standard output; everything meant for a
person goes to standard error. Errors of racing_lib are printed as one line (``error: ...``) with
exit status 2, never as a traceback.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path as FilePath
from typing import Any

from racing_lib.errors import PlantError, RacingLibError
from racing_lib.face.console import _clean, _emit_json, _say
from racing_lib.face.learn_command import add_learn_parser
from racing_lib.face.output_places import (
    check_output_dir,
    check_output_file,
)
from racing_lib.face.tracks_command import add_tracks_parser
from racing_lib.face.tune_command import add_tune_parser, checkpoint_dir
from racing_lib.io import atomic_savefig, atomic_write_json
from racing_lib.model import CarModel, ModelOptions, identified_model
from racing_lib.planning import METHODS, STARTS, TimeOptimalSettings, plan
from racing_lib.plants import CARS

# The parser needs only the modules above (racing_lib.model and racing_lib.planning give its
# choices; numpy and racing_lib.io are loaded with them). Each command imports the rest of what it
# runs in its own body (tracks, experiments, the optimizer, matplotlib), so that
# `racing-lib --help` and the refusal of bad arguments stay instant.

DEFAULT_TRACK = "expressway"


# --------------------------------------------------------------------------------------------------
# plan and lap share the way a plan is obtained


def _model(args: argparse.Namespace) -> CarModel | None:
    """The model of the run: the default one with the effects on the command line.

    None when a plan file is driven and no model flag is given: the plan's own model is then
    used, the one it was made with.
    """
    options = ModelOptions(
        drag=not args.no_drag,
        longitudinal_weight_transfer=not args.no_weight_transfer,
        lateral_weight_transfer=args.lateral_weight_transfer,
    )
    if getattr(args, "plan", None) and options == ModelOptions():
        return None
    return identified_model().replace(options=options)


def _plan_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The planner knobs given on the command line (``--spacing``, ``--start``, ``--max-iter``)."""
    kwargs: dict[str, Any] = {"report": _say}
    if args.spacing is not None:
        kwargs["spacing"] = args.spacing
    if args.start is not None:
        kwargs["start"] = args.start
    if args.max_iter is not None:
        kwargs["time_optimal_settings"] = TimeOptimalSettings(max_iter=args.max_iter)
    return kwargs


def _make_plan(args: argparse.Namespace, track):
    """Plan ``track`` with the method, model options and knobs on the command line."""
    return plan(track, args.method, _model(args), **_plan_kwargs(args))


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan a lap and optionally save it as a plan CSV."""
    # Per command: the built-in tracks are not needed for --help (see the note at the top).
    from racing_lib.tracks import load_track

    track = load_track(args.track)
    _say(f"planning {track.name} ({track.length:.0f} m) with method '{args.method}' ...")
    result = _make_plan(args, track)
    traj = result.trajectory
    if args.out:
        traj.save_csv(args.out)
        _say(f"plan written to {args.out}")
    fields = result.summary(track)
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
    # Per command: the pipeline loads the controllers (scipy.signal, OSQP), a third of a second.
    from racing_lib.experiments.pipeline import race

    out_dir = FilePath(args.out) if args.out else None

    def save_log(lap) -> None:
        # Saved as each lap ends: an interrupted run of many trials keeps the laps already driven.
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            lap.log.save(str(out_dir / f"log_seed{lap.metrics.seed}.npz"))

    common = dict(
        plan_kwargs=_plan_kwargs(args),
        method=args.method,
        controller=args.controller,
        seed=args.seed,
        trials=args.trials,
        smooth_transition=not args.no_smooth_transition,
        reference=args.plan,
        progress=not args.json and args.trials == 1,
        report=_say,
        on_lap=save_log,
    )
    try:
        if args.car is None:
            result = race(args.track, model=_model(args), **common)
        else:
            result = _race_named_car(args, common)
    except PlantError as exc:
        # The car's own fate (it spun, its state diverged), not a usage error: the lap was not
        # completed, and the laps before it are saved.
        print(f"lap not completed: {exc}", file=sys.stderr)
        return 1
    report = result.summary()
    if out_dir is not None:
        _save_lap_outputs(out_dir, result.track, result.reference, result.laps, report)
        _say(f"figures, logs and summary written to {out_dir}/")
    if args.json:
        _emit_json(report)
    else:
        _print_summary(report)
    return 0 if result.completed else 1


def _race_named_car(args: argparse.Namespace, common: dict[str, Any]) -> Any:
    """``lap --car NAME``: identify the car (cached), plan with its model, race it."""
    from racing_lib.experiments.own_car import race_car

    return race_car(
        args.car,
        args.track,
        refresh=args.reidentify,
        speed_scale=args.speed_scale,
        **common,
    )


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

    # Only when a lap's figures are saved: plotting loads matplotlib.
    from racing_lib.face import plotting

    plotting.set_style()
    out_dir.mkdir(parents=True, exist_ok=True)
    trajectory.save_csv(str(out_dir / "plan.csv"))
    log = results[0].log
    ax = plotting.plot_track(track, {"plan": trajectory, "closed loop": log})
    atomic_savefig(ax.figure, out_dir / "track.png", dpi=130, bbox_inches="tight")
    plt.close(ax.figure)
    fig, axes = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    lap = log.in_lap
    plotting.plot_profiles(
        {"plan": trajectory.s, "closed loop": log.s_ref[lap]},
        {"plan": trajectory.vx, "closed loop": log.vx[lap]},
        ax=axes[0],
        ylabel="$v_x$ [m/s]",
    )
    plotting.plot_profiles(log.s_ref[lap], {"e_y": log.ey[lap]}, ax=axes[1], ylabel="$e_y$ [m]")
    atomic_savefig(fig, out_dir / "profiles.png", dpi=130, bbox_inches="tight")
    plt.close(fig)
    atomic_write_json(out_dir / "summary.json", _clean(report))


# --------------------------------------------------------------------------------------------------
# ablation


def _row_names(text: str | None) -> list[str] | None:
    return [n.strip() for n in text.split(",") if n.strip()] if text else None


def cmd_ablation(args: argparse.Namespace) -> int:
    """The paper's Table I and Table II on the simulated car.

    Shows the shipped table at once; rows recomputed with ``--recompute`` (or found recomputed in
    the ``--out`` cache folder) replace their shipped versions and are marked as such.
    """
    # Per command (see the note at the top): the tables load the experiments and the controllers
    # (scipy.signal, OSQP), a third of a second.
    from racing_lib.experiments import ablation
    from racing_lib.experiments.ablation.check import (
        compare_rows,
        format_checks,
    )
    from racing_lib.provenance import describe, environment

    shown = [r.name for r in ablation.select_rows(_row_names(args.rows), args.track)]
    # Unknown names are refused here, before any work.
    asked = _row_names(args.recompute) or []
    if "all" in asked:
        recompute = shown
    else:
        recompute = [r.name for r in ablation.select_rows(asked, args.track)] if asked else []
    # A row asked to be recomputed is shown, whatever --rows says (in table order).
    order = [r.name for r in ablation.ablation_rows()]
    shown = [n for n in order if n in shown or n in recompute]
    try:
        shipped = {r["name"]: r for r in ablation.shipped_table()}
        header = ablation.shipped_table_header()
    except RacingLibError as exc:
        if not recompute:
            raise
        _say(f"note: {exc}; showing only the recomputed rows")
        shipped, header = {}, {}
        shown = [n for n in shown if n in recompute]
    common = {
        "track": args.track,
        "trials": args.ablation_trials,
        "seed": args.seed,
        "out_dir": args.out or ablation.DEFAULT_OUT,
        "workers": args.workers,
        "spacing": args.spacing,
        "progress": False,
        "log": _say,
    }
    todo = [n for n in shown if n in recompute]
    client = None
    if todo and args.scheduler is not None:
        from racing_lib.face.cluster import connect_scheduler

        client = connect_scheduler(args.scheduler)
        common["executor"] = client.get_executor()
    try:
        fresh = {r["name"]: r for r in ablation.run_ablation(todo, **common)} if todo else {}
    finally:
        if client is not None:
            client.close()
    common.pop("executor", None)
    if FilePath(common["out_dir"]).is_dir():
        # Rows recomputed by an earlier run with these settings count as recomputed too.
        rest = [n for n in shown if n not in fresh]
        for r in ablation.run_ablation(rest, cached_only=True, **common):
            fresh[r["name"]] = r
    rows, sources, checks = [], [], []
    for name in shown:
        if name in fresh:
            rows.append(fresh[name])
            sources.append("recomputed")
            if name in shipped:
                checks += compare_rows(shipped[name], fresh[name])
        elif name in shipped:
            rows.append(shipped[name])
            sources.append("shipped")
        else:
            raise RacingLibError(
                f"row {name!r} is neither shipped nor in {common['out_dir']}; compute it with "
                f"`racing-lib ablation --recompute {name}`."
            )
    moved = [c for c in checks if not c.ok]
    made_by = header.get("provenance")
    if args.json:
        _emit_json(
            {
                "rows": [
                    {**{k: v for k, v in r.items() if k != "profile"}, "source": src}
                    for r, src in zip(rows, sources, strict=True)
                ],
                "shipped_provenance": made_by,
                "this_machine": environment() if fresh else None,
                "checks": [{**c.__dict__, "difference": c.difference, "ok": c.ok} for c in checks],
            }
        )
    else:
        print(ablation.format_table(rows, sources=sources))
        if made_by:
            print(f"shipped rows: {describe(made_by)}")
        if fresh:
            print(f"recomputed rows: {describe(environment())}")
        if checks:
            print(
                "\nrecomputed against shipped (tolerances: racing_lib.experiments.ablation.check):"
            )
            print(format_checks(checks))
    if moved and args.check:
        _say(f"error: {len(moved)} number(s) moved beyond tolerance (MOVED above).")
        return 1
    return 0


# --------------------------------------------------------------------------------------------------
# checks made before any work: a refusal after minutes of planning would lose that work


def _at_least(value: int | None, low: int, flag: str, why: str = "") -> None:
    if value is not None and value < low:
        raise RacingLibError(f"{flag} must be at least {low}, got {value}{why}.")


def _check_car_flags(args: argparse.Namespace) -> None:
    """``lap --car``: its own flags need it, and it plans with its own model."""
    if args.command != "lap":
        return
    scale = args.speed_scale
    if not (math.isfinite(scale) and 0.0 < scale <= 1.0):
        raise RacingLibError(f"--speed-scale must be in (0, 1], got {scale}.")
    if args.car is None:
        if args.reidentify or scale != 1.0:
            raise RacingLibError(
                "--reidentify and --speed-scale go with --car (another car than the simulated "
                "one); add --car NAME, or drop them."
            )
        return
    model_flags = ("no_drag", "no_weight_transfer", "lateral_weight_transfer")
    flags = [f for f in model_flags if getattr(args, f)]
    if flags:
        raise RacingLibError(
            f"--car plans with the car's own identified model, so "
            f"{', '.join('--' + f.replace('_', '-') for f in flags)} cannot apply; drop them."
        )
    if args.plan:
        raise RacingLibError(
            "--car plans with the car's own identified model, and --plan is a plan made with "
            "another; drop --plan."
        )


def check_arguments(args: argparse.Namespace) -> None:
    """Every number and output place on the command line, checked before any work starts.

    Raises
    ------
    RacingLibError
        One line naming the flag, its value and the way out.
    """
    _at_least(getattr(args, "trials", None), 1, "--trials")
    _at_least(getattr(args, "ablation_trials", None), 1, "--trials")
    _at_least(getattr(args, "seed", None), 0, "--seed", " (seeds are whole numbers >= 0)")
    _at_least(getattr(args, "budget", None), 1, "--budget", " (CMA-ES generations)")
    _at_least(getattr(args, "workers", None), 1, "--workers", " (1 runs the laps in-process)")
    _at_least(getattr(args, "max_iter", None), 1, "--max-iter")
    _at_least(getattr(args, "iterations", None), 0, "--iterations")
    _at_least(getattr(args, "seeds", None), 1, "--seeds", " (a number of laps)")
    _at_least(getattr(args, "popsize", None), 2, "--popsize", " (CMA-ES candidates per generation)")
    spacing = getattr(args, "spacing", None)
    if spacing is not None and not (math.isfinite(spacing) and 0.5 <= spacing <= 20.0):
        raise RacingLibError(
            f"--spacing must be a node spacing between 0.5 and 20 m, got {spacing} (the "
            "planners are tuned for 3 m)."
        )
    _check_car_flags(args)
    knobs = ("spacing", "start", "max_iter")
    if getattr(args, "plan", None) and any(getattr(args, k, None) is not None for k in knobs):
        raise RacingLibError(
            "--spacing, --start and --max-iter are planner settings, but --plan drives a plan "
            "made before; give them to `racing-lib plan`, or drop --plan to plan here."
        )
    if args.command == "ablation" and args.scheduler is not None and not args.recompute:
        raise RacingLibError(
            "--scheduler runs recomputed rows on a cluster; without --recompute ROWS there is "
            "nothing to run: add --recompute, or drop --scheduler."
        )
    out = getattr(args, "out", None)
    if args.command == "ablation" and getattr(args, "recompute", None) and not out:
        # Only for this command's check: the runner loads the experiments (a third of a second),
        # which a refusal of bad arguments must not wait for.
        from racing_lib.experiments.ablation.runner import DEFAULT_OUT

        check_output_dir(DEFAULT_OUT, "--out (default)")
    if out:
        if args.command in ("plan", "tune"):
            check_output_file(out)
        else:
            check_output_dir(out)
        if args.command == "tune":
            check_output_dir(str(checkpoint_dir(FilePath(out))), "--out (its checkpoints)")
    plan_file = getattr(args, "plan", None)
    try:
        found = bool(plan_file) and FilePath(plan_file).is_file()
    except OSError:
        found = False
    if plan_file and not found:
        raise RacingLibError(
            f"--plan {plan_file}: no such file (or not readable); make one with "
            f"`racing-lib plan --out {plan_file}`."
        )


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


def _add_planner_knobs(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--spacing", type=float, help="plan node spacing along the centerline in m (default 3)"
    )
    p.add_argument(
        "--start",
        choices=STARTS,
        help="start of the time-optimal NLP: the centerline at 10 m/s (cold, the default and "
        "the faster) or the curvature QP's plan (warm, the paper's two-stage planner)",
    )
    p.add_argument(
        "--max-iter",
        type=int,
        help="IPOPT iteration limit of the time-optimal NLP (default 1000)",
    )


#: The controllers' names, as racing_lib.control.CONTROLLER_NAMES says (a test keeps the two
#: equal): the parser is built without importing the controllers, which cost a third of a second.
CONTROLLERS = ("nominal", "coupled-mpc", "decoupled-mpc")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``racing-lib`` (exposed for the docs and the tests)."""
    parser = argparse.ArgumentParser(
        prog="racing-lib",
        description="Model-based planning and control for time-trial racing (racing-lab course).",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    add_tracks_parser(sub)

    p = sub.add_parser("plan", help="plan a lap of a track")
    _add_track(p)
    p.add_argument("--method", choices=METHODS, default="time-optimal")
    _add_model_flags(p)
    _add_planner_knobs(p)
    p.add_argument("--out", help="write the plan to this CSV file")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser("lap", help="drive laps in closed loop (no arguments: the main job)")
    _add_track(p)
    group = p.add_mutually_exclusive_group()
    group.add_argument("--plan", help="a plan CSV made by 'racing-lib plan --out'")
    group.add_argument("--method", choices=METHODS, default="time-optimal")
    _add_model_flags(p)
    _add_planner_knobs(p)
    p.add_argument("--controller", choices=CONTROLLERS, default="coupled-mpc")
    p.add_argument(
        "--no-smooth-transition",
        action="store_true",
        help="MPC ablation: linearize along the reference itself",
    )
    p.add_argument(
        "--car",
        help="drive another car than the simulated one: identify it (kept in ~/.cache/"
        "racing-lib/cars), plan with its model and race it; one of: " + ", ".join(CARS),
    )
    p.add_argument(
        "--reidentify",
        action="store_true",
        help="with --car: identify the car anew instead of reading its kept model",
    )
    p.add_argument(
        "--speed-scale",
        type=float,
        default=1.0,
        help="with --car: drive the plan at this share of its speeds, in (0, 1] (default 1)",
    )
    p.add_argument("--trials", type=int, default=1, help="number of seeded trials (default 1)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first trial (default 0)")
    p.add_argument("--out", help="folder for figures, logs, the plan and summary.json")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_lap)

    add_tune_parser(sub)

    add_learn_parser(sub, _add_track)

    p = sub.add_parser(
        "ablation", help="the paper's Table I and II: the shipped table, or rows recomputed"
    )
    p.add_argument("--track", help="only the rows of this track (expressway or shortcut)")
    p.add_argument("--rows", help="comma-separated row names to show, e.g. main,no-drag")
    p.add_argument(
        "--recompute",
        metavar="ROWS",
        help="recompute these rows (comma-separated, or 'all'; cached rows in --out are reused)",
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="exit 1 if a recomputed row differs from the shipped one beyond tolerance",
    )
    # Its own dest: the default (10, or 2 in fast mode) is decided by
    # racing_lib.experiments.ablation.
    p.add_argument(
        "--trials",
        dest="ablation_trials",
        type=int,
        metavar="N",
        help="seeded trials per row (default 10; 2 in fast mode)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the first trial (default 0)")
    runner = p.add_mutually_exclusive_group()
    runner.add_argument(
        "--workers", type=int, default=2, help="local lap processes for --recompute (default 2)"
    )
    runner.add_argument(
        "--scheduler", metavar="ADDRESS",
        help="recompute on a Dask cluster (dask scheduler / dask worker), e.g. tcp://host:8786",
    )  # fmt: skip
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
    try:
        check_arguments(args)
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
