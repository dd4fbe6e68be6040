"""The rows of the paper's Table I and Table II: which track, configuration and plan each one is."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from racing_lib.config import fast_mode
from racing_lib.errors import ControlError, TrackError
from racing_lib.experiments.configs import (
    TUNING_CONFIGS,
)

__all__ = [
    "DEFAULT_TRIALS",
    "FAST_TRIALS",
    "AblationRow",
    "TableRow",
    "ablation_rows",
    "default_trials",
    "format_number",
    "row_summary",
    "select_rows",
]
#: Seeded trials per row (the paper's ten).
DEFAULT_TRIALS = 10
#: Trials per row in fast mode (tests, CI): fewer laps, the same algorithm.
FAST_TRIALS = 2

#: One computed row of the tables, as :func:`~racing_lib.experiments.ablation.run_ablation`
#: returns it and the table file stores it: a JSON object (name, track, configuration, trials,
#: lap-time and error statistics, per-trial metrics, plan and profiles). Its values are numbers,
#: strings, lists and nested objects, hence ``Any``.
TableRow = dict[str, Any]

# Labels of the table's rows in the paper's words ("without" = the paper's cross mark).
_LABELS = {
    "main": "main experiment (expressway)",
    "no-drag": "without drag",
    "no-longitudinal-weight-transfer": "without longitudinal weight transfer",
    "lateral-weight-transfer": "with lateral weight transfer",
    "curvature-plan": "curvature-optimal plan instead of time-optimal",
    "decoupled": "decoupled MPC instead of coupled",
    "no-smooth-transition": "without smooth reference transition",
}


# --------------------------------------------------------------------------------------------------
# The rows


@dataclass(frozen=True)
class AblationRow:
    """One row of the tables: which track, which configuration, which plan.

    Attributes
    ----------
    name : str
        Unique name (``'main'``, ``'no-drag'``, ..., ``'shortcut-main'``, ``'best-lap'``).
    track : str
        Built-in track the row is driven on.
    config : str
        The :data:`~racing_lib.experiments.configs.TUNING_CONFIGS` entry giving the plan method, the
        model options (of planner and MPC), the controller, the smooth-transition switch and the
        tuned weights.
    table : str
        ``'I'`` (the ablation table) or ``'II'`` (tracking the best possible lap).
    label : str
        Description in the paper's words.
    best_lap : bool
        The plan is the best possible lap of the simulated car (Table II) instead of the
        configuration's planner.
    """

    name: str
    track: str
    config: str
    table: str
    label: str
    best_lap: bool = False


def ablation_rows() -> tuple[AblationRow, ...]:
    """Every row, in the order of the paper's tables.

    The expressway rows are exactly the configurations of
    :data:`~racing_lib.experiments.configs.TUNING_CONFIGS` (in its order), so a configuration added
    there appears here.
    """
    rows = [
        AblationRow(name, "expressway", name, "I", _LABELS.get(name, name))
        for name in TUNING_CONFIGS
    ]
    rows += [
        AblationRow("shortcut-main", "shortcut", "main", "I", "sharper open track (shortcut)"),
        AblationRow(
            "shortcut-lateral-weight-transfer",
            "shortcut",
            "lateral-weight-transfer",
            "I",
            "shortcut, with lateral weight transfer",
        ),
        AblationRow(
            "best-lap",
            "expressway",
            "main",
            "II",
            "coupled MPC tracking the best possible lap",
            best_lap=True,
        ),
    ]
    return tuple(rows)


def select_rows(names: Iterable[str] | None = None, track: str | None = None) -> list[AblationRow]:
    """The rows to run, in table order.

    Parameters
    ----------
    names : iterable of str, optional
        Row names (all rows when omitted). Within a ``track``, a configuration name also selects
        that track's row (``track='shortcut'``, ``names=['main']`` is ``shortcut-main``).
    track : str, optional
        Only the rows driven on this built-in track.

    Raises
    ------
    TrackError
        ``track`` is not a track of the tables.
    ControlError
        A name is not a row (the message lists the rows).
    """
    rows = list(ablation_rows())
    if track is not None:
        tracks = sorted({r.track for r in rows})
        if track not in tracks:
            raise TrackError(
                f"the ablation tables have no rows on track {track!r}; choose one of "
                f"{', '.join(tracks)} (or no track for all rows)."
            )
        rows = [r for r in rows if r.track == track]
    if names is None:
        return rows
    wanted: set[str] = set()
    for name in names:
        exact = [r for r in rows if r.name == name]
        # Inside one track, 'main' means that track's main row (not the best-lap row).
        alias = [r for r in rows if r.config == name and not r.best_lap] if track else []
        found = exact or alias
        if len(found) != 1:
            where = f" on track {track!r}" if track else ""
            raise ControlError(
                f"unknown ablation row {name!r}{where}; choose from "
                f"{', '.join(r.name for r in rows)}."
            )
        wanted.add(found[0].name)
    return [r for r in rows if r.name in wanted]


def default_trials() -> int:
    """Trials per row: :data:`DEFAULT_TRIALS`, or :data:`FAST_TRIALS` in fast mode."""
    return FAST_TRIALS if fast_mode() else DEFAULT_TRIALS


def format_number(x: float | None, decimals: int) -> str:
    """``x`` with ``decimals`` digits, or ``-`` when there is no value."""
    return "-" if x is None else f"{float(x):.{decimals}f}"


def row_summary(row: TableRow) -> str:
    """One line on a row: planned and closed-loop lap time, errors, walls."""
    mean = row.get("lap_time_mean_s")
    lap = f"{mean:.2f} +- {row['lap_time_std_s']:.3f} s" if mean is not None else "no lap completed"
    vx, ey = row.get("vx_mae_mps"), row.get("ey_mae_m")
    return (
        f"planned {row['planned_lap_time_s']:.2f} s, closed loop {lap} "
        f"({row['completed']}/{row['trials']} completed), v_x MAE "
        f"{format_number(vx, 3)} m/s, e_y MAE {format_number(ey, 3)} m, "
        f"wall contacts {row['wall_contacts']}"
    )
