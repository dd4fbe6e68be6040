"""The ablation tables: every row from the real runner (on two short tracks standing in for the
built-in ones, with coarse plans), the cache (reuse, stale rows, interruption), the table's text,
the shipped table and the command line."""

from __future__ import annotations

import json
import logging
import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from racing_lib.errors import ControlError, RacingLibError, TrackError
from racing_lib.experiments.ablation import runner as ablation_runner
from racing_lib.experiments.ablation import table as ablation_table
from racing_lib.experiments.ablation.rows import (
    ablation_rows,
    select_rows,
)
from racing_lib.experiments.ablation.runner import run_ablation
from racing_lib.experiments.ablation.table import (
    format_table,
    generate_ablation_table,
    load_table,
    shipped_table,
    stale_rows,
)
from racing_lib.experiments.configs import (
    TUNING_CONFIGS,
    tuned_weights,
)
from racing_lib.experiments.tuning import MPC_WEIGHT_NAMES
from racing_lib.face.cli import main
from racing_lib.tracks import Arc, Straight, track_from_segments

#: Plan node spacing of the tests, m: coarse, so that every plan takes well under a second.
SPACING = 10.0
#: The fields of DESIGN.md's ``racing-lib ablation --json`` rows.
DESIGN_FIELDS = {
    "name", "planned_lap_time_s", "lap_time_mean_s", "lap_time_std_s", "lap_time_min_s",
    "vx_mae_mps", "ey_mae_m", "completed",
}  # fmt: skip
ALL_ROWS = [
    *TUNING_CONFIGS,
    "shortcut-main",
    "shortcut-lateral-weight-transfer",
    "best-lap",
]


@pytest.fixture(scope="module")
def tracks():
    """A 450 m walled oval for the expressway, a 350 m open one with tighter turns for the
    shortcut: laps of under 20 s, so one trial takes about a second."""
    oval = track_from_segments(
        [Straight(100.0), Arc.degrees(40.0, 180.0), Straight(100.0), Arc.degrees(40.0, 180.0)],
        width=12.0,
        boundary="walls",
        name="oval",
    )
    sharp = track_from_segments(
        [Straight(100.0), Arc.degrees(24.0, 180.0), Straight(100.0), Arc.degrees(24.0, 180.0)],
        width=12.0,
        boundary="open",
        name="sharp",
    )
    return {"expressway": oval, "shortcut": sharp}


@pytest.fixture(scope="module")
def table(tmp_path_factory, tracks):
    """The whole table, one trial per row, through the default local process pool."""
    logging.disable(logging.WARNING)  # MPC fallbacks of the ablations are expected
    out = tmp_path_factory.mktemp("ablation")
    rows = run_ablation(
        trials=1, workers=2, spacing=SPACING, out_dir=out, tracks=tracks, progress=False
    )
    logging.disable(logging.NOTSET)
    return out, rows


def _mtimes(folder) -> dict[str, int]:
    return {str(p): p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file()}


class Calls:
    """Wraps a function of the ablation runner and counts its calls (or refuses them)."""

    def __init__(self, monkeypatch, name: str, refuse: bool = False, interrupt_at: int = 0):
        self.fn = getattr(ablation_runner, name)
        self.name, self.refuse, self.interrupt_at, self.n = name, refuse, interrupt_at, 0
        monkeypatch.setattr(ablation_runner, name, self)

    def __call__(self, *args, **kwargs):
        self.n += 1
        if self.refuse:
            raise AssertionError(f"{self.name} was called although its result is cached")
        if self.n == self.interrupt_at:
            raise KeyboardInterrupt  # as Ctrl-C in the middle of a row
        return self.fn(*args, **kwargs)


# --------------------------------------------------------------------------------------------------
# Every row from the runner


