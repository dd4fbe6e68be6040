"""Is a recomputed row of the ablation table the shipped one? A statistical comparison.

The closed-loop numbers of a row are means over seeded laps, and a lap is chaotic: another BLAS
kernel or solver version changes the last digits of a sum, and a few seconds later the car is on
another line. So a recomputed row is compared with the shipped one within tolerances that grow
with the spread of the laps themselves, not digit by digit:

* the planned lap time (deterministic on one machine; across CPU kernels it moved by at most
  0.03 % when measured) within :data:`PLAN_RTOL`;
* each per-lap mean (lap time, v_x MAE, e_y MAE) within ``Z`` standard errors of the difference
  of two means, ``Z * sqrt(sd_a**2 / n_a + sd_b**2 / n_b)``, with a floor of :data:`MEAN_RTOL`
  of the value (so that two identical sets of laps, whose spread may be tiny, still compare);
* the share of completed laps within :data:`COMPLETED_SLACK` laps of the smaller row, and the
  wall contacts per lap within ``Z * sqrt(c_a / n_a**2 + c_b / n_b**2) + 1 / min(n_a, n_b)``
  (counts are roughly Poisson); rows of different trial counts therefore compare;
* a row of one lap borrows the other row's lap-to-lap spread.

On the machine that made the table, with the same code and seeds, every difference is zero.
Used by the tests (CI recomputes the ``main`` row) and by ``racing-lib ablation --recompute``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from racing_lib.experiments.ablation.rows import TableRow

#: Standard errors allowed between two means (3: a false alarm about 3 times in 1,000).
Z = 3.0
#: Relative tolerance of the planned lap time.
PLAN_RTOL = 1e-3
#: Relative floor of every per-lap mean's tolerance.
MEAN_RTOL = 5e-4
#: Completed laps that may differ (a chaotic lap near a wall may end either way).
COMPLETED_SLACK = 1


@dataclass(frozen=True)
class Check:
    """One quantity of a row, shipped against recomputed.

    Attributes
    ----------
    row, quantity : str
        The row's name and what is compared (with its unit).
    shipped, recomputed : float or None
        The two values (None where a row has no value, e.g. no lap completed).
    tolerance : float
        The largest allowed absolute difference, in the quantity's unit.
    """

    row: str
    quantity: str
    shipped: float | None
    recomputed: float | None
    tolerance: float

    @property
    def difference(self) -> float:
        """Recomputed - shipped (NaN when either is missing)."""
        if self.shipped is None or self.recomputed is None:
            return math.nan
        return self.recomputed - self.shipped

    @property
    def ok(self) -> bool:
        """Within tolerance (two missing values agree; one missing value does not)."""
        if self.shipped is None and self.recomputed is None:
            return True
        return abs(self.difference) <= self.tolerance


def _per_lap(row: TableRow, key: str) -> list[float]:
    values = [m.get(key) for m in row.get("trial_metrics", [])]
    return [float(v) for v in values if v is not None and math.isfinite(float(v))]


def _sd(values: Sequence[float]) -> float:
    n = len(values)
    if n < 2:
        return 0.0
    mean = sum(values) / n
    return math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))


def _mean_check(name: str, quantity: str, a: TableRow, b: TableRow, key: str) -> Check:
    """Compare the per-lap means of ``key`` (over the trials) of two rows.

    A side with a single lap has no spread of its own; it borrows the other side's.
    """
    la, lb = _per_lap(a, key), _per_lap(b, key)
    ma = sum(la) / len(la) if la else None
    mb = sum(lb) / len(lb) if lb else None
    sa, sb = _sd(la), _sd(lb)
    sa = sa if len(la) > 1 else sb
    sb = sb if len(lb) > 1 else sa
    se = math.sqrt(sa**2 / max(len(la), 1) + sb**2 / max(len(lb), 1))
    floor = MEAN_RTOL * abs(ma if ma is not None else (mb or 0.0))
    return Check(name, quantity, ma, mb, max(Z * se, floor))


def compare_rows(shipped: TableRow, recomputed: TableRow) -> list[Check]:
    """The checks of one row: planned lap, per-lap means, completed laps, wall contacts.

    Parameters
    ----------
    shipped, recomputed : TableRow
        Two rows of the same name, as :func:`racing_lib.experiments.ablation.run_ablation`
        returns them.
    """
    name = str(shipped.get("name"))
    planned = float(shipped["planned_lap_time_s"])
    walls_a, walls_b = int(shipped["wall_contacts"]), int(recomputed["wall_contacts"])
    # Counts as shares of the laps, so that rows of different trial counts compare.
    n_a, n_b = max(int(shipped["trials"]), 1), max(int(recomputed["trials"]), 1)
    fewer = min(n_a, n_b)
    return [
        Check(
            name,
            "planned lap [s]",
            planned,
            float(recomputed["planned_lap_time_s"]),
            PLAN_RTOL * planned,
        ),
        _mean_check(name, "closed-loop lap, mean [s]", shipped, recomputed, "lap_time_s"),
        _mean_check(name, "v_x MAE, mean of laps [m/s]", shipped, recomputed, "vx_mae_mps"),
        _mean_check(name, "e_y MAE, mean of laps [m]", shipped, recomputed, "ey_mae_m"),
        Check(
            name,
            "completed, share of laps",
            float(shipped["completed"]) / n_a,
            float(recomputed["completed"]) / n_b,
            COMPLETED_SLACK / fewer,
        ),
        Check(
            name,
            "wall contacts per lap",
            walls_a / n_a,
            walls_b / n_b,
            Z * math.sqrt(walls_a / n_a**2 + walls_b / n_b**2) + 1.0 / fewer,
        ),
    ]


def format_checks(checks: Sequence[Check]) -> str:
    """The checks as an aligned text table, one line each, ``ok`` or ``MOVED``."""

    def num(x: float | None) -> str:
        return "-" if x is None or not math.isfinite(x) else f"{x:.4f}"

    header = ("row", "quantity", "shipped", "recomputed", "difference", "tolerance", "")
    lines = [header]
    for c in checks:
        lines.append(
            (
                c.row,
                c.quantity,
                num(c.shipped),
                num(c.recomputed),
                num(c.difference),
                num(c.tolerance),
                "ok" if c.ok else "MOVED",
            )
        )
    widths = [max(len(line[i]) for line in lines) for i in range(len(header))]
    return "\n".join(
        "  ".join(field.ljust(w) for field, w in zip(line, widths, strict=True)) for line in lines
    )
