"""From logs to samples, and the diagnostics every fit reports.

From logs to samples: one per control period, derivatives by interval differences, and the
regression diagnostics every fit reports.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.signal import savgol_filter

from racing_lib.errors import ModelError
from racing_lib.experiments.sysid.manoeuvres import MANOEUVRES
from racing_lib.model.actuator import NO_LAG_TAU, lagged_steering
from racing_lib.model.drive import Drive

__all__ = ["FitStats"]

Derivative = Literal["interval", "savgol"]

_MIN_SAMPLES = 50  # shortest usable set of samples for any one regression
_V_MIN = 5.0  # m/s: below this slip angles and drag are too small to be informative


# --------------------------------------------------------------------------------------------------
# Samples: one per control period
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Samples:
    """Per-control-period quantities of all logs, concatenated (arrays of shape (M,))."""

    kind: np.ndarray  # manoeuvre of the log the sample came from
    log: np.ndarray  # index of that log
    vx: np.ndarray  # mean states over the period, m/s, m/s, rad/s
    vy: np.ndarray
    r: np.ndarray
    theta: np.ndarray  # road pitch, rad
    dvx: np.ndarray  # mean derivatives over the period, m/s^2, m/s^2, rad/s^2
    dvy: np.ndarray
    dr: np.ndarray
    steer: np.ndarray  # steering command, rad
    pedal: np.ndarray  # pedal command, -
    settled: np.ndarray  # True when the steering command has been steady for 1 s
    age: np.ndarray  # index of the sample within its log
    bounds: tuple[tuple[int, int], ...]  # [start, stop) of each log's samples

    @property
    def valid(self) -> np.ndarray:
        """Samples inside the planning model's domain: moving forward, not sliding sideways.

        A body slip ``|v_y| > 0.1 v_x`` (about 6 degrees) means a spin or a slide: the model's tyres
        and small-angle slip are not meant for it, so such samples are left out of every fit.
        The first second of each log is left out too: the actuator's state when the log starts is
        unknown, so the steering-lag reconstruction needs that long to forget it.
        """
        moving = (self.vx > 1.0) & (np.abs(self.vy) <= 0.1 * np.maximum(self.vx, 1.0))
        return moving & (self.age >= 10)

    @property
    def a_y(self) -> np.ndarray:
        """Lateral acceleration of the centre of gravity, v_y_dot + r v_x, m/s^2."""
        return self.dvy + self.r * self.vx

    def steer_effective(self, tau: float, dt: float = 0.1) -> np.ndarray:
        """Mean actual steering angle over each period for a first-order actuator lag ``tau`` (s).

        The angle obeys ``tau delta_dot = delta_cmd - delta`` with the command held over the period;
        each log starts settled (``delta = delta_cmd[0]``).
        """
        if tau <= NO_LAG_TAU:
            return self.steer
        out = np.empty_like(self.steer)
        for start, stop in self.bounds:
            out[start:stop] = lagged_steering(self.steer[start:stop], tau, dt)
        return out


def _samples(logs: Sequence[Drive], derivative: Derivative) -> _Samples:
    if derivative not in ("interval", "savgol"):
        raise ModelError(f"unknown derivative method {derivative!r}; use 'interval' or 'savgol'.")
    cols: dict[str, list[np.ndarray]] = {k: [] for k in _Samples.__dataclass_fields__}
    bounds = []
    start = 0
    for i, log in enumerate(logs):
        n = log.t.size - 1  # periods between observations, each with the command sent at its start
        if n < 8:
            continue  # too short to differentiate; the total length is checked by the caller
        if log.theta is None:
            raise ModelError(
                f"drive {log.name!r} has no road pitch theta (rad); record it from the track map "
                "at each observation to identify from it."
            )
        dt = np.diff(log.t)
        if np.any(dt <= 0.0):
            raise ModelError(f"drive {log.name!r}: time must increase strictly.")
        nodes = {"vx": log.vx, "vy": log.vy, "r": log.r, "theta": log.theta}
        for key in ("vx", "vy", "r"):
            v = nodes[key]
            if derivative == "interval":
                # Exact mean derivative over the period in which command k was held.
                d = np.diff(v) / dt
                m = 0.5 * (v[:-1] + v[1:])
            else:
                h = float(np.median(dt))
                d_nodes = savgol_filter(v, 7, 2, deriv=1, delta=h, mode="interp")
                v_nodes = savgol_filter(v, 7, 2, mode="interp")
                d = 0.5 * (d_nodes[:-1] + d_nodes[1:])
                m = 0.5 * (v_nodes[:-1] + v_nodes[1:])
            cols[key].append(m)
            cols["d" + key].append(d)
        cols["theta"].append(0.5 * (log.theta[:-1] + log.theta[1:]))
        cols["steer"].append(log.steer[:-1])
        cols["pedal"].append(log.pedal[:-1])
        # Steady steering: the command moved less than 5 mrad over the last 10 periods.
        s = log.steer[:-1]
        settled = np.zeros(n, dtype=bool)
        for k in range(10, n):
            settled[k] = np.ptp(s[k - 10 : k + 1]) < 5e-3
        cols["settled"].append(settled)
        cols["age"].append(np.arange(n))
        cols["kind"].append(np.full(n, log.kind, dtype=object))
        cols["log"].append(np.full(n, i))
        bounds.append((start, start + n))
        start += n
    if not bounds:
        return _Samples(
            **{k: np.zeros(0) for k in cols if k != "bounds"},
            bounds=(),
        )
    return _Samples(
        **{k: np.concatenate(v) for k, v in cols.items() if k != "bounds"},
        bounds=tuple(bounds),
    )


# --------------------------------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------------------------------


#: What to change when a manoeuvre ran but its data could not determine a parameter.
_ADVICE = {
    "circles": (
        "larger circles or more speed levels (circle_logs(radii=..., levels=..., hold=...)) "
        "reach a higher steady lateral acceleration at speeds the car can hold; if its watchdog "
        "backed off before the data sheet's mu g (the car's grip is lower, or the throttle spins "
        "its wheels), give a truer mu in the data sheet or wider bands "
        "(ManoeuvreSettings(yaw_limit=..., slip_limit=...))"
    ),
    "steps": (
        "longer runs or more base speeds (step_logs(speeds=..., duration=...)); a car that "
        "trips the watchdog in them needs lower speeds"
    ),
    "coast-down": (
        "a wider speed range: a higher start and a lower end "
        "(coast_down_log(v_high=..., v_low=...))"
    ),
    "braking": "higher start speeds (braking_logs(speeds=...))",
    "laps": "more laps or speed scalings (lap_logs(tracks=..., scalings=...))",
}


def _missing(what: str, detail: str, manoeuvre: str, S: _Samples | None = None) -> ModelError:
    """The error for data that cannot determine ``what``.

    If the logs ``S`` hold the ``manoeuvre`` that determines it, the message says so and what to
    change in it; otherwise it names the manoeuvre to add.
    """
    if S is not None and S.kind.size and np.any(S.kind == manoeuvre):
        runs = sum(1 for start, _ in S.bounds if S.kind[start] == manoeuvre)
        return ModelError(
            f"cannot identify {what}: the '{manoeuvre}' manoeuvre ran ({runs} log(s)), but "
            f"{detail}. To change: {_ADVICE.get(manoeuvre, 'drive it longer')}."
        )
    return ModelError(
        f"cannot identify {what}: {detail}. Add the '{manoeuvre}' manoeuvre "
        f"({MANOEUVRES[manoeuvre]}) to the logs, e.g. with "
        "racing_lib.experiments.sysid.collect_logs()."
    )


def _condition(A: np.ndarray) -> float:
    """Condition number of the regressor with its columns scaled to unit norm (scale-free)."""
    norms = np.linalg.norm(A, axis=0)
    if np.any(norms == 0.0):
        return math.inf
    return float(np.linalg.cond(A / norms))


def _check_regressor(
    A: np.ndarray, names: Sequence[str], what: str, manoeuvre: str, S: _Samples | None = None
) -> float:
    """Raise if the columns of ``A`` are nearly linearly dependent; return the condition number."""
    cond = _condition(A)
    if not math.isfinite(cond) or cond > 1e4:
        norms = np.linalg.norm(A, axis=0)
        weakest = names[int(np.argmin(norms))] if np.any(norms == 0.0) else "/".join(names)
        raise _missing(
            what,
            f"the regressors {list(names)} are nearly collinear (condition number {cond:.3g} "
            f"> 1e4; weakest: {weakest})",
            manoeuvre,
            S,
        )
    return cond


def _r2(y: np.ndarray, residual: np.ndarray) -> float:
    ss = float(np.sum((y - np.mean(y)) ** 2))
    return 1.0 - float(np.sum(residual**2)) / ss if ss > 0.0 else float("nan")


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else float("nan")


# --------------------------------------------------------------------------------------------------
# Fits
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FitStats:
    """Quality of one regression.

    Attributes
    ----------
    name : str
        Which fit (e.g. ``"tyres (steady state)"``).
    n : int
        Number of samples used.
    rms : float
        Root-mean-square residual, in ``unit``.
    unit : str
        Unit of the residual.
    r2 : float
        Coefficient of determination of the fitted quantity (held-out data for the pedal map).
    cond : float
        Condition number of the (column-scaled) regressor or Jacobian at the solution.
    """

    name: str
    n: int
    rms: float
    unit: str
    r2: float
    cond: float


def _subset(S: _Samples, idx: np.ndarray) -> _Samples:
    """The samples ``idx`` (the lag filter must run on the full samples: index its output)."""
    fields_ = {k: getattr(S, k)[idx] for k in S.__dataclass_fields__ if k != "bounds"}
    return _Samples(**fields_, bounds=())