def test_the_rows_are_the_papers(tracks):
    rows = ablation_rows()
    assert [r.name for r in rows] == ALL_ROWS
    assert [r.name for r in rows if r.track == "shortcut"] == ALL_ROWS[-3:-1]
    assert [r.table for r in rows].count("II") == 1 and rows[-1].best_lap
    # Within a track a configuration name selects that track's row; alone it means the expressway.
    assert [r.name for r in select_rows(["main"], track="shortcut")] == ["shortcut-main"]
    assert [r.name for r in select_rows(["best-lap", "main"])] == ["main", "best-lap"]
    with pytest.raises(ControlError, match="'bogus'.*no-drag"):
        select_rows(["bogus"])
    with pytest.raises(TrackError, match="'monza'.*expressway, shortcut"):
        select_rows(track="monza")


def test_every_row_is_produced_with_its_configuration(table, tracks):
    out, rows = table
    assert [r["name"] for r in rows] == ALL_ROWS
    by_name = {r["name"]: r for r in rows}
    for r in rows:
        assert DESIGN_FIELDS <= set(r), r["name"]
        row = next(x for x in ablation_rows() if x.name == r["name"])
        cfg = TUNING_CONFIGS[row.config]
        assert r["track"] == tracks[row.track].name
        assert r["controller"] == cfg["controller"]
        assert r["smooth_transition"] == cfg.get("smooth_transition", True)
        assert r["plan"]["method"] == ("best-lap" if row.best_lap else cfg["method"])
        assert r["plan"]["options"] == ({} if row.best_lap else cfg["options"])
        assert r["seeds"] == [0] and r["trials"] == 1 and len(r["trial_metrics"]) == 1
        trial = r["trial_metrics"][0]
        assert r["completed"] == int(trial["completed"])
        if trial["completed"]:
            assert r["lap_time_mean_s"] == trial["lap_time_s"] and r["lap_time_std_s"] == 0.0
        # With one trial the pooled errors are that lap's (float32 transport: 1e-6).
        assert r["vx_mae_mps"] == pytest.approx(trial["vx_mae_mps"], rel=1e-5)
        assert r["ey_max_m"] == pytest.approx(trial["ey_max_m"], rel=1e-5)
        assert r["wall_contacts"] == trial["wall_contacts"]
        tuned = tuned_weights(row.config)
        assert r["weights_source"] == ("tuned" if tuned else "defaults")
        assert set(MPC_WEIGHT_NAMES) <= set(r["weights"])
        for k, v in (tuned or {}).items():
            assert r["weights"][k] == pytest.approx(v)
        assert 0.0 < r["solve_time_ms_median"] <= r["solve_time_ms_p99"]
    # The plan is made once per (track, method, options): three rows drive the same plan.
    same = [by_name[n]["plan"]["key"] for n in ("main", "decoupled", "no-smooth-transition")]
    assert len(set(same)) == 1
    assert by_name["no-drag"]["plan"]["key"] != same[0]
    # Without drag the planner expects more speed on the straights: a faster plan.
    assert by_name["no-drag"]["planned_lap_time_s"] < by_name["main"]["planned_lap_time_s"]
    assert len(list((out / "plans").glob("*.csv"))) == 8  # 6 on the oval, 2 on the sharp track
    assert len(list((out / "rows").glob("*.json"))) == len(ALL_ROWS)


def test_profiles_follow_the_lap_on_the_track_grid(table, tracks):
    _, rows = table
    for r in rows:
        p = r["profile"]
        length = tracks["expressway" if r["track"] == "oval" else "shortcut"].length
        assert len(p["s_m"]) == math.ceil(length / 10.0)
        assert np.allclose(np.diff(p["s_m"]), 10.0)
        series = [*p["plan"].values(), *p["closed_loop"].values()]
        assert all(len(v) == len(p["s_m"]) for v in series)

        def arr(part, name, p=p):
            return np.array([np.nan if v is None else v for v in p[part][name]], float)

        # Both profiles sit at the same places: the speed gap never exceeds the lap's largest
        # speed error, and the car's offset from the centerline is the plan's plus e_y.
        gap = np.abs(arr("closed_loop", "vx_mps") - arr("plan", "vx_mps"))
        assert np.nanmax(gap) <= r["vx_max_err_mps"] + 0.5, r["name"]
        offset = arr("closed_loop", "n_m") - arr("plan", "n_m") - arr("closed_loop", "ey_m")
        assert np.nanmax(np.abs(offset)) < 0.3, r["name"]
    main_row = rows[0]
    kappa = np.array(main_row["profile"]["plan"]["kappa_radpm"])
    # The oval's turns have a 40 m centerline radius: the line's curvature peaks near 1/40.
    assert 0.7 / 40.0 < np.max(np.abs(kappa)) < 2.0 / 40.0


