"""The benchmark scripts as a user runs them: ``--help`` explains them, bad input ends in one line.

Nothing here times anything (timings belong to the scripts' own output); these only check that
each script starts, describes itself and stops cleanly on a track that does not exist.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(p for p in BENCHMARKS.glob("*.py") if not p.name.startswith("_"))


def _run(script: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    return subprocess.run(
        [sys.executable, str(script), *args],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        cwd=BENCHMARKS.parent,
    )


def test_every_script_is_found():
    names = {p.stem for p in SCRIPTS}
    assert {"bench_plan_speed", "bench_closed_loop", "bench_sim", "check_kernels"} <= names


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.stem)
def test_help_prints_the_whole_docstring(script):
    proc = _run(script, "--help")
    assert proc.returncode == 0, proc.stderr
    doc = ast.get_docstring(ast.parse(script.read_text()))
    assert doc, f"{script.name} has no module docstring to show under --help"
    # The last line of the docstring too, not only its first (which argparse alone would keep).
    first, last = doc.splitlines()[0], doc.strip().splitlines()[-1]
    assert first.strip() in proc.stdout
    assert last.strip() in proc.stdout
    assert proc.stdout.startswith("usage:")


@pytest.mark.parametrize(
    ("script", "args"),
    [
        ("bench_closed_loop.py", ("--tracks", "expressway", "no_such_circuit.csv")),
        ("bench_sim.py", ("no_such_circuit.csv",)),
        ("bench_mpc.py", ("--track", "no_such_circuit.csv")),
    ],
)
def test_a_missing_track_is_one_line_and_status_2(script, args):
    proc = _run(BENCHMARKS / script, *args)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: ") and "no_such_circuit.csv" in lines[0]
    # The track is checked before any work starts, so nothing was printed as if it would run.
    assert "track" not in proc.stdout.lower()


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (("no_such_folder",), "no_such_folder"),  # a mistyped folder measured nothing before
        (("--only", "Nowhere"), "Nowhere"),  # and a name that matches no track, silently
    ],
)
def test_a_folder_or_name_that_gives_no_track_is_one_line_and_status_2(args, named):
    for script in ("bench_plan_speed.py", "bench_nlp_iteration.py", "bench_warm_restart.py"):
        proc = _run(BENCHMARKS / script, *args)
        assert proc.returncode == 2, (script, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and named in lines[0], script
        assert proc.stdout == "", script  # refused before the table's header
