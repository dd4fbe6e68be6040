"""The plan file: a plan CSV with its metadata, its model and a checksum (taught in notebook 03).

Format (version :data:`PLAN_FORMAT_VERSION`): ``#`` metadata lines (``# key: value``: format
version, track name and checksum, method, model options as JSON, the model as JSON
(:meth:`~racing_lib.model.CarModel.to_dict`, floats exact), planned lap time, line length, node
count), the header ``s_m,x_m,y_m,psi_rad,kappa_radpm,vx_mps,vy_mps,r_radps,ax_mps2,delta_rad,t_s``,
one row per node, and last a ``# sha256: ...`` line: the checksum of every line above it. The
reader recomputes it, so a truncated, edited or spliced plan is refused instead of driven.
:meth:`racing_lib.planning.Trajectory.save_csv` and :meth:`~racing_lib.planning.Trajectory.load_csv`
use this module.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from racing_lib.errors import ModelError, PlanningError
from racing_lib.geometry import Track
from racing_lib.io import atomic_write_text
from racing_lib.model.car_model import CarModel

__all__ = [
    "OLDEST_PLAN_FORMAT",
    "PLAN_COLUMNS",
    "PLAN_FIELDS",
    "PLAN_FORMAT_VERSION",
    "PlanFile",
    "plan_digest",
    "read_plan_file",
    "write_plan_file",
]

#: Version of the plan CSV format written by :meth:`Trajectory.save_csv`: 3 adds the model (a
#: ``# model:`` line of JSON); version 2 files, without it, still load, with no model.
PLAN_FORMAT_VERSION = 3
#: The oldest plan format :meth:`Trajectory.load_csv` reads (the first with a checksum).
OLDEST_PLAN_FORMAT = 2

#: The columns of a plan CSV, in order (units in the names).
PLAN_COLUMNS = (
    "s_m",
    "x_m",
    "y_m",
    "psi_rad",
    "kappa_radpm",
    "vx_mps",
    "vy_mps",
    "r_radps",
    "ax_mps2",
    "delta_rad",
    "t_s",
)
#: The Trajectory attributes of the columns, in the same order.
PLAN_FIELDS = ("s", "x", "y", "psi", "kappa", "vx", "vy", "r", "ax", "delta", "t")


@dataclass(frozen=True)
class PlanFile:
    """What a plan file holds, checked.

    Attributes
    ----------
    columns : dict of str to ndarray
        The node arrays by Trajectory attribute name (:data:`PLAN_FIELDS`).
    track_name, track_checksum, method : str
        Where the plan came from.
    model : CarModel or None
        The model it was made with (None in a version 2 file).
    planned_lap_time : float
        Lap time, s.
    line_length : float
        Length of the closed line, m.
    """

    columns: dict[str, np.ndarray]
    track_name: str
    track_checksum: str
    method: str
    model: CarModel | None
    planned_lap_time: float
    line_length: float


def write_plan_file(
    path: str | os.PathLike[str], metadata: Mapping[str, str | int], data: np.ndarray
) -> None:
    """Write a plan file atomically (temporary file, then rename).

    Parameters
    ----------
    path : path-like
        The file.
    metadata : mapping
        The ``# key: value`` lines, in order.
    data : ndarray, shape (N, 11)
        The node values, columns in the order of :data:`PLAN_COLUMNS`.
    """
    buf = io.StringIO()
    buf.write("# racing_lib plan\n")
    for key, value in metadata.items():
        buf.write(f"# {key}: {value}\n")
    buf.write(",".join(PLAN_COLUMNS) + "\n")
    np.savetxt(buf, data, delimiter=",", fmt="%.9g")
    text = buf.getvalue()
    atomic_write_text(path, text + f"# sha256: {plan_digest(text)}\n")


def read_plan_file(path: str | os.PathLike[str], track: Track | None = None) -> PlanFile:
    """Read a plan file, refusing any that is not intact.

    The checksum (which covers the header, the line length and every number) and the node
    count recorded in the file are checked against its rows, so a plan truncated (even at a
    row boundary), edited by hand or spliced from two files raises a :class:`PlanningError`
    that names the file and says to re-plan.

    Parameters
    ----------
    path : path-like
        The plan file.
    track : Track, optional
        If given, the plan must have been made for this track (same checksum); otherwise a
        :class:`PlanningError` names both tracks.
    """
    where = os.fspath(path)
    try:
        with open(path, encoding="utf-8-sig") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise PlanningError(f"cannot read plan file {where!r}: {exc}") from exc
    meta, header, rows, digest_line, covered = _split_plan_text(text)
    replan = "re-plan with `racing-lib plan --out PLAN.csv`"
    if tuple(h.strip() for h in header) != PLAN_COLUMNS:
        raise PlanningError(
            f"{where!r} is not a racing_lib plan CSV: expected the header "
            f"{','.join(PLAN_COLUMNS)}; make one with `racing-lib plan --out PLAN.csv`."
        )
    version = _int_or(meta.get("format_version"), 0)
    if version > PLAN_FORMAT_VERSION:
        raise PlanningError(
            f"plan file {where!r} has format version {version}, newer than this "
            f"racing_lib understands ({PLAN_FORMAT_VERSION}); upgrade racing_lib or re-plan."
        )
    if version < OLDEST_PLAN_FORMAT:
        raise PlanningError(
            f"plan file {where!r} has format version {version}, written by an older "
            f"racing_lib without a checksum, so it cannot be verified; {replan}."
        )
    if not rows:
        raise PlanningError(f"plan file {where!r} has a header but no rows; {replan}.")
    data = _parse_plan_rows(rows, where, replan)
    if digest_line is None:
        raise PlanningError(
            f"plan file {where!r} ends without its '# sha256:' line: it was cut short; {replan}."
        )
    nodes = _int_or(meta.get("nodes"), -1)
    if nodes != len(data):
        raise PlanningError(
            f"plan file {where!r} has {len(data)} rows where its header says {nodes} (it "
            f"was cut short or spliced); {replan}."
        )
    if digest_line != plan_digest(covered):
        raise PlanningError(
            f"plan file {where!r} fails its checksum (its numbers or header were changed "
            f"after it was written), so the plan cannot be trusted; {replan}."
        )
    name = meta.get("track", "")
    checksum = meta.get("track_checksum", "")
    if track is not None:
        want = track.checksum()
        if checksum != want:
            raise PlanningError(
                f"plan {where!r} was made for track {name!r} (checksum "
                f"{checksum[:12] or 'none'}), not for track {track.name!r} (checksum "
                f"{want[:12]}); re-plan with `racing-lib plan --track {track.name}`."
            )
    return PlanFile(
        columns={name_: data[:, i] for i, name_ in enumerate(PLAN_FIELDS)},
        track_name=name,
        track_checksum=checksum,
        method=meta.get("method", ""),
        model=_model_from_meta(meta.get("model"), where, replan),
        planned_lap_time=float(meta.get("planned_lap_time_s", "nan")),
        line_length=float(meta.get("length_m", "nan")),
    )


def _model_from_meta(text: str | None, where: str, replan: str) -> CarModel | None:
    """The model of a plan file's ``# model:`` line (None when the file has none)."""
    if text is None:
        return None
    try:
        data = json.loads(text)
        return None if data is None else CarModel.from_dict(data)
    except (json.JSONDecodeError, ModelError) as exc:
        raise PlanningError(
            f"plan file {where!r} has an unreadable model ({exc}); {replan}."
        ) from None