# --------------------------------------------------------------------------------------------------
# The cache


def test_a_rerun_reuses_every_finished_row(table, tracks, monkeypatch):
    out, rows = table
    before = _mtimes(out)
    Calls(monkeypatch, "_trial", refuse=True)
    Calls(monkeypatch, "_make_plan", refuse=True)
    seen = []
    again = run_ablation(
        trials=1,
        workers=2,
        spacing=SPACING,
        out_dir=out,
        tracks=tracks,
        progress=False,
        on_row=lambda row, reused: seen.append(reused),
    )
    assert again == rows
    assert seen == [True] * len(rows)
    assert _mtimes(out) == before  # nothing rewritten


def test_a_stale_row_is_recomputed_and_the_others_reused(table, tracks, monkeypatch):
    out, rows = table
    old = {r["name"]: r for r in rows}
    trials = Calls(monkeypatch, "_trial")
    plans = Calls(monkeypatch, "_make_plan")
    new_weights = {**(tuned_weights("no-smooth-transition") or {}), "w_ey": 7.0}
    monkeypatch.setattr(
        ablation_runner,
        "tuned_weights",
        lambda cfg: new_weights if cfg == "no-smooth-transition" else tuned_weights(cfg),
    )
    with ThreadPoolExecutor(max_workers=1) as pool:
        got = run_ablation(
            ["main", "no-smooth-transition"],
            trials=1,
            spacing=SPACING,
            out_dir=out,
            tracks=tracks,
            executor=pool,
            progress=False,
        )
        assert pool.submit(int, 3).result() == 3  # a given executor is left running
    assert (trials.n, plans.n) == (1, 0)  # only the stale row's lap; its plan came from disk
    assert got[0] == old["main"]
    assert got[1]["key"] != old["no-smooth-transition"]["key"]
    assert got[1]["weights"]["w_ey"] == 7.0 and got[1]["weights_source"] == "tuned"
    # Another plan spacing changes the plan's key: planned again, then driven.
    got = run_ablation(
        ["shortcut-main"], trials=1, spacing=12.0, out_dir=out, tracks=tracks, workers=1,
        progress=False,
    )  # fmt: skip
    assert (trials.n, plans.n) == (2, 1)
    assert got[0]["plan"]["spacing_m"] == 12.0


def test_an_interrupted_run_keeps_its_finished_rows(tmp_path, tracks, monkeypatch):
    names = ["shortcut-main", "shortcut-lateral-weight-transfer"]
    kwargs = dict(trials=2, spacing=SPACING, out_dir=tmp_path, tracks=tracks, workers=1)
    Calls(monkeypatch, "_trial", interrupt_at=3)  # the first trial of the second row
    with pytest.raises(KeyboardInterrupt):
        run_ablation(names, progress=False, **kwargs)
    files = sorted((tmp_path / "rows").iterdir())
    assert [f.name.split("-")[:2] for f in files] == [["shortcut", "main"]]
    finished = json.loads(files[0].read_text())
    assert not list(tmp_path.rglob("*.tmp"))  # no half-written file anywhere
    monkeypatch.undo()

    trials = Calls(monkeypatch, "_trial")
    rows = run_ablation(names, progress=False, **kwargs)
    assert trials.n == 2  # only the second row's two laps
    assert rows[0] == finished
    # Pooled over two laps: the mean lies between the laps' own, the max is the larger max.
    for r in rows:
        maes = [t["vx_mae_mps"] for t in r["trial_metrics"]]
        assert min(maes) - 1e-5 <= r["vx_mae_mps"] <= max(maes) + 1e-5
        assert r["ey_max_m"] == pytest.approx(max(t["ey_max_m"] for t in r["trial_metrics"]))
        assert r["seeds"] == [0, 1] and r["vx_mae_std_mps"] > 0.0


# --------------------------------------------------------------------------------------------------
# The table, the shipped file


