"""``racing-lib tune``: CMA-ES on the coupled MPC's weights, over circuits and seeds.

The laps run in local processes or on a Dask cluster (``--scheduler``). Paper Section
"Hyperparameter Optimization"; chapter 06.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path as FilePath
from typing import Any

from racing_lib.errors import RacingLibError
from racing_lib.face.console import _clean, _say
from racing_lib.io import atomic_write_json, jsonable

__all__ = ["add_tune_parser", "checkpoint_dir", "cmd_tune", "tune_tracks"]


def checkpoint_dir(out: FilePath) -> FilePath:
    """Where ``tune --out FILE`` keeps its checkpoints: a folder beside FILE."""
    return out.with_name(out.stem + "_checkpoints")


def tune_tracks(names: list[str]) -> list[Any]:
    """The circuits of ``--tracks``: built-in names, CSV files, or folders of CSV files.

    Raises
    ------
    RacingLibError
        A folder without circuits, an unknown name or a broken file (one line each), or the same
        circuit twice.
    """
    from racing_lib.tracks import load_track

    sources: list[str] = []
    for name in names:
        folder = FilePath(name)
        if folder.is_dir():
            files = sorted(folder.glob("*.csv"))
            if not files:
                raise RacingLibError(
                    f"--tracks {name}: no track CSV files (*.csv) in this folder; give a folder "
                    "of racetrack-database files, or make some with `racing-lib tracks "
                    f"--generate 20 --out {name}`."
                )
            sources += [str(f) for f in files]
        else:
            sources.append(name)
    tracks = []
    seen: dict[str, str] = {}
    for source in sources:
        track = load_track(source)
        key = track.checksum()
        if key in seen:
            raise RacingLibError(
                f"--tracks: {source} is the same circuit as {seen[key]}; give each circuit once."
            )
        seen[key] = source
        tracks.append(track)
    return tracks


def _same_problem(work: FilePath, tracks: list[Any], seeds: tuple[int, ...]) -> None:
    """Record what the checkpoints in ``work`` tune, or refuse checkpoints of another problem.

    CMA-ES's own checkpoint knows its search space, not the laps that score a candidate: resumed
    on other circuits or seeds, it would carry over a best candidate scored on something else.
    """
    problem = {
        "configuration": "main",
        "tracks": [[t.name, t.checksum()] for t in tracks],
        "seeds": list(seeds),
    }
    marker = work / "problem.json"
    if marker.is_file():
        try:
            kept = json.loads(marker.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            kept = None
        if kept != problem:
            raise RacingLibError(
                f"the checkpoints in {work}/ tune other circuits or seeds than these; give "
                "another --out, or delete that folder to start this tuning afresh."
            )
        return
    atomic_write_json(marker, problem)


def cmd_tune(args: argparse.Namespace) -> int:
    """Tune the coupled MPC's weights on the time-optimal plans of one or more circuits."""
    # Per command (see racing_lib.face.cli): the experiments load the controllers (scipy.signal,
    # OSQP), a third of a second.
    from racing_lib.experiments.configs import config_spec
    from racing_lib.experiments.tuning import tune_weights
    from racing_lib.optim.cmaes import TuningSettings

    tracks = tune_tracks(args.tracks or [args.track])
    seeds = tuple(range(args.seed, args.seed + args.seeds))
    out = FilePath(args.out)
    work = checkpoint_dir(out)
    client = None
    if args.scheduler is not None:
        from racing_lib.face.cluster import connect_scheduler

        client = connect_scheduler(args.scheduler)
        where = f"the Dask cluster at {args.scheduler}"
    else:
        where = f"{args.workers} local processes"
    try:
        _same_problem(work, tracks, seeds)
        specs = []
        for track in tracks:
            _say(f"planning {track.name} time-optimally ...")
            specs.append(config_spec("main", track))
        settings = TuningSettings(max_generations=args.budget, seed=args.seed, popsize=args.popsize)
        laps = len(specs) * len(seeds)
        _say(f"tuning with CMA-ES on {where}: {args.budget} generations; each candidate drives "
             f"{laps} laps ({len(specs)} circuits x {len(seeds)} seeds); checkpoints in {work}/ "
             "(rerun the same command to resume)")  # fmt: skip
        result = tune_weights(
            specs if len(specs) > 1 else specs[0],
            seeds=seeds,
            settings=settings,
            executor=client,
            workers=args.workers,
            out_dir=work,
            resume=True,
            progress=True,
        )
    finally:
        if client is not None:
            client.close()
    atomic_write_json(
        out,
        jsonable(
            {
                "tracks": [t.name for t in tracks],
                "seeds": list(seeds),
                "configuration": "main",
                "best_objective": result.best_objective,
                "generations": result.generations,
                "evaluations": result.evaluations,
                "laps": result.evaluations * laps,
                "weights": result.best_weights,
            }
        ),
    )
    _say(f"best objective {result.best_objective:.3f} after {result.evaluations * laps} laps "
         f"({result.evaluations} candidates)")  # fmt: skip
    print(json.dumps(_clean(result.best_weights), indent=2))
    return 0


def add_tune_parser(sub: Any) -> None:
    """The ``tune`` subcommand and its flags."""
    p = sub.add_parser("tune", help="tune the coupled MPC's weights with CMA-ES")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--track", default="expressway", help="one built-in track or CSV file (default expressway)"
    )
    where.add_argument(
        "--tracks", nargs="+", metavar="DIR|NAME",
        help="tune on the mean over several circuits: names, CSV files or folders of them",
    )  # fmt: skip
    p.add_argument("--seeds", type=int, default=1, help="laps per circuit and candidate (1)")
    p.add_argument("--budget", type=int, default=20, help="CMA-ES generations (default 20)")
    p.add_argument("--popsize", type=int, help="candidates per generation (CMA-ES default: 9)")
    runner = p.add_mutually_exclusive_group()
    runner.add_argument("--workers", type=int, default=2, help="local lap processes (default 2)")
    runner.add_argument(
        "--scheduler", metavar="ADDRESS",
        help="run the laps on a Dask cluster (dask scheduler / dask worker), e.g. tcp://host:8786",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="seed of CMA-ES and of the first lap")
    p.add_argument("--out", default="tuned_weights.json", help="where to write the weights")
    p.set_defaults(func=cmd_tune)
