"""Checks on the repository itself: style, README and CI agreement, clean notebooks."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CHECK_MARK = "# NBVAL_CHECK_OUTPUT"


def _ruff() -> list[str]:
    exe = shutil.which("ruff")
    return [exe] if exe else [sys.executable, "-m", "ruff"]


def test_ruff_check_is_clean():
    proc = subprocess.run(
        [
            *_ruff(),
            "check",
            "racing_lib",
            "tests",
            "benchmarks",
            "tools",
            "book",
            "exercises",
            "conftest.py",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_ruff_format_is_clean():
    proc = subprocess.run(
        [
            *_ruff(),
            "format",
            "--check",
            "racing_lib",
            "tests",
            "benchmarks",
            "tools",
            "conftest.py",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def _readme_test_command() -> str:
    text = (REPO / "README.md").read_text()
    match = re.search(r"<!-- test-command -->\s*```bash\n(.+?)\n```", text, re.S)
    assert match, "README.md must mark its test command with <!-- test-command -->"
    return match.group(1).strip()


def test_readme_test_command_runs_pytest_on_a_fresh_install():
    cmd = _readme_test_command()
    assert "pip install" in cmd and ".[test]" in cmd and "pytest" in cmd


def test_ci_reads_the_readme_command():
    ci = (REPO / ".ci" / "run").read_text()
    assert "test-command" in ci, ".ci/run must take its command from the README"


def test_every_import_is_a_declared_dependency():
    """A package imported by racing_lib must be in pyproject's dependencies (fresh installs)."""
    import ast
    import tomllib

    deps = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    declared = {re.split(r"[<>=\[ ]", d)[0].lower().replace("-", "_") for d in deps}
    used = set()
    for py in (REPO / "racing_lib").rglob("*.py"):
        for node in ast.walk(ast.parse(py.read_text())):
            if isinstance(node, ast.Import):
                used.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                used.add(node.module.split(".")[0])
    third_party = used - set(sys.stdlib_module_names) - {"racing_lib"}
    # the [distributed] extra, imported lazily; the [commonroad] extra (racing_lib.plants); the
    # [gym] extra (racing_lib.envs)
    optional = {"dask", "distributed", "vehiclemodels", "gymnasium"}
    missing = {u for u in third_party - optional if u.lower() not in declared}
    assert not missing, f"imported but not declared in pyproject.toml: {sorted(missing)}"


def _notebooks() -> list[Path]:
    return sorted((REPO / "notebooks").glob("*.ipynb")) + sorted(
        (REPO / "exercises").rglob("*.ipynb")
    )


@pytest.mark.parametrize("nb_path", _notebooks(), ids=lambda p: str(p.relative_to(REPO)))
def test_notebook_outputs_are_stripped_except_checked_cells(nb_path: Path):
    nb = json.loads(nb_path.read_text())
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        source = "".join(cell["source"])
        if CHECK_MARK in source:
            assert cell.get("outputs"), f"{nb_path.name} cell {i} is checked but has no output"
        else:
            assert not cell.get("outputs"), (
                f"{nb_path.name} cell {i} has committed outputs; run tools/refresh_notebooks.py"
            )
            assert cell.get("execution_count") is None
