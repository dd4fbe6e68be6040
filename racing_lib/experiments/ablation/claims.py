"""The paper's claims about its Tables I and II, as data, and their verdict on a table (chapter 07).

The paper's conclusions are statements of direction: removing drag makes the plan optimistic and the
lap slower, the curvature-optimal plan is slower than the time-optimal one, the decoupled MPC tracks
worse, lateral weight transfer changes little. :data:`CLAIMS` writes each of them as a
:class:`Claim`, a comparison of one quantity (:data:`QUANTITIES`) of one row with another row's, or
with a bound, that can be decided on any table of measures (row name -> the fields of
:data:`~racing_lib.experiments.ablation.paper.PAPER_FIELDS`): the paper's own
(:data:`~racing_lib.experiments.ablation.paper.PAPER`) and ours
(:func:`~racing_lib.experiments.ablation.paper.row_measures` of each row). Each claim cites the rows and the column of the paper it reads (:func:`citation`).

:func:`score` decides every claim on both tables with a verdict function, by default
:func:`direction` (the plain comparison of the numbers); another verdict (one that takes the
spread of the laps into account, say) has the same signature, :data:`Verdict`, and replaces it
without changing the claims. :func:`format_scores` prints the result as chapter 07 shows it.

Examples
--------
>>> from racing_lib.experiments.ablation.claims import CLAIMS, score
>>> from racing_lib.experiments.ablation.paper import PAPER
>>> scores = score(PAPER)  # the paper's table against itself
>>> sum(s.agrees for s in scores) == len(CLAIMS)
True
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from racing_lib.errors import ArgumentError
from racing_lib.experiments.ablation.paper import (
    PAPER,
    PAPER_COLUMNS,
    PAPER_ROW_LABELS,
    plan_gap,
)

__all__ = [
    "CLAIMS",
    "LEVEL",
    "QUANTITIES",
    "RELATIONS",
    "Claim",
    "Quantity",
    "Score",
    "Verdict",
    "agreement",
    "citation",
    "decided",
    "direction",
    "format_scores",
    "score",
    "verdict_counts",
    "welch_interval",
]

#: A table the claims are decided on: row name -> field of
#: :data:`~racing_lib.experiments.ablation.paper.PAPER_FIELDS` -> value.
Measures = Mapping[str, Mapping[str, Any]]


@dataclass(frozen=True)
class Quantity:
    """One number of a row that a claim compares.

    Attributes
    ----------
    name : str
        The key a :class:`Claim` uses.
    fields : tuple of str
        The fields of :data:`~racing_lib.experiments.ablation.paper.PAPER_FIELDS` it is computed
        from (the paper's columns it reads).
    unit : str
        Its unit (``"1"``: a fraction).
    value : callable
        ``value(measures) -> float``: the quantity from one row's measures.
    per_trial : callable or None
        ``per_trial(measures, trials) -> ndarray``: the quantity of each completed trial of the row
        (``trials`` from :func:`~racing_lib.experiments.ablation.paper.row_trials`), whose spread
        :func:`decided` weighs; None for a quantity without spread (the plan is deterministic).
    """

    name: str
    fields: tuple[str, ...]
    unit: str
    value: Callable[[Mapping[str, Any]], float]
    per_trial: Callable[[Mapping[str, Any], Mapping[str, np.ndarray]], np.ndarray] | None = None


def _field(name: str, unit: str, trial_field: str | None = None) -> Quantity:
    per_trial = None if trial_field is None else (lambda m, trials: trials[trial_field])
    return Quantity(name, (name,), unit, lambda m: m[name], per_trial)


#: The quantities of :data:`CLAIMS`, by name: four columns of the paper's tables, the wall contacts
#: its text counts, the closed loop's gap to its plan
#: (:func:`~racing_lib.experiments.ablation.paper.plan_gap`, a fraction) and its loss to the plan
#: (closed-loop mean - planned lap, s).
QUANTITIES: dict[str, Quantity] = {
    "planned": _field("planned", "s"),
    "mean": _field("mean", "s", "lap_time_s"),
    "vx": _field("vx", "m/s", "vx_mae_mps"),
    "ey": _field("ey", "m", "ey_mae_m"),
    "walls": _field("walls", "contacts", "wall_contacts"),
    "plan_gap": Quantity(
        "plan_gap", ("planned", "mean"), "1", plan_gap,
        lambda m, trials: trials["lap_time_s"] / m["planned"] - 1.0,
    ),
    "loss": Quantity(
        "loss", ("planned", "mean"), "s", lambda m: m["mean"] - m["planned"],
        lambda m, trials: trials["lap_time_s"] - m["planned"],
    ),
}  # fmt: skip

#: The comparisons a claim can make, ``(row value, base value or None, bound or None) -> bool``:
#: ``greater`` and ``less`` than the base row's value, ``below`` a bound, and ``within`` a relative
#: bound of the base row's value (``abs(row / base - 1) < bound``).
RELATIONS: dict[str, Callable[[Any, Any, Any], bool]] = {
    "greater": lambda x, base, bound: x > base,
    "less": lambda x, base, bound: x < base,
    "below": lambda x, base, bound: x < bound,
    "within": lambda x, base, bound: abs(x / base - 1) < bound,
}


@dataclass(frozen=True)
class Claim:
    """One statement of the paper about its tables, decidable on a table.

    Attributes
    ----------
    group : str
        What the claim is about: ``"main"``, ``"model"``, ``"planning"``, ``"control"``,
        ``"sharper track"`` or ``"best lap"``.
    text : str
        The claim in words, as chapter 07 prints it (unique among :data:`CLAIMS`).
    row : str
        The row the claim is about (a key of
        :data:`~racing_lib.experiments.ablation.paper.PAPER`).
    quantity : str
        What is compared, a key of :data:`QUANTITIES`.
    relation : str
        How, a key of :data:`RELATIONS`: the row's quantity is ``greater`` or ``less`` than the
        base's, ``below`` the bound, or ``within`` the relative bound of the base's.
    base : str or None
        The row it is compared with (None for ``below``).
    bound : float or None
        The bound of ``below`` (in the quantity's unit) and ``within`` (a fraction, 0.005 = 0.5 %).
    """

    group: str
    text: str
    row: str
    quantity: str
    relation: str
    base: str | None = None
    bound: float | None = None

    @property
    def rows(self) -> tuple[str, ...]:
        """The rows the claim reads: its row, then its base if it has one."""
        return (self.row,) if self.base is None else (self.row, self.base)


def _claims() -> tuple[Claim, ...]:
    c = Claim
    main, lwt, cp = "main", "lateral-weight-transfer", "curvature-plan"
    nl, ns, sc = "no-longitudinal-weight-transfer", "no-smooth-transition", "shortcut-main"
    half_percent = 0.005  # "changes little": within 0.5 % of the main row's lap time
    # One claim per line: group, text, row, quantity, relation, base row, bound.
    # fmt: off
    return (
        c("main", "closed loop within 2 % of its plan", main, "plan_gap", "below", None, 0.02),
        c("model", "no drag: the plan is faster than main's (optimistic)", "no-drag", "planned", "less", main),
        c("model", "no drag: the closed loop is slower than main's", "no-drag", "mean", "greater", main),
        c("model", "no drag: larger v_x MAE than main", "no-drag", "vx", "greater", main),
        c("model", "no drag: the closed loop falls further behind its plan", "no-drag", "plan_gap", "greater", main),
        c("model", "no long. weight transfer: the plan is slower than main's", nl, "planned", "greater", main),
        c("model", "no long. weight transfer: the closed loop is slower", nl, "mean", "greater", main),
        c("model", "lateral weight transfer: plan within 0.5 % of main's", lwt, "planned", "within", main, half_percent),
        c("model", "lateral weight transfer: closed loop within 0.5 % of main's", lwt, "mean", "within", main, half_percent),
        c("planning", "curvature-optimal: the plan is slower than the time-optimal one", cp, "planned", "greater", main),
        c("planning", "curvature-optimal: the closed loop is slower", cp, "mean", "greater", main),
        c("planning", "curvature-optimal: larger v_x MAE", cp, "vx", "greater", main),
        c("planning", "curvature-optimal: the closed loop falls further behind its plan", cp, "plan_gap", "greater", main),
        c("control", "decoupled MPC: the closed loop is slower", "decoupled", "mean", "greater", main),
        c("control", "decoupled MPC: larger v_x MAE", "decoupled", "vx", "greater", main),
        c("control", "decoupled MPC: larger e_y MAE", "decoupled", "ey", "greater", main),
        c("control", "decoupled MPC: more wall contacts", "decoupled", "walls", "greater", main),
        c("control", "no smooth transition: the closed loop is slower", ns, "mean", "greater", main),
        c("control", "no smooth transition: larger v_x MAE", ns, "vx", "greater", main),
        c("control", "no smooth transition: larger e_y MAE", ns, "ey", "greater", main),
        c("sharper track", "shortcut: falls further behind its plan than the expressway", sc, "plan_gap", "greater", main),
        c("sharper track", "shortcut: larger e_y MAE than the expressway", sc, "ey", "greater", main),
        c("sharper track", "shortcut, lateral weight transfer: plan within 0.5 %", "shortcut-lateral-weight-transfer", "planned", "within", sc, half_percent),
        c("best lap", "our plan is slower than the best lap", main, "planned", "greater", "best-lap"),
        c("best lap", "tracking the best lap: faster closed loop than tracking our plan", "best-lap", "mean", "less", main),
        c("best lap", "tracking the best lap: smaller loss to the reference", "best-lap", "loss", "less", main),
        c("best lap", "tracking the best lap: smaller e_y MAE", "best-lap", "ey", "less", main),
        c("best lap", "tracking the best lap: larger v_x MAE", "best-lap", "vx", "greater", main),
    )
    # fmt: on


#: The paper's 28 claims about its Tables I and II, in the order chapter 07 reads them.
CLAIMS: tuple[Claim, ...] = _claims()


def citation(claim: Claim) -> str:
    """Where in the paper a claim comes from: its tables' rows and the columns it reads.

    For example ``"Table I: row '✗ wind drag force' vs 'main experiment (Tokyo Expressway)';
    planned lap time [s]"``.
    """
    tables = sorted({PAPER_ROW_LABELS[r][0] for r in claim.rows})
    rows = " vs ".join(f"'{PAPER_ROW_LABELS[r][1]}'" for r in claim.rows)
    columns = ", ".join(PAPER_COLUMNS[f] for f in QUANTITIES[claim.quantity].fields)
    where = f"Table {tables[0]}" if len(tables) == 1 else f"Tables {' and '.join(tables)}"
    return f"{where}: row {rows}; {columns}"


#: A verdict function: ``verdict(claim, table) -> bool``, whether ``claim`` holds on ``table``
#: (row name -> measures of
#: :func:`~racing_lib.experiments.ablation.paper.row_measures`). :func:`score` takes any such one.
Verdict = Callable[[Claim, Measures], bool]


def direction(claim: Claim, table: Measures) -> bool:
    """Whether ``claim`` holds on ``table``, comparing its numbers as they are (no spread).

    Parameters
    ----------
    claim : Claim
        The claim.
    table : mapping
        Row name -> measures (the fields of
        :data:`~racing_lib.experiments.ablation.paper.PAPER_FIELDS`, units as there).

    Returns
    -------
    bool
        The claim's relation between the row's quantity and the base row's (or the bound).
    """
    quantity = QUANTITIES[claim.quantity].value
    x = quantity(table[claim.row])
    base = None if claim.base is None else quantity(table[claim.base])
    return bool(RELATIONS[claim.relation](x, base, claim.bound))


#: Confidence level of :func:`decided`.
LEVEL = 0.95


def welch_interval(x: np.ndarray, y: np.ndarray, level: float = LEVEL) -> tuple[float, float]:
    """Confidence interval of ``mean(x) - mean(y)`` for two samples of unequal spread (Welch).

    ``y`` may hold a single value without spread (a bound, a deterministic plan): the interval
    is then the one-sample interval of ``mean(x)`` shifted by it.

    Returns
    -------
    (float, float)
        The interval's ends; both equal the difference when neither sample has any spread.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    diff = float(x.mean() - y.mean())
    parts = [a.var(ddof=1) / a.size if a.size > 1 else 0.0 for a in (x, y)]
    se2 = parts[0] + parts[1]
    if se2 <= 0.0:
        return diff, diff
    # Welch-Satterthwaite degrees of freedom; a sample of one contributes none.
    dof = se2**2 / sum(p**2 / (a.size - 1) for p, a in zip(parts, (x, y), strict=True) if p > 0)
    half = float(stats.t.ppf(0.5 + level / 2.0, dof)) * math.sqrt(se2)
    return diff - half, diff + half


def decided(
    claim: Claim,
    table: Measures,
    trials: Mapping[str, Mapping[str, np.ndarray]],
    level: float = LEVEL,
) -> bool:
    """Whether ``table`` answers ``claim`` beyond the spread of its trials.

    The claim's quantity is taken trial by trial (the completed laps of each row, seeds as
    samples), and the ``level`` confidence interval of the difference it compares is computed
    (:func:`welch_interval`): against the base row's trials, or against the bound. The answer is
    decided when the whole interval lies on one side of the claim's boundary (for ``within``:
    wholly inside or wholly outside the relative bound of the base's mean); when the boundary is
    inside the interval, the trials could have given either answer. A quantity without spread
    (the planned lap) and a row without two completed laps are always decided.

    Parameters
    ----------
    claim : Claim
        The claim.
    table : mapping
        Row name -> measures.
    trials : mapping
        Row name -> per-trial arrays (:func:`~racing_lib.experiments.ablation.paper.row_trials`).
    level : float
        Confidence level of the interval.
    """
    quantity = QUANTITIES[claim.quantity]
    if quantity.per_trial is None or claim.row not in trials:
        return True

    def samples(name: str) -> np.ndarray:
        values = quantity.per_trial(table[name], trials[name])  # type: ignore[misc]
        return np.asarray(values, dtype=float)

    x = samples(claim.row)
    if claim.relation == "below":
        y = np.array([claim.bound], dtype=float)
    else:
        y = samples(str(claim.base))
    if x.size < 2 or y.size < 1 or not np.all(np.isfinite(x)) or not np.all(np.isfinite(y)):
        return True
    lo, hi = welch_interval(x, y, level)
    if claim.relation == "within":
        limit = float(claim.bound) * abs(float(y.mean()))
        return (-limit < lo and hi < limit) or hi <= -limit or lo >= limit
    return lo > 0.0 or hi < 0.0 or lo == hi


@dataclass(frozen=True)
class Score:
    """One claim decided on the paper's table and on ours.

    Attributes
    ----------
    claim : Claim
        The claim.
    paper, ours : bool
        Whether it holds on the paper's table and on ours.
    decided : bool
        Whether our answer stands beyond the spread of our trials (:func:`decided`); True when
        no trials were given to weigh it.
    """

    claim: Claim
    paper: bool
    ours: bool
    decided: bool = True

    @property
    def agrees(self) -> bool:
        """Our table decides the claim as the paper's does."""
        return self.paper == self.ours

    @property
    def verdict(self) -> str:
        """``"agrees"``, ``"disagrees"``, or ``"indistinguishable"`` when our trials cannot tell."""
        if not self.decided:
            return "indistinguishable"
        return "agrees" if self.agrees else "disagrees"


def score(
    ours: Measures,
    paper: Measures = PAPER,
    claims: Sequence[Claim] = CLAIMS,
    verdict: Verdict = direction,
    trials: Mapping[str, Mapping[str, np.ndarray]] | None = None,
    level: float = LEVEL,
) -> list[Score]:
    """Decide every claim on the paper's table and on ours.

    With ``trials``, each of our answers is also weighed against the spread of our laps
    (:func:`decided`), and a claim our trials cannot answer is scored ``indistinguishable``
    (:attr:`Score.verdict`). The paper's table gives no per-trial laps: its answers are taken as
    its authors drew them.

    Parameters
    ----------
    ours : mapping
        Our table: row name -> measures (``row_measures`` of each row of the ablation table).
    paper : mapping
        The paper's table (default :data:`~racing_lib.experiments.ablation.paper.PAPER`).
    claims : sequence of Claim
        The claims (default :data:`CLAIMS`).
    verdict : Verdict
        Decides one claim on one table (default :func:`direction`).
    trials : mapping, optional
        Our rows' per-trial arrays (row name ->
        :func:`~racing_lib.experiments.ablation.paper.row_trials`).
    level : float
        Confidence level of the interval that weighs our answers.

    Returns
    -------
    list of Score
        One per claim, in the claims' order.

    Raises
    ------
    ArgumentError
        A claim reads a row that one of the tables lacks.
    """
    for name, table in (("our", ours), ("the paper's", paper)):
        missing = sorted({r for c in claims for r in c.rows} - set(table))
        if missing:
            raise ArgumentError(
                f"the claims read rows that {name} table lacks: {', '.join(missing)}; pass a table "
                "with every row of the ablation (or only the claims about the rows it has)."
            )
    return [
        Score(
            c,
            verdict(c, paper),
            verdict(c, ours),
            True if trials is None else decided(c, ours, trials, level),
        )
        for c in claims
    ]


def agreement(scores: Sequence[Score]) -> int:
    """How many claims our table decides as the paper's does."""
    return sum(s.agrees for s in scores)


def verdict_counts(scores: Sequence[Score]) -> dict[str, int]:
    """How many claims are ``agrees``, ``disagrees`` and ``indistinguishable``."""
    counts = {"agrees": 0, "disagrees": 0, "indistinguishable": 0}
    for s in scores:
        counts[s.verdict] += 1
    return counts


def format_scores(scores: Sequence[Score]) -> str:
    """The scores as chapter 07 prints them: one line per claim, then the counts.

    A claim our table decides otherwise than the paper's is marked ``≠`` in the first column, one
    our trials cannot answer (:func:`decided`) ``~``; the marks lead the line so that a page
    narrower than the table still shows them.
    """
    lines = [f"  {'':<14}{'claim':<65}{'paper':>6}{'ours':>6}"]
    for s in scores:
        mark = "~" if not s.decided else ("" if s.agrees else "≠")
        lines.append(f"{mark:<2}{s.claim.group:<14}{s.claim.text:<65}{s.paper!s:>6}{s.ours!s:>6}")
    lines.append("")
    lines.append(
        f"the simulated car agrees with the paper on {agreement(scores)} of {len(scores)} directions"
    )
    if not all(s.decided for s in scores):
        counts = verdict_counts(scores)
        lines.append(
            f"~ within the noise of our trials ({100 * LEVEL:.0f} % intervals), "
            "≠ decided otherwise than the paper"
        )
        lines.append(
            f"weighed: agrees {counts['agrees']}, disagrees {counts['disagrees']}, "
            f"indistinguishable {counts['indistinguishable']}"
        )
    return "\n".join(lines)
