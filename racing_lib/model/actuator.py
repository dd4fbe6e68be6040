"""The steering actuator the planning model leaves out: a first-order lag behind the command."""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

__all__ = ["NO_LAG_TAU", "lagged_steering", "steering_lag_coefficients"]

#: Time constant (s) at or below which the steering lag counts as none: the command is the angle.
#: One threshold for every user of the lag (the identification's fits and open-loop predictions,
#: the MPC's model). Why 1e-4 s, not 0: there the exact coefficients are already no lag to within
#: the steering's resolution (a = exp(-dt / tau) underflows to 0 for tau < dt / 745, and the mean
#: angle's weight w = tau / dt (1 - a) is at most 1e-3 at the 0.1 s control period); and the
#: identification fits tau down to its bound 0, where a clean "no lag" (the commands themselves)
#: beats an exponential of -1000. Real actuators (about 0.08 s) are 800 times slower, and their
#: numbers are the same with either threshold.
NO_LAG_TAU = 1e-4


def steering_lag_coefficients(tau: float, dt: float) -> tuple[float, float]:
    """``(a, w)`` of the first-order steering lag ``delta_dot = (delta_cmd - delta) / tau``.

    Over one period ``dt`` (s) with the command held: ``delta_{k+1} = a delta_k + (1 - a)
    delta_cmd`` with ``a = exp(-dt / tau)``, and the *mean* angle over the period is
    ``w delta_k + (1 - w) delta_cmd`` with ``w = tau / dt (1 - a)``. ``tau <= NO_LAG_TAU`` (s):
    ``(0, 0)``, the command is the angle. Used by :func:`lagged_steering` and the MPC's model
    (:func:`racing_lib.control.mpc.linearize.augment_steering_lag`).
    """
    if tau <= NO_LAG_TAU:
        return 0.0, 0.0
    a = math.exp(-dt / tau)
    return a, tau / dt * (1.0 - a)


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
        Time constant of the lag, s; ``tau <= NO_LAG_TAU`` (1e-4 s) returns the commands unchanged.
    dt : float
        Control period, s.

    Returns
    -------
    ndarray, shape (N,)
        The exact mean angle over each period, rad.
    """
    c = np.asarray(steer_cmd, dtype=float).ravel()
    if tau <= NO_LAG_TAU or c.size == 0:
        return c.copy()
    a, _ = steering_lag_coefficients(tau, dt)
    nodes, _ = lfilter([1.0 - a], [1.0, -a], c, zi=[a * c[0]])  # delta at k + 1
    d0 = np.concatenate(([c[0]], nodes[:-1]))  # delta at k
    # Mean of d0 + (c - d0) (1 - exp(-t / tau)) over the period: w (d0 - c) + c with the w of
    # steering_lag_coefficients, multiplied factor by factor as the identified parameters were.
    return c + (d0 - c) * (tau / dt) * (1.0 - a)
