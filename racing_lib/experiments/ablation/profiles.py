"""The profiles each row keeps for the figures: its plan and its first lap, one grid per track."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from racing_lib.experiments.lap import LapLog
from racing_lib.geometry import Track
from racing_lib.planning.trajectory import Trajectory

__all__ = ["PROFILE_SPACING", "closed_loop_profile", "plan_profile", "profile_grid", "rounded"]
#: Spacing of the stored profiles along the track centerline, m.
PROFILE_SPACING = 10.0


def rounded(values: np.ndarray, decimals: int) -> list[float | None]:
    """Values rounded to ``decimals`` as a JSON-ready list (None for NaN or infinite)."""
    arr = np.round(np.asarray(values, dtype=float), decimals)
    return [float(v) if math.isfinite(v) else None for v in arr]


def _periodic_profile(
    s: np.ndarray, values: Mapping[str, np.ndarray], grid: np.ndarray, length: float, gap: float
) -> dict[str, np.ndarray]:
    """Values given at (unsorted) arc lengths ``s`` resampled on ``grid``, m (periodic).

    Grid points farther than ``gap`` (m) from every sample (a lap that stopped) become NaN.
    """
    s = np.mod(np.asarray(s, dtype=float), length)
    order = np.argsort(s)
    s_sorted = s[order]
    idx = np.searchsorted(s_sorted, grid) % s_sorted.size
    nearest = np.minimum(
        np.abs((s_sorted[idx] - grid + 0.5 * length) % length - 0.5 * length),
        np.abs((s_sorted[idx - 1] - grid + 0.5 * length) % length - 0.5 * length),
    )
    out = {}
    for name, vals in values.items():
        v = np.interp(grid, s_sorted, np.asarray(vals, dtype=float)[order], period=length)
        out[name] = np.where(nearest <= gap, v, np.nan)
    return out


def profile_grid(track: Track) -> np.ndarray:
    """The arc lengths (m) every profile of a track is sampled at, :data:`PROFILE_SPACING` apart."""
    return np.arange(0.0, float(track.length), PROFILE_SPACING)


def closed_loop_profile(log: LapLog, track: Track) -> dict[str, list[float | None]]:
    """The closed-loop lap on the track-centerline grid (every :data:`PROFILE_SPACING` m)."""
    lap = log.lap_steps
    s = np.asarray(log.s_track, dtype=float)[lap]
    vx = np.asarray(log.vx, dtype=float)[lap]
    _, n, _ = track.centerline.to_frenet(log.x[lap], log.y[lap], s_hint=s)
    # Path curvature of the closed loop: yaw rate over speed (the side-slip rate is neglected).
    kappa = np.asarray(log.r, dtype=float)[lap] / np.maximum(vx, 1.0)
    values = {"vx": vx, "steer": log.steer[lap], "kappa": kappa, "ey": log.ey[lap], "n": n}
    # A gap of a few control steps means the car stopped lapping there.
    gap = max(3.0 * PROFILE_SPACING, 3.0 * float(np.max(vx, initial=0.0)) * 0.1)
    prof = _periodic_profile(s, values, profile_grid(track), float(track.length), gap)
    return {
        "vx_mps": rounded(prof["vx"], 2),
        "steer_rad": rounded(prof["steer"], 4),
        "kappa_radpm": rounded(prof["kappa"], 5),
        "ey_m": rounded(prof["ey"], 3),
        "n_m": rounded(prof["n"], 2),
    }


def plan_profile(trajectory: Trajectory, track: Track) -> dict[str, list[float | None]]:
    """The plan on the track-centerline grid (every :data:`PROFILE_SPACING` m)."""
    s, n = track.centerline.to_frenet_along(trajectory.x, trajectory.y)
    values = {"vx": trajectory.vx, "kappa": trajectory.kappa, "delta": trajectory.delta, "n": n}
    prof = _periodic_profile(s, values, profile_grid(track), float(track.length), math.inf)
    return {
        "vx_mps": rounded(prof["vx"], 2),
        "kappa_radpm": rounded(prof["kappa"], 5),
        "delta_rad": rounded(prof["delta"], 4),
        "n_m": rounded(prof["n"], 2),
    }
