"""The tables: rows as the paper prints them, the shipped full-mode table, and the stale rows."""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Iterable, Mapping, Sequence
from importlib import resources
from pathlib import Path as FilePath
from typing import Any

from racing_lib.config import fast_mode
from racing_lib.errors import RacingLibError
from racing_lib.experiments.ablation.keys import (
    code_digests,
    compact_json,
    digest,
    plan_key_inputs,
    row_key_inputs,
)
from racing_lib.experiments.ablation.rows import TableRow, ablation_rows, format_number
from racing_lib.experiments.ablation.runner import DEFAULT_OUT, resolve_tracks, run_ablation
from racing_lib.experiments.configs import (
    tuned_weights,
)
from racing_lib.geometry import Track
from racing_lib.io import atomic_write_text, data_file
from racing_lib.provenance import environment

__all__ = [
    "SHIPPED_TABLE_FILE",
    "TABLE_FORMAT",
    "TableFile",
    "format_table",
    "generate_ablation_table",
    "known_best_lap",
    "load_table",
    "shipped_table",
    "shipped_table_file",
    "shipped_table_header",
    "shipped_table_path",
    "stale_rows",
    "table_records",
    "table_text",
]
#: Version of the table file: 2 added the provenance header and a checksum per row.
TABLE_FORMAT = 2
#: The shipped full-mode table, in ``racing_lib/data``.
SHIPPED_TABLE_FILE = "ablation_table.json"
#: A table file's JSON object: its header (``format``, ``created_utc``, ``provenance``,
#: ``fast_mode``, ``trials``, ``workers``, ``wall_time_s``, and ``probes`` once restamped) and,
#: as :func:`load_table` returns it, its ``rows``. Its values are numbers, strings, lists and
#: nested objects, hence ``Any``.
TableFile = dict[str, Any]


# --------------------------------------------------------------------------------------------------
# The table as the paper prints it


def table_records(rows: Iterable[TableRow]) -> list[dict[str, str]]:
    """The paper's columns as formatted text, one dict per row.

    Columns: ``row``, ``planned lap [s]``, ``closed-loop lap [s]`` (mean +- std (min)),
    ``v_x MAE [m/s]`` and ``e_y MAE [m]`` (mean +- std (max) over the control steps of all
    trials), ``wall contacts`` (total over the trials, and per lap), ``completed``.
    """
    out = []
    for r in rows:
        mean = r.get("lap_time_mean_s")
        lap = (
            f"{mean:.2f} ± {r['lap_time_std_s']:.3f} ({r['lap_time_min_s']:.2f})"
            if mean is not None
            else "-"
        )
        vx = (
            f"{format_number(r.get('vx_mae_mps'), 3)} ± "
            f"{format_number(r.get('vx_mae_std_mps'), 3)} "
        )
        vx += f"({format_number(r.get('vx_max_err_mps'), 2)})"
        ey = f"{format_number(r.get('ey_mae_m'), 3)} ± {format_number(r.get('ey_mae_std_m'), 3)} "
        ey += f"({format_number(r.get('ey_max_m'), 2)})"
        walls = f"{r['wall_contacts']} ({format_number(r.get('wall_contacts_per_lap'), 1)}/lap)"
        out.append(
            {
                "row": str(r["name"]),
                "planned lap [s]": f"{r['planned_lap_time_s']:.2f}",
                "closed-loop lap [s]": lap,
                "v_x MAE [m/s]": vx,
                "e_y MAE [m]": ey,
                "wall contacts": walls,
                "completed": f"{r['completed']}/{r['trials']}",
            }
        )
    return out


