"""The record of a drive: what the car was seen doing and what it was told to do.

One record for every drive: a lap of :func:`racing_lib.experiments.lap.run_lap` (whose
:class:`~racing_lib.experiments.lap.LapLog` adds the lap's own columns), a manoeuvre of the
identification (:mod:`racing_lib.experiments.sysid`), and the input of the prediction error
(:func:`racing_lib.model.prediction.prediction_errors`). Taught in notebooks 01 (the lap's log) and
02 (identification and prediction).
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from racing_lib.errors import ModelError
from racing_lib.io import atomic_write_bytes

__all__ = ["Drive"]

#: The arrays every drive has, one entry per sample.
DRIVE_COLUMNS = ("t", "x", "y", "psi", "vx", "vy", "r", "steer", "pedal")


@dataclass(frozen=True)
class Drive:
    """A recorded drive: ``N`` samples, each an observation and the command sent after it.

    Sample ``k`` holds observation ``k`` (taken at ``t[k]``) and the command the car was sent
    right after it, held until observation ``k + 1``. So every array has the same length ``N``,
    and the ``N - 1`` intervals between consecutive observations each have the command that acted
    over them (``steer[:-1]``, ``pedal[:-1]``); the last command's effect is not observed. This is
    the order in which a controller works (observe, then command), so a closed-loop lap records
    one row per control step, and every column of a lap's log (the reference's ``s_ref``,
    ``vx_ref``, the controller's ``solve_ms``, ...) is a column of the same length.

    Attributes
    ----------
    t : ndarray (N,)
        Time of the observations, s.
    x, y : ndarray (N,)
        Position, m.
    psi : ndarray (N,)
        Yaw angle, rad.
    vx, vy : ndarray (N,)
        Body-frame longitudinal and lateral velocity, m/s.
    r : ndarray (N,)
        Yaw rate, rad/s.
    steer : ndarray (N,)
        Steering command sent after each observation, rad.
    pedal : ndarray (N,)
        Pedal command sent after each observation, in [-1, 1].
    theta : ndarray (N,) or None
        Road pitch at the car's position from the track map, rad (positive uphill); None when not
        recorded (the identification needs it).
    name : str
        Human-readable label, e.g. ``"circle R=60 m"``.
    kind : str
        What sort of drive it is, e.g. a manoeuvre of
        :data:`racing_lib.experiments.sysid.MANOEUVRES` (the identification picks its data by it).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    r: np.ndarray
    steer: np.ndarray
    pedal: np.ndarray
    theta: np.ndarray | None = field(default=None, kw_only=True)
    name: str = field(default="", kw_only=True)
    kind: str = field(default="", kw_only=True)

    def __post_init__(self) -> None:
        keys = DRIVE_COLUMNS if self.theta is None else (*DRIVE_COLUMNS, "theta")
        n = np.asarray(self.t).size
        for key in keys:
            arr = np.asarray(getattr(self, key), dtype=float).ravel()
            if arr.size != n:
                raise ModelError(
                    f"drive {self.name!r}: {key} has {arr.size} samples, t has {n}; a drive has "
                    "one observation and the command sent after it per sample."
                )
            if not np.all(np.isfinite(arr)):
                raise ModelError(
                    f"drive {self.name!r}: {key} contains NaN or infinite values; drop the "
                    "broken part of the log."
                )
            object.__setattr__(self, key, arr)

    @property
    def duration(self) -> float:
        """Time from the first observation to the last, s."""
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0

    def save(self, path: str | Path) -> None:
        """Write the drive as a compressed ``.npz`` file (one entry per column), atomically."""
        columns = {f.name: getattr(self, f.name) for f in fields(self)}
        buf = io.BytesIO()
        np.savez_compressed(buf, **{k: v for k, v in columns.items() if v is not None})
        atomic_write_bytes(path, buf.getvalue())

    @classmethod
    def load(cls, path: str | Path) -> Drive:
        """A drive written by :meth:`save` (called on the class that saved it, e.g. ``LapLog``)."""
        with np.load(path, allow_pickle=False) as data:
            columns = {k: data[k] for k in data.files}
        for key in ("name", "kind"):
            if key in columns:
                columns[key] = str(columns[key])
        return cls(**columns)