def plan_digest(text: str) -> str:
    """SHA-256 of a plan file's text above its checksum line (line endings normalized)."""
    canonical = "\n".join(line.rstrip() for line in text.splitlines())
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def _int_or(value: str | None, default: int) -> int:
    try:
        return int(value) if value is not None else default
    except ValueError:
        return default


def _split_plan_text(
    text: str,
) -> tuple[dict[str, str], list[str], list[str], str | None, str]:
    """A plan file's parts: metadata, header fields, data rows and checksum.

    A plan file's metadata, header fields, data rows, recorded checksum (or None) and the
    text the checksum covers (every line above the checksum line).
    """
    meta: dict[str, str] = {}
    header: list[str] = []
    rows: list[str] = []
    digest: str | None = None
    lines = text.lstrip("\ufeff").splitlines()
    covered = len(lines)
    for i, line in enumerate(lines):
        if line.startswith("#"):
            key, sep, value = line[1:].partition(":")
            if sep and key.strip() == "sha256":
                digest = value.strip()
                covered = i
            elif sep and not header:
                meta[key.strip()] = value.strip()
        elif not header:
            header = line.strip().split(",")
        elif line.strip():
            rows.append(line)
    return meta, header, rows, digest, "\n".join(lines[:covered])


def _parse_plan_rows(rows: list[str], where: str, replan: str) -> np.ndarray:
    """The plan's rows as an (N, 11) array; a short or unreadable row is named by its number."""
    ncol = len(PLAN_COLUMNS)
    data = np.empty((len(rows), ncol))
    for i, line in enumerate(rows):
        fields = line.split(",")
        if len(fields) != ncol:
            raise PlanningError(
                f"plan file {where!r}: data row {i + 1} has {len(fields)} fields, expected "
                f"{ncol} (the file is cut short or edited); {replan}."
            )
        try:
            data[i] = [float(f) for f in fields]
        except ValueError as exc:
            raise PlanningError(
                f"plan file {where!r}: data row {i + 1} is not numbers ({exc}); {replan}."
            ) from exc
    return data