def format_table(
    rows: Iterable[TableRow],
    markdown: bool = False,
    sources: Sequence[str] | None = None,
) -> str:
    """The table as text (aligned columns) or as a Markdown table (for a notebook).

    Parameters
    ----------
    rows : iterable of TableRow
        Rows of :func:`run_ablation` or :func:`shipped_table`.
    markdown : bool
        Markdown table (``IPython.display.Markdown`` renders it) instead of plain text.
    sources : sequence of str, optional
        Where each row comes from (``'shipped'``, ``'recomputed'``): an extra last column.
    """
    records = table_records(rows)
    if sources is not None:
        records = [{**r, "source": src} for r, src in zip(records, sources, strict=True)]
    if not records:
        return "(no rows)"
    cols = list(records[0])
    if markdown:
        lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        lines += ["| " + " | ".join(r[c] for c in cols) + " |" for r in records]
        return "\n".join(lines)
    widths = {c: max(len(c), *(len(r[c]) for r in records)) for c in cols}
    lines = ["  ".join(c.ljust(widths[c]) for c in cols)]
    lines.append("  ".join("-" * widths[c] for c in cols))
    lines += ["  ".join(r[c].ljust(widths[c]) for c in cols) for r in records]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------------
# The shipped table


def shipped_table_path() -> FilePath:
    """Where the shipped table lives: ``racing_lib/data/ablation_table.json`` in the package."""
    return data_file(SHIPPED_TABLE_FILE)


