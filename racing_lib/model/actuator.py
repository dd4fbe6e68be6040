"""The steering actuator the planning model leaves out: a first-order lag behind the command."""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

__all__ = ["lagged_steering"]


def lagged_steering(steer_cmd: np.ndarray, tau: float, dt: float = 0.1) -> np.ndarray:
    """Mean road-wheel angle over each control period behind a first-order steering actuator.

    The actual angle obeys ``tau delta_dot = delta_cmd - delta`` with each command held for one
    period ``dt``; the actuator starts settled at the first command (``delta = delta_cmd[0]``).
    Used by the identification (the steering lag fit) and by the open-loop predictions of
    :mod:`racing_lib.model.prediction`. Taught in notebook 02.

    Parameters
    ----------
    steer_cmd : ndarray, shape (N,)
        Steering commands, rad, command ``k`` held from ``t_k`` to ``t_k + dt``.
    tau : float
        Time constant of the lag, s; ``tau <= 1e-4`` returns the commands unchanged.
    dt : float
        Control period, s.

    Returns
    -------
    ndarray, shape (N,)
        The exact mean angle over each period, rad.
    """
    c = np.asarray(steer_cmd, dtype=float).ravel()
    if tau <= 1e-4 or c.size == 0:
        return c.copy()
    a = math.exp(-dt / tau)
    nodes, _ = lfilter([1.0 - a], [1.0, -a], c, zi=[a * c[0]])  # delta at k + 1
    d0 = np.concatenate(([c[0]], nodes[:-1]))  # delta at k
    # Mean of d0 + (c - d0) (1 - exp(-t / tau)) over the period
    return c + (d0 - c) * (tau / dt) * (1.0 - a)
