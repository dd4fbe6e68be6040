"""The racetrack-database CSV format: reading its rows, writing a track's file."""

from __future__ import annotations

import math
from pathlib import Path as _FsPath

from racing_lib.errors import TrackError
from racing_lib.io import atomic_write_text

__all__ = ["CSV_COLUMNS", "read_track_rows", "write_track_text"]

#: Column names of the racetrack-database format; ``z_m`` (elevation) is optional.
CSV_COLUMNS = ("x_m", "y_m", "w_tr_right_m", "w_tr_left_m")


def read_track_rows(fpath: _FsPath) -> tuple[list[tuple[int, list[float]]], bool]:
    """Parse a racetrack-database CSV into (line number, values) rows; validate columns."""
    where = f"Track file {str(fpath)!r}"
    if not fpath.exists():
        raise TrackError(
            f"{where} does not exist; check the path, or use a built-in track name "
            "(racing_lib.tracks.builtin_track_names() lists them)."
        )
    try:
        # utf-8-sig: a byte-order mark, as some spreadsheet programs write, is dropped.
        text = fpath.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as err:
        raise TrackError(
            f"{where} cannot be read ({err}); check that it is a readable text CSV."
        ) from None
    lines = text.splitlines()
    header_idx = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if header_idx is None:
        raise TrackError(f"{where} is empty; expected the header '# {','.join(CSV_COLUMNS)}'.")
    names = [c.strip() for c in lines[header_idx].lstrip().lstrip("#").split(",")]
    expected = list(CSV_COLUMNS)
    if names not in (expected, [*expected, "z_m"]):
        raise TrackError(
            f"{where}, line {header_idx + 1}: wrong columns {names}; expected the header "
            f"'# {','.join(CSV_COLUMNS)}' (optionally ',z_m' for elevation)."
        )
    ncol = len(names)
    rows: list[tuple[int, list[float]]] = []
    for i in range(header_idx + 1, len(lines)):
        raw = lines[i].strip()
        if not raw or raw.startswith("#"):
            continue
        parts = raw.split(",")
        if len(parts) != ncol:
            raise TrackError(
                f"{where}, line {i + 1}: {len(parts)} values, expected {ncol} "
                f"({','.join(names)}); fix the row."
            )
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise TrackError(
                f"{where}, line {i + 1}: {raw!r} is not numeric; every row needs {ncol} numbers."
            ) from None
        if not all(math.isfinite(v) for v in vals):
            raise TrackError(
                f"{where}, line {i + 1}: NaN or infinite value in {raw!r}; give finite metres."
            )
        rows.append((i + 1, vals))
    return rows, ncol == 5


def write_track_text(target: _FsPath, text: str) -> None:
    """Write text to ``target`` atomically, with a clear error if its folder does not exist."""
    folder = target.parent if str(target.parent) else _FsPath(".")
    if not folder.is_dir():
        raise TrackError(f"Cannot write {str(target)!r}: folder {str(folder)!r} does not exist.")
    atomic_write_text(target, text)