def load_table(path: str | os.PathLike[str]) -> TableFile:
    """A table file written by :func:`generate_ablation_table` (the whole object).

    Returns
    -------
    TableFile
        ``format``, ``created_utc``, ``fast_mode``, ``trials``, ``wall_time_s`` and ``rows``.
    """
    try:
        data = json.loads(FilePath(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise RacingLibError(
            f"cannot read the ablation table {os.fspath(path)!r} ({exc}); regenerate it with "
            "racing_lib.experiments.ablation.generate_ablation_table()."
        ) from exc
    if not isinstance(data, dict) or not isinstance(data.get("rows"), list):
        raise RacingLibError(
            f"{os.fspath(path)!r} is not an ablation table (no 'rows'); regenerate it with "
            "racing_lib.experiments.ablation.generate_ablation_table()."
        )
    if int(data.get("format", 0)) < TABLE_FORMAT:
        raise RacingLibError(
            f"the ablation table {os.fspath(path)!r} has format {data.get('format')}, from before "
            "tables recorded their provenance and row checksums; regenerate it with "
            "racing_lib.experiments.ablation.generate_ablation_table()."
        )
    for row in data["rows"]:
        if not isinstance(row, dict) or row.get("sha256") != _row_digest(row):
            name = row.get("name", "?") if isinstance(row, dict) else "?"
            raise RacingLibError(
                f"row {name!r} of the ablation table {os.fspath(path)!r} fails its checksum: "
                "its numbers were changed after the table was made, so none of them can be "
                "trusted; restore the file (git checkout) or recompute the row with "
                f"`racing-lib ablation --recompute {name}`."
            )
    return data


def shipped_table_header() -> TableFile:
    """The shipped table's header.

    Format, date, trials, wall time and ``provenance`` (the machine, BLAS kernel and package
    versions that made it, see :func:`racing_lib.provenance.environment`).
    """
    data = shipped_table_file()
    return {k: v for k, v in data.items() if k != "rows"}


def shipped_table_file() -> TableFile:
    """The shipped table's whole file (header and rows), checked (see :func:`load_table`)."""
    ref = data_file(SHIPPED_TABLE_FILE)
    if not ref.is_file():
        raise RacingLibError(
            f"racing_lib/data/{SHIPPED_TABLE_FILE} is not shipped yet; compute it with "
            "racing_lib.experiments.ablation.generate_ablation_table(workers=2), or run rows "
            "with run_ablation()."
        )
    with resources.as_file(ref) as path:
        return load_table(path)


def known_best_lap(track: Track) -> float | None:
    """The best possible lap of the simulated car on ``track``, s, where it is known.

    From the shipped table's ``best-lap`` row (an NLP on the car's own equations,
    :mod:`racing_lib.planning.best_lap`), when the track is the one it was planned on.
    """
    for row in shipped_table():
        if row.get("name") == "best-lap" and row.get("track_checksum") == track.checksum():
            return float(row["planned_lap_time_s"])
    return None


def shipped_table() -> list[TableRow]:
    """The rows of the full-mode table shipped in ``racing_lib/data/ablation_table.json``.

    Loads in milliseconds; notebook 07 reads it instead of recomputing (about five minutes on two
    cores). :func:`stale_rows` tells which rows the current code would compute differently.

    Raises
    ------
    RacingLibError
        No table is shipped yet (make it with :func:`generate_ablation_table`).
    """
    return shipped_table_file()["rows"]


def stale_rows(rows: Iterable[TableRow], tracks: Mapping[str, Track] | None = None) -> list[str]:
    """Names of the rows that the current code and data would not reproduce.

    A row is stale when its cache key differs from the one computed now from the same seeds and
    plan spacing (the weights, model parameters, track or source code changed since it was made).
    """
    by_name = {r.name: r for r in ablation_rows()}
    code = code_digests()
    stale = []
    for row in rows:
        spec = by_name.get(str(row.get("name")))
        if spec is None:
            stale.append(str(row.get("name")))
            continue
        trk = resolve_tracks([spec], tracks)[spec.track]
        spacing = (row.get("plan") or {}).get("spacing_m")
        plan_key = digest(plan_key_inputs(spec, trk, spacing, code))
        weights = tuned_weights(spec.config)
        inputs = row_key_inputs(spec, trk, plan_key, weights, row["seeds"], code)
        inputs["fast_mode"] = bool(row.get("fast_mode", False))  # judge the row on its own terms
        if digest(inputs) != row.get("key"):
            stale.append(spec.name)
    return stale


def _row_digest(row: TableRow) -> str:
    """SHA-256 of a row's JSON (its own ``sha256`` field left out)."""
    return hashlib.sha256(
        compact_json({k: v for k, v in row.items() if k != "sha256"}).encode("utf-8")
    ).hexdigest()


def table_text(header: TableFile, rows: Sequence[TableRow]) -> str:
    """JSON with one row per line: small diffs when a row changes, still one JSON object.

    Each row carries the checksum of its own numbers, so that :func:`load_table` refuses a row
    edited by hand instead of showing it.
    """
    head = ",\n".join(f"{json.dumps(k)}: {json.dumps(v)}" for k, v in sorted(header.items()))
    signed = [{**r, "sha256": _row_digest(r)} for r in rows]
    body = ",\n".join(compact_json(r) for r in signed)
    return "{\n" + head + ',\n"rows": [\n' + body + "\n]\n}\n"


def generate_ablation_table(
    workers: int = 2,
    *,
    out_dir: str | os.PathLike[str] | None = DEFAULT_OUT,
    target: str | os.PathLike[str] | None = None,
    progress: bool = True,
    # Any: forwarded to run_ablation, whose keywords have different types (see **kwargs below).
    **kwargs: Any,
) -> list[TableRow]:
    """Recompute every row (reusing the cache) and write the shipped table (maintainers).

    Run after a change to the planner, the MPC, the car or the tuned weights, then commit
    ``racing_lib/data/ablation_table.json``. Rows already in ``out_dir`` with a matching key are
    reused, so an interrupted run continues where it stopped.

    Parameters
    ----------
    workers : int
        Local worker processes for the laps.
    out_dir : path or None
        The cache folder (see :func:`run_ablation`).
    target : path, optional
        The file written (default: ``racing_lib/data/ablation_table.json`` of the source tree
        this module was imported from).
    progress : bool
        Progress bar.
    **kwargs
        More :func:`run_ablation` arguments (``trials``, ``seed``, ``executor``, ``log``, ...).

    Raises
    ------
    RacingLibError
        Fast mode is on and the target is the shipped file (the shipped table is full-mode).
    """
    path = FilePath(target) if target is not None else shipped_table_path()
    if fast_mode() and target is None:
        raise RacingLibError(
            "generate_ablation_table writes the shipped full-mode table, but fast mode is on "
            "(RACING_LIB_FAST); unset it, or pass target= to write somewhere else."
        )
    tic = time.perf_counter()
    rows = run_ablation(out_dir=out_dir, workers=workers, progress=progress, **kwargs)
    env = environment()
    header = {
        "format": TABLE_FORMAT,
        "created_utc": env["created_utc"],
        "provenance": env,
        "fast_mode": fast_mode(),
        "trials": max((int(r["trials"]) for r in rows), default=0),
        "workers": workers,
        "wall_time_s": round(time.perf_counter() - tic, 1),
    }
    atomic_write_text(path, table_text(header, rows))
    return rows
