"""The racing-lib command: JSON output, human output, and one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from racing_lib.face.cli import main


def test_tracks_json_lists_the_builtin_tracks(capsys):
    assert main(["tracks", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    names = {t["name"]: t for t in out["tracks"]}
    assert set(names) == {"expressway", "shortcut"}
    assert 4300 < names["expressway"]["length_m"] < 4500
    assert names["expressway"]["boundary"] == "walls"
    assert names["shortcut"]["boundary"] == "open"


def test_tracks_human_output_is_a_table(capsys):
    assert main(["tracks"]) == 0
    out = capsys.readouterr().out
    assert "expressway" in out and "walls" in out


def test_lap_nominal_centerline_prints_exactly_one_json_object(capsys, tmp_path):
    code = main(
        ["lap", "--controller", "nominal", "--method", "centerline", "--json",
         "--out", str(tmp_path)]
    )  # fmt: skip
    captured = capsys.readouterr()
    report = json.loads(captured.out)  # the whole of stdout is one JSON object
    assert code == 0
    assert report["track"] == "expressway"
    assert report["controller"] == "nominal"
    trial = report["trials"][0]
    expected = {
        "seed", "completed", "lap_time_s", "vx_mae_mps", "vx_max_err_mps", "ey_mae_m", "ey_max_m",
        "wall_contacts", "wall_contact_time_s", "offtrack_time_s", "solve_time_ms_median",
        "solve_time_ms_p99",
    }  # fmt: skip
    assert expected <= set(trial)
    assert trial["completed"] and trial["wall_contacts"] == 0
    assert report["summary"]["completed"] == 1
    # The nominal controller keeps within 3 % of its (moderate) reference lap time.
    assert report["summary"]["lap_time_mean_s"] == pytest.approx(
        report["planned_lap_time_s"], rel=0.03
    )
    for name in ("track.png", "profiles.png", "summary.json", "plan.csv", "log_seed0.npz"):
        assert (tmp_path / name).exists(), name


def test_unknown_track_is_one_clear_error(capsys):
    assert main(["tracks"]) == 0
    capsys.readouterr()
    code = main(["lap", "--track", "nurburgring", "--controller", "nominal", "--json"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error:") and "expressway" in err
    assert "Traceback" not in err


def test_a_broken_csv_is_one_clear_error(capsys, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("# x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,5,5\n10,0,5,nan\n10,10,5,5\n0,10,5,5\n")
    code = main(["lap", "--track", str(bad), "--controller", "nominal", "--method", "centerline"])
    err = capsys.readouterr().err
    assert code == 2
    assert "bad.csv" in err and "Traceback" not in err


def test_plan_json_has_the_documented_fields(capsys, tmp_path):
    # A small oval written as a racetrack-database CSV: the command works on any track file.
    t = np.linspace(0.0, 2.0 * np.pi, 120, endpoint=False)
    rows = "\n".join(f"{220 * np.cos(a):.4f},{90 * np.sin(a):.4f},6.0,6.0" for a in t)
    csv = tmp_path / "oval.csv"
    csv.write_text("# x_m,y_m,w_tr_right_m,w_tr_left_m\n" + rows + "\n")
    out = tmp_path / "plan.csv"
    code = main(["plan", "--track", str(csv), "--method", "curvature", "--json", "--out", str(out)])
    report = json.loads(capsys.readouterr().out)
    assert code == 0
    fields = {"track", "method", "length_m", "nodes", "lap_time_s", "solve_time_s", "iterations",
              "status"}  # fmt: skip
    assert set(report) == fields
    assert report["method"] == "curvature" and report["nodes"] > 100
    assert out.exists()
    # The plan file drives a lap of the same track, and is refused on another one.
    assert main(["lap", "--track", str(csv), "--plan", str(out), "--controller", "nominal",
                 "--json"]) == 0  # fmt: skip
    capsys.readouterr()
    assert main(["lap", "--plan", str(out), "--controller", "nominal", "--json"]) == 2
    assert "oval" in capsys.readouterr().err


def test_planner_flags_with_a_plan_file_are_refused_in_one_line(capsys, tmp_path):
    out = tmp_path / "centerline.csv"
    assert main(["plan", "--method", "centerline", "--out", str(out), "--json"]) == 0
    capsys.readouterr()
    for flag in (["--start", "warm"], ["--spacing", "4"], ["--max-iter", "50"]):
        assert main(["lap", "--plan", str(out), *flag, "--json"]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error:") and len(err.splitlines()) == 1, err
        assert "--start" in err and "racing-lib plan" in err


def test_plan_spacing_flag_sets_the_node_spacing(capsys):
    assert main(["plan", "--method", "centerline", "--spacing", "5", "--json"]) == 0
    fields = json.loads(capsys.readouterr().out)
    assert fields["nodes"] == pytest.approx(fields["length_m"] / 5.0, abs=2)


@pytest.mark.slow
def test_a_failed_nlp_names_ipopt_its_status_and_only_knobs_that_exist(capsys):
    code = main(["plan", "--track", "shortcut", "--max-iter", "3", "--json"])
    captured = capsys.readouterr()
    assert code == 2 and captured.out == ""
    line = captured.err.strip().splitlines()[-1]
    assert line.startswith("error: time-optimal NLP") and "IPOPT returned" in line
    assert "--max-iter 6" in line and "--spacing" in line
    # The default start is cold, so the other start is suggested, with its flag.
    assert "start='warm'" in line and "--start warm" in line and "--start cold" not in line


def test_the_parsers_controller_names_are_the_librarys():
    """The parser lists the controllers without importing them; the two lists must agree."""
    from racing_lib.control import CONTROLLER_NAMES
    from racing_lib.face import cli

    assert cli.CONTROLLERS == CONTROLLER_NAMES


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["lap", "--car", "bmw"], "commonroad:vehicle2"),  # the known names, before any work
        (["lap", "--car", "sim", "--no-drag"], "--no-drag"),  # its own model, not the flags
        (["lap", "--reidentify"], "--car"),  # a flag of --car, without it
        (["lap", "--car", "sim", "--speed-scale", "0"], "(0, 1]"),
        (["lap", "--car", "sim", "--track", "nurburgring"], "expressway"),  # before identifying
    ],
)
def test_a_car_the_lap_cannot_drive_is_one_clear_error(capsys, argv, says):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error:") and says in err
    assert "Traceback" not in err and "identifying" not in err
