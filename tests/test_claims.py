"""The paper's claims about Tables I and II (racing_lib.experiments.ablation.claims), chapter 07."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from racing_lib.errors import ArgumentError
from racing_lib.experiments.ablation.claims import (
    CLAIMS,
    QUANTITIES,
    RELATIONS,
    Claim,
    agreement,
    citation,
    decided,
    direction,
    format_scores,
    score,
    verdict_counts,
    welch_interval,
)
from racing_lib.experiments.ablation.paper import (
    PAPER,
    PAPER_COLUMNS,
    PAPER_FIELDS,
    PAPER_ROW_LABELS,
    row_measures,
    row_trials,
)
from racing_lib.experiments.ablation.rows import ablation_rows
from racing_lib.experiments.ablation.table import shipped_table

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "07_experiments.ipynb"


def _uniform(changes: dict[str, dict[str, float]] | None = None) -> dict[str, dict]:
    """A made-up table: every row is the paper's main row, except ``changes`` (row -> fields)."""
    table = {name: dict(PAPER["main"]) for name in PAPER}
    for name, fields in (changes or {}).items():
        table[name].update(fields)
    return table


def _claim(text: str) -> Claim:
    (claim,) = [c for c in CLAIMS if c.text == text]
    return claim


def test_every_claim_reads_rows_and_quantities_of_both_tables():
    shipped = {row["name"]: row_measures(row) for row in shipped_table()}
    ours_rows = {r.name for r in ablation_rows()}
    assert len({c.text for c in CLAIMS}) == len(CLAIMS) == 28
    assert set(PAPER_ROW_LABELS) == set(PAPER) and set(PAPER_COLUMNS) == set(PAPER_FIELDS)
    for claim in CLAIMS:
        assert set(claim.rows) <= set(PAPER) & ours_rows & set(shipped), claim.text
        assert claim.relation in RELATIONS and claim.quantity in QUANTITIES, claim.text
        fields = QUANTITIES[claim.quantity].fields
        for row in claim.rows:
            assert set(fields) <= set(PAPER[row]) & set(shipped[row]), claim.text
            assert all(PAPER[row][f] is not None for f in fields), claim.text
            assert all(shipped[row][f] is not None for f in fields), claim.text
        # A comparison with another row has a base; a bound only where the relation uses one.
        assert (claim.base is None) == (claim.relation == "below"), claim.text
        assert (claim.bound is not None) == (claim.relation in ("below", "within")), claim.text
        cited = citation(claim)
        assert all(PAPER_ROW_LABELS[r][1] in cited for r in claim.rows), cited
        assert all(PAPER_COLUMNS[f] in cited for f in fields), cited
    assert citation(_claim("tracking the best lap: smaller e_y MAE")).startswith(
        "Tables I and II: row 'tracking the best human lap' vs 'main experiment"
    )


def test_every_claim_holds_on_the_papers_own_table():
    """The claims are the paper's: its own numbers must bear each of them out."""
    assert all(direction(c, PAPER) for c in CLAIMS)


def test_identical_rows_bear_out_no_direction_and_every_small_change():
    scores = score(_uniform())
    for s in scores:
        if s.claim.relation in ("greater", "less"):
            assert not s.ours, s.claim.text  # no row is faster or slower than another
        else:
            assert s.ours, s.claim.text  # 'within 0.5 %' of itself; main 1.6 % behind its plan
        assert s.paper


@pytest.mark.parametrize(
    ("text", "holds", "fails"),
    [
        # direction against the main row, in seconds, m/s, m and contacts per lap
        ("no drag: the closed loop is slower than main's", {"mean": 101.1}, {"mean": 100.9}),
        (
            "no drag: the plan is faster than main's (optimistic)",
            {"planned": 99.0},
            {"planned": 100.0},
        ),
        ("decoupled MPC: larger e_y MAE", {"ey": 0.2}, {"ey": 0.1}),
        ("decoupled MPC: more wall contacts", {"walls": 0.1}, {"walls": 0.0}),
        # a gap to the own plan: main plans 99.48 s and drives 101.03 s (1.56 %)
        (
            "curvature-optimal: the closed loop falls further behind its plan",
            {"planned": 99.0},
            {"planned": 100.0},
        ),
        # within 0.5 % of main's 101.03 s
        (
            "lateral weight transfer: closed loop within 0.5 % of main's",
            {"mean": 101.5},
            {"mean": 101.6},
        ),
    ],
)
def test_a_made_up_row_decides_a_claim_against_main(text, holds, fails):
    name = _claim(text).row
    assert direction(_claim(text), _uniform({name: holds}))
    assert not direction(_claim(text), _uniform({name: fails}))


def test_the_bounds_and_the_loss_to_the_reference():
    within_two_percent = _claim("closed loop within 2 % of its plan")
    assert direction(within_two_percent, _uniform({"main": {"planned": 100.0, "mean": 101.9}}))
    assert not direction(within_two_percent, _uniform({"main": {"planned": 100.0, "mean": 102.1}}))
    # main: 99.48 s planned, 101.03 s driven, 1.55 s lost; the best lap is planned 99.0 s.
    smaller_loss = _claim("tracking the best lap: smaller loss to the reference")
    assert direction(smaller_loss, _uniform({"best-lap": {"planned": 99.0, "mean": 100.5}}))
    assert not direction(smaller_loss, _uniform({"best-lap": {"planned": 99.0, "mean": 100.6}}))


