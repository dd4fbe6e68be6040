"""``racing-lib learn``: drive, fit a model correction, re-plan, drive again (chapter 09)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from racing_lib.face.console import _emit_json, _say

__all__ = ["add_learn_parser", "cmd_learn"]


def cmd_learn(args: argparse.Namespace) -> int:
    """Run :func:`racing_lib.experiments.learning.learn` and report its iterations."""
    # Imported here, as in every command: the experiments load the controllers.
    from racing_lib.experiments.learning import LearnSettings, learn

    settings = LearnSettings(iterations=args.iterations, seeds=args.seeds, seed=args.seed)
    say = None if args.json else _say
    model = plant = None
    if args.car:
        from racing_lib.experiments.own_car import identify_car, named_car

        # Identified first (or read from its cache), as `lap --car` does; learning starts there.
        named = named_car(args.car)
        model = identify_car(named, report=say)
        plant = named.car.make_plant
    if args.out:
        _say(f"learning on {args.track}: {args.iterations} iterations of {args.seeds} laps; "
             f"kept in {args.out}/ (rerun the same command to resume)")  # fmt: skip
    run = learn(
        args.track,
        settings,
        model=model,
        car=plant,
        out=args.out,
        progress=not args.json,
        report=say,
    )
    if args.json:
        _emit_json(run.to_dict())
        return 0
    best = run.best()
    if best is None:
        print("no iteration drove clean laps")
        return 1
    gap = "" if best.gap_to_best_pct is None else f", {best.gap_to_best_pct:+.2f} % on the best lap"
    gain = run.gain_pct(best)
    gain_text = "" if gain is None else f", {gain:.2f} % faster than the identified model"
    how = (
        "the fastest clean one within its edge margins"
        if best.within_margins
        else "no clean iteration stayed within its edge margins: the fastest clean one"
    )
    print(f"result: iteration {best.iteration} ({how}), {best.driven_lap_s:.2f} s{gap}{gain_text}")
    return 0


def add_learn_parser(sub: Any, add_track: Callable[[argparse.ArgumentParser], None]) -> None:
    """The ``learn`` subcommand and its flags."""
    p = sub.add_parser(
        "learn", help="learn a model correction from laps: drive, fit, re-plan, drive again"
    )
    add_track(p)
    p.add_argument(
        "--iterations", type=int, default=5, help="learning iterations after the first (5)"
    )
    p.add_argument("--seeds", type=int, default=4, help="laps per iteration (default 4)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first lap (default 0)")
    p.add_argument(
        "--car",
        help="learn on another car than the simulated one (a name that `racing-lib lap --car` "
        "takes): identified first, or read from its kept model",
    )
    p.add_argument("--out", help="folder that keeps every iteration (resumable)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_learn)