def test_the_table_has_the_papers_columns(table):
    _, rows = table
    text = format_table(rows).splitlines()
    assert len(text) == 2 + len(rows)
    for col in ("planned lap [s]", "closed-loop lap [s]", "v_x MAE [m/s]", "e_y MAE [m]"):
        assert col in text[0]
    main_line = text[2]
    r = rows[0]
    assert main_line.startswith("main ") and f"{r['planned_lap_time_s']:.2f}" in main_line
    assert f"{r['vx_mae_mps']:.3f} ± {r['vx_mae_std_mps']:.3f}" in main_line
    md = format_table(rows, markdown=True).splitlines()
    assert md[0].startswith("| row |") and len(md) == 2 + len(rows)


def test_generate_writes_a_table_that_loads_back(table, tracks, tmp_path, monkeypatch):
    out, rows = table
    with pytest.raises(RacingLibError, match="fast mode"):
        generate_ablation_table(workers=1, out_dir=out, tracks=tracks)  # the shipped file
    Calls(monkeypatch, "_trial", refuse=True)
    target = tmp_path / "table.json"
    generate_ablation_table(
        workers=1, out_dir=out, target=target, trials=1, spacing=SPACING, tracks=tracks,
        progress=False,
    )  # fmt: skip
    data = load_table(target)
    assert [{k: v for k, v in r.items() if k != "sha256"} for r in data["rows"]] == rows
    assert data["fast_mode"] is True and data["trials"] == 1
    assert data["provenance"]["packages"]["casadi"] != "not installed"
    assert stale_rows(data["rows"], tracks=tracks) == []
    monkeypatch.setattr(ablation_table, "tuned_weights", lambda cfg: {"w_ey": 3.0})
    assert stale_rows(data["rows"], tracks=tracks) == ALL_ROWS  # every row's weights changed


@pytest.mark.slow
def test_the_shipped_table_holds_the_numbers_the_code_computes(capsys):
    """Every shipped row is either current (its key matches the code and data) or reproduced:
    its first lap, recomputed here, is the table's to the last bit. A refactor therefore passes
    without regenerating the table; a change that moves a number fails, naming the row.

    On a BLAS kernel without probes in the table a moved key cannot be judged: the test then
    says so (restamp on the table's kernel, or regenerate)."""
    from racing_lib.experiments.ablation.verify import verify_table

    checks, _ = verify_table(workers=2)
    with capsys.disabled():
        print("\nshipped ablation table: " + ", ".join(f"{c.name} {c.status}" for c in checks))
    moved = [f"{c.name}: {c.detail}" for c in checks if c.status == "moved"]
    assert not moved, "the shipped ablation table no longer holds:\n" + "\n".join(moved)
    unverifiable = [c.name for c in checks if c.status == "unverifiable"]
    if unverifiable:
        pytest.skip(f"rows {unverifiable} cannot be verified on this BLAS kernel: {checks[0]}")


