"""Execute notebooks and keep only the outputs nbval must compare.

Usage: ``python tools/refresh_notebooks.py [notebooks/01_frenet_kinematics.ipynb ...]``
(no argument: every notebook in notebooks/ and exercises/).

Each notebook runs top to bottom in fast mode (as in the tests); then every output is stripped
except those of cells containing ``# NBVAL_CHECK_OUTPUT``, whose rounded numbers nbval compares.
Outputs stay out of git otherwise: they are large, unreadable in diffs, and the book re-executes the
notebooks anyway. The run time of each notebook is printed (the course's limit is 3 minutes).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

REPO = Path(__file__).resolve().parents[1]
CHECK_MARK = "# NBVAL_CHECK_OUTPUT"


def strip(nb: nbformat.NotebookNode) -> None:
    """Remove outputs and counters except on checked cells.

    nbval treats a cell with outputs but no execution count as "unrun", so checked cells keep a
    count (renumbered 1, 2, ... so that re-running does not change the file needlessly).
    """
    count = 0
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        cell.metadata.pop("execution", None)
        if CHECK_MARK in cell.source:
            count += 1
            cell.execution_count = count
            for out in cell.outputs:
                if "execution_count" in out:
                    out["execution_count"] = count
        else:
            cell.execution_count = None
            cell.outputs = []
    nb.metadata.pop("widgets", None)


def refresh(path: Path, execute: bool = True) -> float:
    """Execute (optionally) and strip one notebook in place; return the run time in s."""
    nb = nbformat.read(path, as_version=4)
    elapsed = 0.0
    if execute:
        os.environ.setdefault("RACING_LIB_FAST", "1")
        tic = time.perf_counter()
        NotebookClient(
            nb,
            timeout=600,
            kernel_name="python3",
            resources={"metadata": {"path": str(path.parent)}},
        ).execute()
        elapsed = time.perf_counter() - tic
    strip(nb)
    nbformat.write(nb, path)
    return elapsed


def main(argv: list[str]) -> int:
    execute = "--no-execute" not in argv
    paths = [Path(a) for a in argv if not a.startswith("--")]
    if not paths:
        paths = sorted((REPO / "notebooks").glob("*.ipynb")) + sorted(
            (REPO / "exercises").rglob("*.ipynb")
        )
    for p in paths:
        seconds = refresh(p, execute=execute)
        print(f"{p}: {seconds:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
