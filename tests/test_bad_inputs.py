"""Every bad command line of tools/bad_inputs.py is refused before any work: one line, exit 2.

The expensive steps (planning, driving a lap, tuning, computing an ablation row) are replaced by
functions that fail the test when reached, so a refusal that comes only after the work fails here.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import pytest

from racing_lib.face.cli import main

_spec = importlib.util.spec_from_file_location(
    "bad_inputs", Path(__file__).resolve().parents[1] / "tools" / "bad_inputs.py"
)
bad_inputs = importlib.util.module_from_spec(_spec)
sys.modules["bad_inputs"] = bad_inputs  # dataclasses look their module up there
_spec.loader.exec_module(bad_inputs)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return bad_inputs.make_files(tmp_path_factory.mktemp("inputs"))


def _never(name):
    def reached(*args, **kwargs):
        raise AssertionError(f"{name} was reached: the input was not refused before the work")

    return reached


CASES = [c.what for c in bad_inputs.cases({})]


def test_there_are_at_least_thirty_cases():
    assert len(CASES) >= 30


@pytest.mark.parametrize("what", CASES)
def test_a_bad_input_is_refused_at_once_in_one_line(what, files, tmp_path, monkeypatch, capsys):
    case = next(c for c in bad_inputs.cases(files) if c.what == what)
    import racing_lib.experiments.ablation.runner as ablation
    import racing_lib.experiments.configs as configs
    import racing_lib.experiments.pipeline as pipeline
    import racing_lib.experiments.tuning as tuning
    import racing_lib.planning as planning

    monkeypatch.setattr(planning, "plan", _never("planning"))
    monkeypatch.setattr(pipeline, "plan", _never("planning"))
    monkeypatch.setattr(pipeline, "drive_lap", _never("driving a lap"))
    monkeypatch.setattr(tuning, "tune_weights", _never("tuning"))
    monkeypatch.setattr(configs, "config_spec", _never("planning for tuning"))
    monkeypatch.setattr(ablation, "run_trials", _never("an ablation row's laps"))
    monkeypatch.setattr(ablation, "_get_plan", _never("an ablation row's plan"))
    monkeypatch.chdir(tmp_path)
    code = main(case.argv)
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert code == 2, (case.what, captured.err)
    assert captured.out == ""
    assert lines and lines[-1].startswith("error: ") and case.says in lines[-1], lines
    assert not [ln for ln in lines if "Traceback" in ln]
    assert not os.listdir(tmp_path), f"{case.what}: wrote {os.listdir(tmp_path)}"
