"""Small file helpers shared by every module that writes.

Atomic writes, JSON-ready values, and where the package's shipped data lives
(:func:`data_file`).

A write goes to a temporary file in the same folder and is then renamed over the target, so an
interrupted run leaves either the old file or the new one, never half of one.
"""

from __future__ import annotations

import io
import json
import math
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

if TYPE_CHECKING:
    # matplotlib costs a second to import; only atomic_savefig's callers need it
    from matplotlib.figure import Figure

JSONValue: TypeAlias = "dict[str, JSONValue] | list[JSONValue] | str | int | float | bool | None"
"""A value JSON can hold: an object (str keys), an array, a string, a number, a boolean or null."""

JSONObject: TypeAlias = "dict[str, JSONValue]"
"""A JSON object, as ``json.load`` returns it and a ``to_dict`` method builds it."""

#: The package's shipped data: the identified parameters, the tuned weights, the ablation table.
DATA_DIR = Path(__file__).resolve().parent / "data"


def data_file(name: str) -> Path:
    """The path of a file shipped in ``racing_lib/data`` (it need not exist yet)."""
    return DATA_DIR / name


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        # mkstemp creates the file private (0600); give it the usual permissions of a data file.
        os.chmod(tmp, 0o644)
        os.replace(tmp, target)
    except BaseException:
        # Leave nothing behind on failure or interruption; the old file, if any, is untouched.
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | os.PathLike[str], obj: JSONValue) -> None:
    """Write ``obj`` as indented JSON to ``path`` atomically."""
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True) + "\n")


def atomic_savefig(fig: Figure, path: str | os.PathLike[str], **kwargs: object) -> None:
    """Save a matplotlib figure atomically: rendered in memory, then written as one file.

    The format is the file's suffix (``.png``, ``.pdf``, ``.svg``); ``kwargs`` go to
    ``fig.savefig`` (for example ``dpi``, ``bbox_inches``).
    """
    buf = io.BytesIO()
    fmt = Path(path).suffix.lstrip(".") or "png"
    fig.savefig(buf, format=fmt, **kwargs)
    atomic_write_bytes(path, buf.getvalue())


# Any: JSON-ready for dicts, sequences, arrays and numbers; any other object passes through as is
def jsonable(obj: object) -> Any:
    """A JSON-ready copy of ``obj``.

    NumPy arrays and scalars become Python values, tuples lists, dict keys strings, and NaN or
    infinite floats None (JSON has no such numbers). Other objects are returned unchanged.
    """
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
