"""``racing-lib tracks``: list the built-in tracks, or generate circuits into a folder."""

from __future__ import annotations

import argparse
from pathlib import Path as FilePath
from typing import Any

import numpy as np

from racing_lib.errors import RacingLibError
from racing_lib.face.console import _emit_json, _say
from racing_lib.face.output_places import check_output_dir

__all__ = ["add_tracks_parser", "cmd_tracks", "track_row"]


def track_row(name: str, track: Any) -> dict[str, Any]:
    """One row of the track table: length, width range, tightest radius, elevation range."""
    s = np.linspace(0.0, track.length, 2000, endpoint=False)
    width = track.width_left(s) + track.width_right(s)
    kappa = np.abs(track.centerline.curvature(s))
    z = track.elevation(s)
    return {
        "name": name,
        "length_m": round(float(track.length), 1),
        "width_min_m": round(float(width.min()), 2),
        "width_max_m": round(float(width.max()), 2),
        "min_radius_m": round(float(1.0 / kappa.max()), 1),
        "elevation_range_m": round(float(z.max() - z.min()), 2),
        "corners": len(track.corners),
        "boundary": track.boundary,
    }


def cmd_tracks(args: argparse.Namespace) -> int:
    """List the built-in tracks, or write ``--generate N`` circuits to ``--out``."""
    if args.generate is not None:
        return _generate(args)
    # Per command: the built-in tracks are not needed for --help (see racing_lib.face.cli).
    from racing_lib.tracks import builtin_track_names, load_track

    rows = [track_row(name, load_track(name)) for name in builtin_track_names()]
    _print_rows(rows, args.json)
    return 0


def _generate(args: argparse.Namespace) -> int:
    """Write circuits with seeds S, S+1, ..., S+N-1 as racetrack-database CSV files."""
    from racing_lib.tracks.generator import CircuitSpec, generate

    if args.generate < 1:
        raise RacingLibError(f"--generate must be at least 1 circuit, got {args.generate}.")
    if args.seed < 0:
        raise RacingLibError(f"--seed must be >= 0, got {args.seed}.")
    if not args.out:
        raise RacingLibError("--generate needs --out DIR, the folder the circuits are written to.")
    spec = CircuitSpec(
        length=tuple(args.length), width=tuple(args.width), min_radius=args.min_radius,
        grade=args.grade,
    )  # fmt: skip
    spec.check()  # an impossible size is refused before any folder is made
    check_output_dir(args.out)
    folder = FilePath(args.out)
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in range(args.seed, args.seed + args.generate):
        name = f"generated-{seed}"
        track = generate(seed, spec, name=name)
        target = folder / f"{name}.csv"
        track.to_csv(target)
        row = track_row(name, track)
        row["file"] = str(target)
        rows.append(row)
        if not args.json:
            _say(f"wrote {target} ({row['length_m']:.0f} m)")
    _print_rows(rows, args.json)
    return 0


def _print_rows(rows: list[dict[str, Any]], as_json: bool) -> None:
    if as_json:
        _emit_json({"tracks": rows})
        return
    name_width = max(12, *(len(r["name"]) for r in rows))
    print(f"{'name':<{name_width}} {'length':>9} {'width':>13} {'min R':>8} {'dz':>7}  boundary")
    for r in rows:
        print(
            f"{r['name']:<{name_width}} {r['length_m']:>7.1f} m "
            f"{r['width_min_m']:>5.1f}-{r['width_max_m']:<5.1f}m "
            f"{r['min_radius_m']:>6.1f} m {r['elevation_range_m']:>5.1f} m  {r['boundary']}"
        )


def add_tracks_parser(sub: Any) -> None:
    """The ``tracks`` subcommand and its flags."""
    p = sub.add_parser(
        "tracks", help="list the built-in tracks, or generate circuits (--generate N --out DIR)"
    )
    p.add_argument(
        "--generate", type=int, metavar="N", help="write N random circuits to --out instead"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the first circuit (default 0)")
    p.add_argument("--out", metavar="DIR", help="folder for the generated circuits' CSV files")
    p.add_argument(
        "--length", type=float, nargs=2, default=(2000.0, 7000.0), metavar=("MIN", "MAX"),
        help="lap length range in m (default 2000 7000)",
    )  # fmt: skip
    p.add_argument(
        "--width", type=float, nargs=2, default=(8.0, 15.0), metavar=("MIN", "MAX"),
        help="road width range in m (default 8 15)",
    )  # fmt: skip
    p.add_argument(
        "--min-radius", type=float, default=15.0, help="tightest hairpin radius in m (default 15)"
    )
    p.add_argument("--grade", action="store_true", help="give the circuits hills (up to 6 %%)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_tracks)
