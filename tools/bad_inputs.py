"""Bad input to ``racing-lib``: every case refused at once, in one line, writing nothing.

Each case is a command line a user could type (with the damaged files it needs, made in a scratch
folder). Run as a script, every case runs as its own process, and a table is printed: the input,
the exit code, the message and the seconds until the refusal::

    python tools/bad_inputs.py            # Markdown table on stdout

``tests/test_bad_inputs.py`` runs the same cases in-process, with the expensive steps (planning,
driving, tuning) replaced by functions that fail the test if they are ever reached.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Case:
    """One bad command line.

    Attributes
    ----------
    what : str
        What is wrong, for the table.
    argv : list of str
        The arguments after ``racing-lib``.
    says : str
        A piece of the one-line message that names the problem.
    """

    what: str
    argv: list[str]
    says: str


def _write_track(path: Path, x: np.ndarray, y: np.ndarray, wl: float, wr: float) -> None:
    rows = "\n".join(f"{a:.6f},{b:.6f},{wr:.3f},{wl:.3f}" for a, b in zip(x, y, strict=True))
    path.write_text("# x_m,y_m,w_tr_right_m,w_tr_left_m\n" + rows + "\n", encoding="utf-8")


def _circle(n: int = 120, radius: float = 80.0) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return radius * np.cos(t), radius * np.sin(t)


def make_files(folder: Path) -> dict[str, Path]:
    """The files the cases refer to: good and damaged plans, bad tracks, a plain file."""
    from racing_lib.model.identified import identified_params
    from racing_lib.planning.trajectory import Trajectory
    from racing_lib.tracks import load_track

    folder.mkdir(parents=True, exist_ok=True)
    files = {"file": folder / "a_file.txt"}
    files["file"].write_text("not a folder\n")

    plan = folder / "plan.csv"
    Trajectory.from_centerline(load_track("expressway"), identified_params()).save_csv(plan)
    lines = plan.read_text().splitlines(keepends=True)
    head = next(i for i, line in enumerate(lines) if line.startswith("s_m"))
    rows = lines[head + 1 : -1]

    def damaged(name: str, text: str) -> None:
        files[name] = folder / f"{name}.csv"
        files[name].write_text(text)

    damaged("plan_cut_at_row", "".join(lines[: head + 1] + rows[:700]))
    damaged("plan_cut_mid_row", "".join(lines[: head + 1] + rows[:700]) + rows[700][:20])
    damaged("plan_header_only", "".join(lines[: head + 1]))
    damaged(
        "plan_lap_time_edited",
        "".join(line.replace("planned_lap_time_s: ", "planned_lap_time_s: 9") for line in lines),
    )

    def faster(line: str) -> str:
        f = line.rstrip("\n").split(",")
        f[5] = f"{float(f[5]) * 1.5:.9g}"
        return ",".join(f) + "\n"

    damaged(
        "plan_vx_times_1.5", "".join(lines[: head + 1] + [faster(r) for r in rows] + lines[-1:])
    )
    damaged("plan_spliced", "".join(lines + rows[:50]))
    damaged("plan_not_a_plan", "# x_m,y_m\n1,2\n")
    files["plan_other_track"] = folder / "plan_other_track.csv"
    Trajectory.from_centerline(load_track("shortcut"), identified_params()).save_csv(
        files["plan_other_track"]
    )

    x, y = _circle()
    files["track_ok"] = folder / "circle.csv"
    _write_track(files["track_ok"], x, y, 6.0, 6.0)
    files["track_nan"] = folder / "track_nan.csv"
    _write_track(files["track_nan"], x, y, 6.0, 6.0)
    text = files["track_nan"].read_text().splitlines()
    text[5] = "nan,1.0,6.0,6.0"
    files["track_nan"].write_text("\n".join(text) + "\n")
    files["track_columns"] = folder / "track_columns.csv"
    files["track_columns"].write_text("x,y\n1,2\n3,4\n")
    files["track_negative_width"] = folder / "track_negative_width.csv"
    _write_track(files["track_negative_width"], x, y, 6.0, -1.0)
    files["track_open"] = folder / "track_open.csv"
    _write_track(files["track_open"], x[:60], y[:60], 6.0, 6.0)
    files["track_three_points"] = folder / "track_three_points.csv"
    _write_track(files["track_three_points"], x[:3], y[:3], 6.0, 6.0)
    # A figure-of-eight crossing at a shallow angle (no bridge) and a pinched oval whose two long
    # sides run 7 m apart with 4 m of road each side (the roads overlap by 1 m).
    t = np.linspace(0.0, 2.0 * math.pi, 400, endpoint=False)
    tc = t + 0.004  # no sample at the crossing itself
    files["track_crossing"] = folder / "track_crossing.csv"
    _write_track(files["track_crossing"], 300 * np.sin(tc), 10 * np.sin(2 * tc), 4.0, 4.0)
    xo = 200.0 * np.cos(t)
    yo = np.sin(t) * (40.0 - 36.5 * np.exp(-((xo / 50.0) ** 2)))
    files["track_overlap"] = folder / "track_overlap.csv"
    _write_track(files["track_overlap"], xo, yo, 4.0, 4.0)
    files["track_binary"] = folder / "track_binary.csv"
    files["track_binary"].write_bytes(b"\xff\xfe\x00\x01garbage")
    files["tuned_out_parent_file"] = files["file"] / "weights.json"
    return files


class _Paths:
    """``f[name]``: the path of a made file as text (a placeholder for a name not made)."""

    def __init__(self, files: dict[str, Path]) -> None:
        self.files = files

    def __getitem__(self, name: str) -> str:
        return str(self.files.get(name, Path("/placeholder") / name))


def cases(files: dict[str, Path]) -> list[Case]:
    """The bad command lines (at least 30), each with a piece of its expected message.

    ``files`` comes from :func:`make_files`; with an empty dict the cases still list (their file
    arguments are placeholders), which is how the tests name them.
    """
    f = _Paths(files)
    unwritable = "/proc/racing_lib_out"  # the kernel refuses files there, even to root
    lap = ["lap", "--controller", "nominal", "--method", "centerline"]
    return [
        Case("negative seed", ["lap", "--seed", "-5"], "--seed must be at least 0"),
        Case("zero trials", ["lap", "--trials", "0"], "--trials must be at least 1"),
        Case("negative trials", ["lap", "--trials", "-2"], "--trials must be at least 1"),
        Case("zero node spacing", ["plan", "--spacing", "0"], "--spacing must be"),
        Case("NaN node spacing", ["plan", "--spacing", "nan"], "--spacing must be"),
        Case("huge node spacing", ["lap", "--spacing", "500"], "--spacing must be"),
        Case("zero IPOPT iterations", ["plan", "--max-iter", "0"], "--max-iter must be"),
        Case("plan --out is a folder", ["plan", "--out", str(Path(f["file"]).parent)], "a folder"),
        Case("plan --out below a file", ["plan", "--out", f["file"] + "/p.csv"], "is a file"),
        Case("plan --out unwritable", ["plan", "--out", unwritable + "/p.csv"], "cannot write"),
        Case("lap --out is a file", ["lap", "--out", f["file"]], "is a file, not a folder"),
        Case("lap --out below a file", ["lap", "--out", f["file"] + "/run"], "is a file"),
        Case("lap --out unwritable", ["lap", "--out", unwritable], "cannot write"),
        Case("tune --budget 0", ["tune", "--budget", "0"], "--budget must be at least 1"),
        Case("tune --budget -1", ["tune", "--budget", "-1"], "--budget must be at least 1"),
        Case("tune --workers 0", ["tune", "--workers", "0"], "--workers must be at least 1"),
        Case("tune --out below a file", ["tune", "--out", f["tuned_out_parent_file"]], "is a file"),
        Case("tune --out unwritable", ["tune", "--out", unwritable + "/w.json"], "cannot write"),
        Case("ablation --workers 0", ["ablation", "--workers", "0"], "--workers must be"),
        Case("ablation --workers -3", ["ablation", "--workers", "-3"], "--workers must be"),
        Case("ablation --out is a file", ["ablation", "--out", f["file"]], "is a file"),
        Case("ablation unknown row", ["ablation", "--rows", "main,bogus"], "'bogus'"),
        Case("ablation --recompute unknown", ["ablation", "--recompute", "nope"], "'nope'"),
        Case("ablation unknown track", ["ablation", "--track", "monza"], "'monza'"),
        Case("unknown track name", [*lap, "--track", "nurburgring"], "Unknown track"),
        Case("missing track file", [*lap, "--track", "missing.csv"], "does not exist"),
        Case("track with NaN", [*lap, "--track", f["track_nan"]], "NaN"),
        Case("track with wrong columns", [*lap, "--track", f["track_columns"]], "wrong columns"),
        Case("negative width", [*lap, "--track", f["track_negative_width"]], "not positive"),
        Case("open centerline", [*lap, "--track", f["track_open"]], "open"),
        Case("three points", [*lap, "--track", f["track_three_points"]], "at least 4"),
        Case("crossing, not a bridge", [*lap, "--track", f["track_crossing"]], "crosses itself"),
        Case("overlapping road", [*lap, "--track", f["track_overlap"]], "overlaps the road"),
        Case("binary track file", [*lap, "--track", f["track_binary"]], "cannot be read"),
        Case("missing plan file", ["lap", "--plan", "nope.csv"], "no such file"),
        Case(
            "planner knobs with a saved plan",
            ["lap", "--plan", f["plan_lap_time_edited"], "--spacing", "4"],
            "--plan drives a plan made before",
        ),
        Case("plan cut at a row", ["lap", "--plan", f["plan_cut_at_row"]], "cut short"),
        Case("plan cut inside a row", ["lap", "--plan", f["plan_cut_mid_row"]], "data row 701"),
        Case("plan header only", ["lap", "--plan", f["plan_header_only"]], "no rows"),
        Case("plan lap time edited", ["lap", "--plan", f["plan_lap_time_edited"]], "checksum"),
        Case("plan v_x times 1.5", ["lap", "--plan", f["plan_vx_times_1.5"]], "checksum"),
        Case("plan rows spliced on", ["lap", "--plan", f["plan_spliced"]], "spliced"),
        Case("not a plan file", ["lap", "--plan", f["plan_not_a_plan"]], "not a racing_lib plan"),
        Case(
            "plan of another track",
            ["lap", "--plan", f["plan_other_track"]],
            "was made for track 'shortcut'",
        ),
    ]


def _run(case: Case, cwd: Path) -> tuple[int, str, float, bool]:
    """Run one case as a process: exit code, last stderr line, seconds, whether stdout is empty."""
    tic = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "racing_lib.face.cli", *case.argv],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    seconds = time.perf_counter() - tic
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    return proc.returncode, lines[-1] if lines else "", seconds, proc.stdout == ""


def main(run: Callable[[Case, Path], tuple[int, str, float, bool]] = _run) -> int:
    """Print the Markdown table of every case; exit 1 if one was not refused cleanly."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        files = make_files(root / "inputs")
        work = root / "work"
        work.mkdir()
        bad = 0
        print("| # | input | exit | message | s |")
        print("|---|---|---|---|---|")
        for k, case in enumerate(cases(files), 1):
            code, message, seconds, quiet = run(case, work)
            wrote = sorted(p.name for p in work.rglob("*"))
            clean = (
                code == 2
                and message.startswith("error: ")
                and case.says in message
                and quiet
                and not wrote
            )
            bad += not clean
            shown = message.replace(str(root), "…").replace("|", "\\|")
            flag = "" if clean else " **NOT CLEAN**"
            print(f"| {k} | {case.what} | {code} | {shown}{flag} | {seconds:.2f} |")
        return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
