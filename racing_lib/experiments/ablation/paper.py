"""The paper's Tables I and II as data, and the measures chapter 07 compares our rows with.

:data:`PAPER` holds the numbers the paper prints for every row of its Table I (the ablations on
the expressway-like circuit and the sharper open track) and Table II (tracking the best human lap).
:func:`row_measures` reduces one row of our table to the same fields, so that each comparison
reads ``PAPER[name][field]`` against ``row_measures(row)[field]``. The profile helpers read the
per-row profiles the table keeps for the figures (:mod:`racing_lib.experiments.ablation.profiles`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from scipy.interpolate import CubicSpline

from racing_lib.experiments.ablation.rows import TableRow
from racing_lib.geometry import Corner, Track

__all__ = [
    "PAPER",
    "PAPER_COLUMNS",
    "PAPER_FIELDS",
    "PAPER_ROW_LABELS",
    "below_plan",
    "corner_window",
    "nearest_corner",
    "plan_gap",
    "relative_to",
    "row_line_xy",
    "row_measures",
    "row_profile",
    "row_trials",
]

#: The fields of a row, in the paper's column order: planned lap, closed-loop lap mean, std and
#: min (s), v_x MAE, its std and max (m/s), e_y MAE, its std and max (m), wall contacts per lap.
PAPER_FIELDS = (
    "planned",
    "mean",
    "std",
    "min",
    "vx",
    "vx_std",
    "vx_max",
    "ey",
    "ey_std",
    "ey_max",
    "walls",
)

# The paper's Table I and Table II, one tuple per row in PAPER_FIELDS order (None: the paper's
# open track has no walls to count).
# fmt: off
_PAPER_ROWS: dict[str, tuple[float | None, ...]] = {
    #                                   planned  mean    std    min     vx    vx_std vx_max  ey    ey_std ey_max walls
    "main":                            (99.48, 101.03, 0.089, 100.80, 0.308, 0.363, 1.872, 0.158, 0.340, 1.508, 0),
    "no-drag":                         (96.89, 101.86, 0.056, 101.80, 2.13, 1.535, 7.362, 0.292, 0.715, 4.800, 2),
    "no-longitudinal-weight-transfer": (100.36, 101.52, 0.060, 101.43, 0.300, 0.413, 2.218, 0.168, 0.368, 1.682, 0),
    "lateral-weight-transfer":         (99.52, 100.94, 0.119, 100.86, 0.457, 0.350, 1.524, 0.143, 0.310, 1.619, 0),
    "curvature-plan":                  (101.28, 103.80, 0.207, 103.58, 0.925, 0.980, 5.743, 0.180, 0.527, 4.246, 1),
    "decoupled":                       (99.48, 103.48, 0.485, 102.86, 1.312, 1.456, 7.071, 0.377, 0.736, 4.330, 3),
    "no-smooth-transition":            (99.48, 103.56, 0.118, 103.28, 1.691, 1.905, 7.887, 0.258, 0.580, 3.540, 1),
    "shortcut-main":                   (93.00, 96.623, 0.103, 96.48, 1.629, 0.591, 3.374, 0.228, 0.410, 2.385, None),
    "shortcut-lateral-weight-transfer": (92.89, 96.556, 0.083, 96.44, 1.582, 0.556, 3.210, 0.230, 0.409, 2.375, None),
    # Table II: the reference is the best human lap (99.43 s); its closed-loop mean is printed as
    # 100.7 s.
    "best-lap":                        (99.43, 100.7, 0.292, 100.54, 0.503, 0.520, 2.058, 0.074, 0.147, 1.005, 2),
}
# fmt: on

#: The paper's numbers per row name and field (see :data:`PAPER_FIELDS`).
PAPER: dict[str, dict[str, float | None]] = {
    name: dict(zip(PAPER_FIELDS, values, strict=True)) for name, values in _PAPER_ROWS.items()
}


#: Where the paper prints each row: its table (``"I"`` or ``"II"``) and the row's label there, in
#: the paper's words (✗: the element removed, ✓: added).
PAPER_ROW_LABELS: dict[str, tuple[str, str]] = {
    "main": ("I", "main experiment (Tokyo Expressway)"),
    "no-drag": ("I", "✗ wind drag force"),
    "no-longitudinal-weight-transfer": ("I", "✗ longitudinal weight transfer"),
    "lateral-weight-transfer": ("I", "✓ lateral weight transfer"),
    "curvature-plan": ("I", "✗ time-optimal trajectory"),
    "decoupled": ("I", "✗ MPC with coupled model"),
    "no-smooth-transition": ("I", "✗ smooth reference transition"),
    "shortcut-main": ("I", "main experiment (Autopolis)"),
    "shortcut-lateral-weight-transfer": ("I", "✓ lateral weight transfer (Autopolis)"),
    "best-lap": ("II", "tracking the best human lap"),
}

#: What each field of :data:`PAPER_FIELDS` is in the paper: a column of its tables, or (``walls``)
#: the collisions its text describes, since the tables print none.
PAPER_COLUMNS: dict[str, str] = {
    "planned": "planned lap time [s]",
    "mean": "closed-loop lap time, mean [s]",
    "std": "closed-loop lap time, std [s]",
    "min": "closed-loop lap time, best [s]",
    "vx": "MAE of v_x, mean [m/s]",
    "vx_std": "MAE of v_x, std [m/s]",
    "vx_max": "MAE of v_x, max [m/s]",
    "ey": "MAE of e_y, mean [m]",
    "ey_std": "MAE of e_y, std [m]",
    "ey_max": "MAE of e_y, max [m]",
    "walls": "the text: collisions in the laps it describes (not a column)",
}


def row_measures(row: TableRow) -> dict[str, float | None]:
    """The fields of :data:`PAPER_FIELDS` that our table has, from one of its rows.

    Lap times are ``inf`` (and their spread NaN) when no lap was completed; ``walls`` is the wall
    contacts per lap, None on an open track.
    """
    done = row["completed"] > 0
    return {
        "planned": row["planned_lap_time_s"],
        "mean": row["lap_time_mean_s"] if done else math.inf,
        "std": row["lap_time_std_s"] if done else math.nan,
        "min": row["lap_time_min_s"] if done else math.inf,
        "vx": row["vx_mae_mps"],
        "vx_max": row["vx_max_err_mps"],
        "ey": row["ey_mae_m"],
        "ey_max": row["ey_max_m"],
        "walls": row["wall_contacts_per_lap"] if row["boundary"] == "walls" else None,
    }


def row_trials(row: TableRow) -> dict[str, np.ndarray]:
    """The completed trials of one of our rows, field by field: one value per seeded lap.

    Keys ``lap_time_s`` (s), ``vx_mae_mps`` (m/s), ``ey_mae_m`` (m) and ``wall_contacts`` (per
    lap; zeros on an open track), the samples whose spread the claims' verdicts weigh
    (:func:`racing_lib.experiments.ablation.claims.decided`).
    """
    done = [t for t in row["trial_metrics"] if t["completed"]]
    fields = ("lap_time_s", "vx_mae_mps", "ey_mae_m", "wall_contacts")
    return {f: np.array([float(t[f]) for t in done]) for f in fields}


def plan_gap(measures: Mapping[str, float | None]) -> float:
    """How much slower the closed loop is than the plan it tracks, as a fraction (0.01 = 1 %)."""
    return measures["mean"] / measures["planned"] - 1.0


def relative_to(
    table: Mapping[str, Mapping[str, float | None]], name: str, base: str
) -> tuple[float, float, float, float]:
    """Row ``name`` against row ``base`` of the same table (the paper's or ours).

    Returns
    -------
    tuple of float
        Planned lap and closed-loop lap against the base's, %, and the v_x and e_y MAE as
        multiples of the base's.
    """
    m, b = table[name], table[base]
    return (
        100 * (m["planned"] / b["planned"] - 1),
        100 * (m["mean"] / b["mean"] - 1),
        m["vx"] / b["vx"],
        m["ey"] / b["ey"],
    )


def row_profile(row: TableRow, part: str, key: str) -> np.ndarray:
    """One profile quantity of a row as a float array on its grid (NaN where the lap stopped).

    ``part`` is ``"plan"`` or ``"closed_loop"``; ``key`` one of its fields (``vx_mps``, ``n_m``,
    ...; see :mod:`racing_lib.experiments.ablation`).
    """
    return np.asarray(row["profile"][part][key], dtype=float)


def row_line_xy(
    track: Track, row: TableRow, part: str, step: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """The line of a row (its plan or its closed loop) as x, y arrays every ``step`` m, m.

    The offsets from the centerline are splined periodically; a lap that stopped is joined by
    straight segments with its gap left open (NaN).
    """
    s = np.asarray(row["profile"]["s_m"], dtype=float)
    n = row_profile(row, part, "n_m")
    fine = np.arange(0.0, track.length, step)
    if np.all(np.isfinite(n)):
        closed_s = np.append(s, track.length)
        n_fine = CubicSpline(closed_s, np.append(n, n[0]), bc_type="periodic")(fine)
    else:
        n_fine = np.interp(fine, s, n)
    x, y, _ = track.centerline.to_cartesian(fine, n_fine)
    return x, y


def corner_window(track: Track, corner: Corner, s: np.ndarray, margin: float = 30.0) -> np.ndarray:
    """Which points of the grid ``s`` (m) lie between a corner's entry and exit, plus ``margin``.

    Periodic in the track's length, so a corner across the start/finish line is whole.
    """
    lo, hi = corner.s_entry - margin, corner.s_exit + margin
    span = (hi - lo) % track.length  # an exit past the line may be given as s_exit < s_entry
    return ((s - lo) % track.length) <= span


def nearest_corner(corners: Mapping[int, float], s: float, length: float | None = None) -> int:
    """The number of the corner (of ``{number: s}``, m) nearest to ``s`` (m).

    With the track's ``length`` (m), distances are measured around the loop, so a corner just
    before the line is near a point just after it.
    """

    def distance(c: int) -> float:
        d = abs(corners[c] - s)
        return min(d, length - d) if length else d

    return min(corners, key=distance)


def below_plan(row: TableRow, by: float = 1.0) -> float:
    """Share of the lap (0-1) where the closed loop (seed 0) is over ``by`` m/s below its plan."""
    short = row_profile(row, "plan", "vx_mps") - row_profile(row, "closed_loop", "vx_mps")
    return float(np.mean(short[np.isfinite(short)] > by))