def test_a_row_whose_first_lap_moved_is_caught_and_one_that_did_not_passes(monkeypatch):
    """The verdicts of verify_table, with the recomputation replaced by the table's own rows
    (as a refactor would give) or by rows with one changed bit (as a real change would)."""
    from racing_lib.experiments.ablation import verify

    data = ablation_table.shipped_table_file()
    rows = data["rows"]
    header = {k: v for k, v in data.items() if k != "rows"}
    header = {**header, "provenance": {**header["provenance"], "blas": verify.blas_kernel()}}
    stale = [rows[0]["name"], rows[1]["name"]]
    monkeypatch.setattr(verify, "stale_rows", lambda _rows: stale)
    by_name = {r["name"]: r for r in rows}

    def same(names, _rows, _workers):
        return {n: by_name[n] for n in names}

    monkeypatch.setattr(verify, "_recompute_first_laps", same)
    checks, _ = verify.verify_table(rows, header)
    assert [c.status for c in checks[:3]] == ["reproduced", "reproduced", "current"]

    def one_bit_off(names, _rows, _workers):
        out = same(names, _rows, _workers)
        first = dict(out[stale[1]]["trial_metrics"][0])
        first["ey_mae_m"] = float(np.nextafter(first["ey_mae_m"], 1.0))
        out[stale[1]] = {**out[stale[1]], "trial_metrics": [first]}
        return out

    monkeypatch.setattr(verify, "_recompute_first_laps", one_bit_off)
    checks, _ = verify.verify_table(rows, header)
    assert [c.status for c in checks[:2]] == ["reproduced", "moved"]
    assert "regenerate" in checks[1].detail
    # On a kernel the table has no probes for, a moved key is not judged but named as such.
    foreign = {**header, "provenance": {**header["provenance"], "blas": "another kernel"}}
    foreign["probes"] = {}
    checks, _ = verify.verify_table(rows, foreign)
    assert [c.status for c in checks[:3]] == ["unverifiable", "unverifiable", "current"]
    assert "restamp_table" in checks[0].detail
    # A probe ignores the controller's wall-clock times, and nothing else.
    timed = {**rows[0], "trial_metrics": [{**rows[0]["trial_metrics"][0],
                                           "solve_time_ms_median": 99.0}]}  # fmt: skip
    assert verify.probe(timed) == verify.probe(rows[0])
    assert verify.probe({**rows[0], "planned_lap_time_s": 1.0}) != verify.probe(rows[0])


def test_the_shipped_table_is_full_and_small_or_says_how_to_make_it():
    path = ablation_table.shipped_table_path()
    if not path.exists():
        with pytest.raises(RacingLibError, match="generate_ablation_table"):
            shipped_table()
        return
    rows = shipped_table()
    assert [r["name"] for r in rows] == ALL_ROWS
    assert all(DESIGN_FIELDS <= set(r) and r["trials"] == 10 for r in rows)
    assert not any(r["fast_mode"] for r in rows)
    assert path.stat().st_size < 1_000_000


def test_a_hand_edited_row_of_a_table_is_refused(table, tmp_path):
    _, rows = table
    path = tmp_path / "table.json"
    path.write_text(ablation_table.table_text({"format": ablation_table.TABLE_FORMAT}, rows))
    assert len(load_table(path)["rows"]) == len(rows)
    edited = json.loads(path.read_text())
    edited["rows"][0]["lap_time_mean_s"] -= 0.5  # a better lap time, typed in
    path.write_text(json.dumps(edited))
    with pytest.raises(RacingLibError, match="row 'main' .* fails its checksum"):
        load_table(path)


def test_a_table_without_provenance_and_checksums_is_refused(table, tmp_path):
    _, rows = table
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"format": 1, "rows": rows}))
    with pytest.raises(RacingLibError, match="regenerate"):
        load_table(path)


def test_the_comparison_passes_the_same_laps_and_fails_a_lap_that_moved(table):
    from racing_lib.experiments.ablation.check import (
        compare_rows,
        format_checks,
    )

    _, rows = table
    row = rows[0]
    assert all(c.ok for c in compare_rows(row, row))
    slower = json.loads(json.dumps(row))
    for m in slower["trial_metrics"]:
        m["lap_time_s"] += 1.0  # every lap a second slower: far beyond the spread of the laps
    checks = compare_rows(row, slower)
    moved = [c.quantity for c in checks if not c.ok]
    assert moved == ["closed-loop lap, mean [s]"]
    assert "MOVED" in format_checks(checks)
    # Two laps against ten: shares and rates, not counts, so nothing "moves".
    ten = {
        **row,
        "trials": 10,
        "completed": 10 * row["completed"],
        "wall_contacts": 10 * row["wall_contacts"],
        "trial_metrics": row["trial_metrics"] * 10,
    }
    assert all(c.ok for c in compare_rows(ten, row)), format_checks(compare_rows(ten, row))
    replanned = {**row, "planned_lap_time_s": row["planned_lap_time_s"] * 1.01}
    assert [c.quantity for c in compare_rows(row, replanned) if not c.ok] == ["planned lap [s]"]


