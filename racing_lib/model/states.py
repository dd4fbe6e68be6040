"""The planning model's state and input vectors: their indices and shape checks.

State and input (paper Eq. 1)::

    xi = [v_x, v_y, r, e_psi, e_y, s]     (m/s, m/s, rad/s, rad, m, m)
    u  = [delta, a_x]                     (rad, m/s^2)

Index them by name (``xi[X.EY]``, ``sol[:, X.VX]``) rather than by number.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from racing_lib.errors import ModelError

__all__ = ["NU", "NX", "Domain", "Method", "U", "X", "as_float", "per_stage", "state_rows"]

#: Integration scheme of a discretization.
Method = Literal["rk4", "euler"]
#: Independent variable: time t (s) or arc length s along the reference line (m).
Domain = Literal["time", "spatial"]


class X(IntEnum):
    """Indices of the state vector ``xi``."""

    VX = 0  #: longitudinal velocity in the body frame, m/s
    VY = 1  #: lateral velocity in the body frame (left positive), m/s
    R = 2  #: yaw rate, rad/s (counter-clockwise positive)
    EPSI = 3  #: heading error to the reference line, rad
    EY = 4  #: lateral offset from the reference line (left positive), m
    S = 5  #: arc length along the reference line, m


class U(IntEnum):
    """Indices of the input vector ``u``."""

    DELTA = 0  #: front steering angle, rad (left positive)
    AX = 1  #: longitudinal acceleration produced by the tyres, m/s^2


NX: int = len(X)
NU: int = len(U)


def as_float(name: str, value: object) -> float:
    """``value`` as a finite float; ModelError naming ``name`` otherwise.

    Text and booleans are refused, though ``float()`` would take them: ``"1.2"`` or ``True`` in a
    parameter is a mistake upstream, not a number.
    """
    if isinstance(value, str | bytes | bool | np.bool_):
        raise ModelError(f"{name} must be a number; got {value!r}.")
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{name} must be a number; got {value!r}.") from None
    if not math.isfinite(out):
        raise ModelError(f"{name} must be finite; got {out}.")
    return out


def state_rows(xi: ArrayLike, name: str = "xi", width: int = NX) -> np.ndarray:
    """``(width,)`` or ``(N, width)`` -> float array ``(N, width)``; ModelError otherwise."""
    arr = np.asarray(xi, dtype=float)
    if arr.ndim == 1 and arr.shape[0] == width:
        return arr[None, :]
    if arr.ndim == 2 and arr.shape[1] == width:
        return arr
    raise ModelError(
        f"{name} must have shape ({width},) or (N, {width}); got {arr.shape}. "
        f"Order: {[x.name for x in (X if width == NX else U)]}."
    )


def per_stage(value: ArrayLike, n: int, name: str) -> np.ndarray:
    """A scalar or ``n`` values as a float array ``(n,)``; ModelError otherwise."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    arr = arr.ravel()
    if arr.size != n:
        raise ModelError(
            f"{name} must be a scalar or have {n} entries (one per state); got {arr.size}."
        )
    return arr