def test_scores_mark_a_disagreement_and_take_another_verdict():
    ours = _uniform({"no-drag": {"mean": 100.0}})  # faster than main: the paper says slower
    scores = score(ours, claims=[_claim("no drag: the closed loop is slower than main's")])
    assert [(s.paper, s.ours, s.agrees) for s in scores] == [(True, False, False)]
    text = format_scores(scores)
    assert text.splitlines()[1].startswith("≠ ") and text.splitlines()[1].endswith("True False")
    assert text.endswith("agrees with the paper on 0 of 1 directions")
    # A verdict is swapped without touching the claims.
    assert agreement(score(ours, verdict=lambda claim, table: table is PAPER)) == 0
    assert agreement(score(ours, verdict=lambda claim, table: True)) == len(CLAIMS)


def test_a_table_without_a_claims_row_is_refused():
    ours = _uniform()
    del ours["best-lap"]
    with pytest.raises(ArgumentError, match="best-lap"):
        score(ours)


def _notebook_output(call: str) -> str:
    nb = json.loads(NOTEBOOK.read_text())
    (cell,) = [c for c in nb["cells"] if c["cell_type"] == "code" and call in "".join(c["source"])]
    return "".join("".join(o.get("text", "")) for o in cell["outputs"])


def test_the_shipped_table_scores_as_chapter_07_reports():
    rows = shipped_table()
    ours = {row["name"]: row_measures(row) for row in rows}
    trials = {row["name"]: row_trials(row) for row in rows}
    expected = format_scores(score(ours, trials=trials)) + "\n"
    assert _notebook_output("print(format_scores(") == expected


def test_the_welch_interval_is_the_one_of_welchs_t_test():
    rng = np.random.default_rng(3)
    x, y = rng.normal(1.0, 0.3, 10), rng.normal(0.7, 0.1, 8)
    lo, hi = welch_interval(x, y, level=0.95)
    # Welch's test rejects "no difference" at 5 % exactly when the 95 % interval excludes 0.
    p = stats.ttest_ind(x, y, equal_var=False).pvalue
    assert (lo > 0 or hi < 0) == (p < 0.05)
    half = stats.t.ppf(0.975, 10.44) * np.hypot(x.std(ddof=1) / 10**0.5, y.std(ddof=1) / 8**0.5)
    assert abs((hi - lo) / 2 - half) < 0.05 * half  # the Welch-Satterthwaite dof, about 10
    assert welch_interval(np.array([2.0, 2.0]), np.array([2.0])) == (0.0, 0.0)


def _noisy(rows: dict[str, tuple[float, float]]) -> tuple[dict, dict]:
    """A made-up table whose rows' closed-loop laps are 10 trials of mean +- spread."""
    table, trials = _uniform(), {}
    for name, (mean, spread) in rows.items():
        laps = mean + spread * np.linspace(-1.0, 1.0, 10)
        table[name] = {**table[name], "mean": float(laps.mean())}
        trials[name] = {"lap_time_s": laps}
    return table, trials


def test_a_difference_inside_the_spread_of_the_trials_is_indistinguishable():
    slower = _claim("decoupled MPC: the closed loop is slower")
    # 0.02 s slower on laps that spread by +-0.15 s: either answer was possible.
    table, trials = _noisy({"decoupled": (101.05, 0.15), "main": (101.03, 0.15)})
    assert direction(slower, table) and not decided(slower, table, trials)
    # 0.5 s slower on the same spread: decided.
    table, trials = _noisy({"decoupled": (101.53, 0.15), "main": (101.03, 0.15)})
    assert decided(slower, table, trials)
    within = _claim("lateral weight transfer: closed loop within 0.5 % of main's")
    table, trials = _noisy({"lateral-weight-transfer": (101.05, 0.1), "main": (101.03, 0.1)})
    assert decided(within, table, trials)  # the interval lies inside +-0.5 % of 101 s
    table, trials = _noisy({"lateral-weight-transfer": (101.4, 1.0), "main": (101.03, 1.0)})
    assert not decided(within, table, trials)  # it reaches past 0.5 %
    # The plan is deterministic: a planned-lap claim is always decided.
    optimistic = _claim("no drag: the plan is faster than main's (optimistic)")
    assert decided(optimistic, table, trials)


def test_scores_weighed_against_the_trials_say_which_are_within_the_noise():
    slower = _claim("decoupled MPC: the closed loop is slower")
    faster = _claim("no drag: the closed loop is slower than main's")
    table, trials = _noisy(
        {"decoupled": (101.05, 0.15), "no-drag": (100.0, 0.05), "main": (101.03, 0.15)}
    )
    scores = score(table, claims=[slower, faster], trials=trials)
    assert [s.verdict for s in scores] == ["indistinguishable", "disagrees"]
    assert verdict_counts(scores) == {"agrees": 0, "disagrees": 1, "indistinguishable": 1}
    text = format_scores(scores)
    assert text.splitlines()[1].startswith("~ ") and text.splitlines()[2].startswith("≠ ")
    assert text.endswith("agrees 0, disagrees 1, indistinguishable 1")
    # Without trials every answer counts as decided, as before.
    assert all(s.decided for s in score(table, claims=[slower, faster]))