@pytest.mark.slow
def test_the_main_row_recomputed_here_matches_the_shipped_one(tmp_path, capsys):
    """CI recomputes the paper's main row with its ten seeds and compares it with the shipped
    row within the statistical tolerances of racing_lib.experiments.ablation.check."""
    from racing_lib.experiments.ablation.check import (
        compare_rows,
        format_checks,
    )

    shipped = {r["name"]: r for r in shipped_table()}["main"]
    logging.disable(logging.WARNING)
    try:
        (row,) = run_ablation(
            ["main"], trials=len(shipped["seeds"]), seed=shipped["seeds"][0],
            out_dir=tmp_path, workers=2, progress=False,
        )  # fmt: skip
    finally:
        logging.disable(logging.NOTSET)
    checks = compare_rows(shipped, row)
    report = format_checks(checks)
    with capsys.disabled():
        print(f"\nthe main row recomputed ({len(row['seeds'])} seeds) against the shipped one:")
        print(report)
    assert all(c.ok for c in checks), report


# --------------------------------------------------------------------------------------------------
# The command line


def test_cli_shows_the_shipped_table_at_once_in_an_empty_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    Calls(monkeypatch, "_trial", refuse=True)
    Calls(monkeypatch, "_get_plan", refuse=True)
    assert main(["ablation", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in report["rows"]] == ALL_ROWS
    assert {r["source"] for r in report["rows"]} == {"shipped"}
    made = report["shipped_provenance"]
    assert made["packages"]["casadi"] and made["cpu_count"] >= 1 and made["blas"]
    assert report["checks"] == [] and not any(tmp_path.iterdir())
    assert main(["ablation", "--rows", "main,decoupled"]) == 0
    text = capsys.readouterr().out
    assert "shipped rows: made" in text and text.count("shipped") >= 3


def test_cli_recompute_marks_the_row_and_check_fails_on_numbers_that_moved(
    tracks, monkeypatch, capsys, tmp_path
):
    out = tmp_path / "cache"
    monkeypatch.setattr(ablation_runner, "load_track", lambda name: tracks[name])
    args = ["ablation", "--rows", "decoupled", "--recompute", "main", "--trials", "1",
            "--spacing", str(SPACING), "--out", str(out)]  # fmt: skip
    assert main([*args, "--json"]) == 0  # the coarse oval's row differs: shown, not an error
    report = json.loads(capsys.readouterr().out)
    assert [r["source"] for r in report["rows"]] == ["recomputed", "shipped"]
    assert report["this_machine"]["packages"]["numpy"]
    assert any(not c["ok"] for c in report["checks"])
    assert main([*args, "--check"]) == 1
    captured = capsys.readouterr()
    assert "MOVED" in captured.out and "moved beyond tolerance" in captured.err


def test_cli_json_prints_one_object_with_the_rows(table, tracks, monkeypatch, capsys):
    out, rows = table
    monkeypatch.setattr(ablation_runner, "load_track", lambda name: tracks[name])
    Calls(monkeypatch, "_trial", refuse=True)  # reused from the table's folder
    code = main(
        ["ablation", "--track", "shortcut", "--trials", "1", "--spacing", str(SPACING),
         "--out", str(out), "--json"]
    )  # fmt: skip
    captured = capsys.readouterr()
    report = json.loads(captured.out)  # the whole of stdout is one JSON object
    assert code == 0 and {"rows", "checks", "shipped_provenance"} <= set(report)
    assert [r["name"] for r in report["rows"]] == ALL_ROWS[-3:-1]  # the shortcut's rows
    assert {r["source"] for r in report["rows"]} == {"recomputed"}  # found in --out
    for r in report["rows"]:
        assert DESIGN_FIELDS <= set(r) and "profile" not in r
    assert report["rows"][0]["lap_time_mean_s"] == rows[-3]["lap_time_mean_s"]
    assert "shortcut-main: reused" in captured.err


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--rows", "main,bogus"], "'bogus'"),
        (["--track", "nurburgring"], "'nurburgring'"),
        (["--trials", "0"], "at least 1"),
    ],
)
def test_cli_bad_input_is_one_clear_error(args, needle, capsys, tmp_path):
    code = main(["ablation", "--json", "--out", str(tmp_path), *args])
    captured = capsys.readouterr()
    assert code == 2 and captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0]
    assert not any(tmp_path.iterdir())  # refused before anything was computed
