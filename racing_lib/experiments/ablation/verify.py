"""Whether the shipped table still holds, judged by what the code computes, not by its source text.

A row's cache key hashes the source of the code that made it, so a refactor that moves no number
still changes every key. Re-running the whole table (minutes) to find that out is wasteful; this
module settles it with one seeded lap per row instead:

* a row whose key matches is **current**;
* a row whose key moved is recomputed for its first seed only, and its **probe** (the planned lap
  time and every number of that first lap except the controller's wall-clock times, bit for bit)
  compared with the table's: equal means **reproduced** (the code changed, its numbers did not),
  different means **moved** (regenerate the table);
* probes are only comparable on one BLAS kernel (the solvers' floating point depends on it), so
  the table's own first laps are the probes of the kernel that made it, and the header keeps the
  probes of other kernels, recorded by :func:`restamp_table` while the code reproduced the table.
  On a kernel with no probe a moved key is **unverifiable** and says how to settle it.

:func:`restamp_table` writes the new keys into the table when every moved row reproduced, so the
next check is instant again; it refuses when a number moved.
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path as FilePath

from racing_lib.errors import RacingLibError
from racing_lib.experiments.ablation.keys import (
    code_digests,
    digest,
    plan_key_inputs,
    row_key_inputs,
)
from racing_lib.experiments.ablation.rows import TableRow, ablation_rows
from racing_lib.experiments.ablation.runner import resolve_tracks, run_ablation
from racing_lib.experiments.ablation.table import (
    TableFile,
    load_table,
    shipped_table_file,
    shipped_table_path,
    stale_rows,
    table_text,
)
from racing_lib.experiments.configs import tuned_weights
from racing_lib.io import atomic_write_text
from racing_lib.provenance import environment

__all__ = [
    "TIMING_FIELDS",
    "RowCheck",
    "blas_kernel",
    "probe",
    "restamp_table",
    "verify_table",
]

#: Fields of a lap's metrics that are wall-clock times, not results: left out of a probe.
TIMING_FIELDS = ("solve_time_ms_median", "solve_time_ms_p99")


@dataclass(frozen=True)
class RowCheck:
    """The verdict on one row of the table.

    Attributes
    ----------
    name : str
        The row.
    status : str
        ``'current'`` (its key matches), ``'reproduced'`` (the key moved, the first lap did not),
        ``'moved'`` (the first lap or the plan differs) or ``'unverifiable'`` (the key moved and
        this BLAS kernel has no probe to compare with).
    detail : str
        What was compared, or what to do.
    """

    name: str
    status: str
    detail: str = ""

    @property
    def ok(self) -> bool:
        """The row's numbers are what the current code computes."""
        return self.status in ("current", "reproduced")


def blas_kernel() -> str:
    """The BLAS library and kernel of this process (as the table's provenance names it)."""
    return str(environment()["blas"])


def probe(row: TableRow) -> str:
    """Digest of a row's plan and first lap: every number but the wall-clock times.

    The planned lap time, the first lap's metrics and the row's ``profile`` (the first seed's lap
    and the plan along the track, which chapter 07 draws). Two runs of the same code on the same
    BLAS kernel give the same probe; a change of a single bit anywhere in the plan or the lap
    almost surely changes one of these numbers, and with it the probe. The statistics pooled over
    all seeds are not in it: a row whose first lap reproduced is taken to reproduce its others.
    """
    first = row["trial_metrics"][0]
    lap = {k: v for k, v in first.items() if k not in TIMING_FIELDS}
    return digest(
        {
            "planned_lap_time_s": row["planned_lap_time_s"],
            "first_lap": lap,
            "profile": row.get("profile"),
        }
    )


def _reference_probes(header: TableFile, rows: Sequence[TableRow]) -> dict[str, str]:
    """The probes this kernel can be compared with: the table's own, or the header's record."""
    kernel = blas_kernel()
    if header.get("provenance", {}).get("blas") == kernel:
        return {str(r["name"]): probe(r) for r in rows}
    return dict(header.get("probes", {}).get(kernel, {}))


def _recompute_first_laps(
    names: Sequence[str], rows: Mapping[str, TableRow], workers: int
) -> dict[str, TableRow]:
    """Each named row recomputed for its first seed only, by name.

    Through a scratch cache folder, as the table was made: each plan is driven as its file
    stores it (the nodes to nine digits), so the laps are those of the table, not of the
    unrounded plan.
    """
    out: dict[str, TableRow] = {}
    # Rows are grouped by their first seed and plan spacing, as run_ablation takes one of each.
    groups: dict[tuple[int, float | None], list[str]] = {}
    for name in names:
        row = rows[name]
        spacing = (row.get("plan") or {}).get("spacing_m")
        groups.setdefault((int(row["seeds"][0]), spacing), []).append(name)
    quiet = logging.getLogger("racing_lib").level
    logging.getLogger("racing_lib").setLevel(logging.ERROR)  # fallbacks are counted, not shown
    try:
        with tempfile.TemporaryDirectory(prefix="racing-lib-verify-") as scratch:
            for (seed, spacing), group in groups.items():
                done = run_ablation(
                    group, trials=1, seed=seed, spacing=spacing, out_dir=scratch,
                    workers=workers, progress=False,
                )  # fmt: skip
                out.update({str(r["name"]): r for r in done})
    finally:
        logging.getLogger("racing_lib").setLevel(quiet)
    return out


