"""The package's shape: one-way layers, no import circle, modules and functions a reader can hold.

The layer contract lives in ``pyproject.toml`` (``[tool.importlinter]``) and is checked with
import-linter; CONTRIBUTING.md ("Where things go") explains it. A test breaks the contract on a
copy of the package, to show that the check can fail.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "racing_lib"
MAX_MODULE_LINES = 700
MAX_FUNCTION_LINES = 100


def _lint_imports(cwd: Path, package_parent: Path) -> subprocess.CompletedProcess:
    # import-linter's command through this interpreter: no reliance on a script on PATH.
    command = (
        "import sys; from importlinter.cli import lint_imports_command; lint_imports_command()"
    )
    env = {**os.environ, "PYTHONPATH": str(package_parent)}
    return subprocess.run(
        [sys.executable, "-c", command, "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_every_layer_imports_only_from_the_layers_below_it():
    run = _lint_imports(ROOT, ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "0 broken" in run.stdout


@pytest.mark.parametrize(
    ("module", "line", "contract"),
    [
        # the geometry layer reaching up into the experiments
        ("geometry/path.py", "from racing_lib.experiments import lap", "one-way layers"),
        # a controller importing the simulator it is meant not to know
        ("control/nominal.py", "from racing_lib.sim import SimulatedCar", "never the simulator"),
    ],
)
def test_the_contract_catches_an_import_that_breaks_it(tmp_path, module, line, contract):
    copy = tmp_path / "racing_lib"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__", "data"))
    target = copy / module
    # Inside a function, as the lazy imports the contract must see too.
    target.write_text(target.read_text() + f"\n\ndef _sneak():\n    {line}\n")
    run = _lint_imports(tmp_path, tmp_path)
    assert run.returncode != 0
    broken = [ln for ln in run.stdout.splitlines() if ln.rstrip().endswith("BROKEN")]
    assert any(contract in ln for ln in broken), run.stdout


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_no_module_is_longer_than_a_reader_can_hold():
    long = {
        str(p.relative_to(ROOT)): n
        for p in _modules()
        if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
    }
    assert not long, f"split these modules (over {MAX_MODULE_LINES} lines): {long}"


def _function_lengths(path: Path):
    """(name, first line, body lines without the docstring) of every function in ``path``."""
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                body = body[1:]  # the docstring is documentation, not code to hold in mind
            start = body[0].lineno if body else node.end_lineno
            first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            yield node.name, first, node.end_lineno - start + 1


def test_no_function_is_longer_than_a_page():
    long = [
        f"{path.relative_to(ROOT)}:{first} {name} ({length} lines)"
        for path in _modules()
        for name, first, length in _function_lengths(path)
        if length > MAX_FUNCTION_LINES
    ]
    assert not long, (
        f"cut these functions into named steps (no body over {MAX_FUNCTION_LINES} lines, "
        f"docstring not counted; there are no exemptions): {long}"
    )