def verify_table(
    rows: Sequence[TableRow] | None = None,
    header: TableFile | None = None,
    *,
    workers: int = 2,
    log: Callable[[str], None] | None = None,
) -> tuple[list[RowCheck], dict[str, TableRow]]:
    """Judge every row of a table (default: the shipped one) against the current code.

    Rows whose key matches cost nothing; the others are recomputed for their first seed (about
    a minute for the whole table on two cores, against the full regeneration's several).

    Parameters
    ----------
    rows : sequence of TableRow, optional
    header : TableFile, optional
        The table's rows and header (default: the shipped table's).
    workers : int
        Worker processes for the recomputed laps.
    log : callable, optional
        Receives one line per row.

    Returns
    -------
    checks : list of RowCheck
        One verdict per row, in table order.
    recomputed : dict of str to TableRow
        The recomputed rows (one trial each) by name.
    """
    if rows is None or header is None:
        data = shipped_table_file()
        rows = data["rows"] if rows is None else rows
        header = {k: v for k, v in data.items() if k != "rows"} if header is None else header
    say = log or (lambda _line: None)
    by_name = {str(r["name"]): r for r in rows}
    stale = set(stale_rows(rows))
    reference = _reference_probes(header, rows)
    runnable = [n for n in by_name if n in stale and n in reference]
    recomputed = _recompute_first_laps(runnable, by_name, workers) if runnable else {}
    checks = []
    for name in by_name:
        if name not in stale:
            check = RowCheck(name, "current", "its key matches the current code and inputs")
        elif name not in reference:
            check = RowCheck(
                name,
                "unverifiable",
                f"its key moved and the BLAS kernel here ({blas_kernel()}) has no probe to "
                "compare with: run racing_lib.experiments.ablation.restamp_table() on the "
                f"kernel that made the table ({header.get('provenance', {}).get('blas')}) or "
                "on one the header records, or regenerate the table",
            )
        elif probe(recomputed[name]) == reference[name]:
            check = RowCheck(name, "reproduced", "its first lap is the same to the last bit")
        else:
            new, old = recomputed[name], by_name[name]
            check = RowCheck(
                name,
                "moved",
                f"its first lap moved (lap {old['trial_metrics'][0]['lap_time_s']!r} s -> "
                f"{new['trial_metrics'][0]['lap_time_s']!r} s, plan "
                f"{old['planned_lap_time_s']!r} s -> {new['planned_lap_time_s']!r} s): "
                "regenerate the table",
            )
        say(f"{name}: {check.status} ({check.detail})")
        checks.append(check)
    return checks, recomputed


def _restamped(row: TableRow, code: Mapping[str, str]) -> TableRow:
    """A row with the keys the current code and inputs give it (its numbers unchanged)."""
    spec = next(r for r in ablation_rows() if r.name == row["name"])
    track = resolve_tracks([spec], None)[spec.track]
    spacing = (row.get("plan") or {}).get("spacing_m")
    plan_key = digest(plan_key_inputs(spec, track, spacing, code))
    inputs = row_key_inputs(spec, track, plan_key, tuned_weights(spec.config), row["seeds"], code)
    inputs["fast_mode"] = bool(row.get("fast_mode", False))
    out = {k: v for k, v in row.items() if k != "sha256"}
    plan = {**(row.get("plan") or {}), "key": plan_key}
    return {**out, "key": digest(inputs), "key_inputs": inputs, "plan": plan}


def restamp_table(
    *,
    workers: int = 2,
    target: str | os.PathLike[str] | None = None,
    log: Callable[[str], None] | None = None,
) -> list[RowCheck]:
    """Give the shipped table the keys of the current code, if its numbers are still the code's.

    Every row whose key moved is recomputed for its first seed (:func:`verify_table`). If each
    reproduces bit for bit, the rows are written back with their new keys and numbers untouched,
    and this kernel's probes are recorded in the header, so that a later change can be verified
    on this machine too. If any moved, or cannot be verified here, nothing is written.

    Parameters
    ----------
    workers : int
        Worker processes for the recomputed laps.
    target : path, optional
        The table file (default: the shipped ``racing_lib/data/ablation_table.json``).
    log : callable, optional
        Receives one line per row.

    Raises
    ------
    RacingLibError
        A row moved or cannot be verified on this kernel (the message names them and what to do).
    """
    path = FilePath(target) if target is not None else shipped_table_path()
    data = shipped_table_file() if target is None else load_table(path)
    rows = data["rows"]
    header = {k: v for k, v in data.items() if k != "rows"}
    checks, recomputed = verify_table(rows, header, workers=workers, log=log)
    bad = [c for c in checks if not c.ok]
    if bad:
        raise RacingLibError(
            "the table cannot be restamped: "
            + "; ".join(f"{c.name} {c.status} ({c.detail})" for c in bad)
        )
    code = code_digests()
    kernel = blas_kernel()
    probes = dict(header.get("probes", {}))
    if header.get("provenance", {}).get("blas") != kernel:
        # Every row now verified on this kernel: its probes are the recomputed first laps, or, for
        # rows whose key never moved, laps of the very code that made the table.
        missing = [str(r["name"]) for r in rows if str(r["name"]) not in recomputed]
        if missing:
            recomputed.update(_recompute_first_laps(missing, {r["name"]: r for r in rows}, workers))
        probes[kernel] = {str(r["name"]): probe(recomputed[str(r["name"])]) for r in rows}
    header = {**header, "probes": probes}
    atomic_write_text(path, table_text(header, [_restamped(r, code) for r in rows]))
    return checks
