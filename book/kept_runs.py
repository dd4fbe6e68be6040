"""Notebook runs kept from the test suite, so the book need not execute a notebook a second time.

The test command runs every chapter and exercise notebook through nbval, in fast mode, as the book
does; the book's build then ran each of them again (five minutes of a CI run on two cores). The
test session now keeps what each notebook printed and drew: when every code cell of a notebook
ran without error, ``conftest.py`` calls :func:`keep`, which writes the notebook with those
outputs to ``build/notebook-runs/`` beside a stamp of what produced them. ``book/execute.py``
takes a kept run (:func:`fresh_run`) only when its stamp equals the stamp of the book's own
environment now:

* the notebook's code cells, byte for byte;
* every file of the ``racing_lib`` package (code and shipped data);
* the versions of the packages whose results the pages show (:data:`PACKAGES`);
* fast mode (``RACING_LIB_FAST``).

Anything else (a notebook or the library edited since the tests ran, another version of a solver,
a failed or interrupted test run) executes the notebook afresh, as before. Delete the folder to
force that for every notebook.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from racing_lib.provenance import KEY_PACKAGES, package_versions

REPO = Path(__file__).resolve().parent.parent
#: Where the test session writes the runs it keeps (``build/`` is ignored by git).
KEPT = REPO / "build" / "notebook-runs"
#: Packages that change what a page shows; the book's extras may install others freely.
PACKAGES = (
    *KEY_PACKAGES,  # the solvers and numerics racing_lib's own provenance records
    "matplotlib",
    "scikit-learn",
    "ipykernel",
    "commonroad-vehicle-models",
    "gymnasium",
)
_STAMP_FORMAT = 1


def _library_digest(root: Path = REPO / "racing_lib") -> str:
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*")):
        if path.is_file() and "__pycache__" not in path.parts:
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _code_digest(notebook: Any) -> str:
    digest = hashlib.sha256()
    for cell in notebook.cells:
        if cell.cell_type == "code":
            digest.update(cell.source.encode())
            digest.update(b"\0")
    return digest.hexdigest()[:16]


def stamp(notebook: Any) -> dict[str, Any]:
    """What a run of ``notebook`` (an nbformat node) depends on, as a JSON-able dict."""
    return {
        "format": _STAMP_FORMAT,
        "code": _code_digest(notebook),
        "racing_lib": _library_digest(),
        "packages": package_versions(PACKAGES),
        "fast_mode": os.environ.get("RACING_LIB_FAST", ""),
    }


def _quiet(source: str) -> bool:
    """IPython's own rule: a cell whose last token is ``;`` shows no result."""
    from IPython.core.displayhook import DisplayHook

    try:
        return bool(DisplayHook.semicolon_at_end_of_expression(source))
    except (SyntaxError, ValueError):  # tokenize errors: the cell's own run reported them
        return False


def _kept_path(path: Path, kept: Path) -> Path:
    resolved = path.resolve()
    if resolved.is_relative_to(REPO):
        return kept / resolved.relative_to(REPO)
    # A notebook outside the repository (a test's): named by its folder, so two do not collide.
    folder = hashlib.sha256(str(resolved.parent).encode()).hexdigest()[:12]
    return kept / "_elsewhere" / folder / resolved.name


def keep(path: Path, outputs: dict[int, list[Any]], kept: Path = KEPT) -> Path | None:
    """Write the run of the notebook at ``path`` whose code cells printed ``outputs``.

    Parameters
    ----------
    path : Path
        The notebook, inside the repository.
    outputs : dict
        For every code cell, numbered from 0 among the code cells, its outputs (nbformat nodes).
    kept : Path
        The folder of kept runs.

    Returns
    -------
    Path or None
        The notebook written, or None when some code cell has no outputs recorded (it did not
        run, or failed): such a run is not kept, and an older one of the notebook is removed.
    """
    import nbformat

    notebook = nbformat.read(path, as_version=4)
    target = _kept_path(path, kept)
    code_cells = [cell for cell in notebook.cells if cell.cell_type == "code"]
    if set(outputs) != set(range(len(code_cells))):
        target.unlink(missing_ok=True)
        return None
    for number, cell in enumerate(code_cells):
        cell.outputs = list(outputs[number])
        if _quiet(cell.source):
            # nbval runs cells outside IPython's history, where a trailing ';' does not silence
            # the cell's result (a "<matplotlib.legend.Legend at 0x...>" line); a notebook run does.
            cell.outputs = [o for o in cell.outputs if o.get("output_type") != "execute_result"]
        cell.execution_count = number + 1
        for output in cell.outputs:
            if output.get("output_type") == "execute_result":
                output["execution_count"] = number + 1
    notebook.metadata["racing_lib_run"] = stamp(notebook)
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_name(target.name + ".partial")
    nbformat.write(notebook, partial)
    partial.replace(target)  # a reader never sees half a file
    return target


def fresh_run(path: Path, kept: Path = KEPT) -> Path | None:
    """The kept run of the notebook at ``path`` if it is still what running it would give.

    Returns
    -------
    Path or None
        The kept notebook, or None when there is none, it cannot be read, or its stamp differs
        from the stamp of ``path`` in this environment (see the module's docstring).
    """
    import nbformat

    target = _kept_path(path, kept)
    if not target.is_file():
        return None
    try:
        run = nbformat.read(target, as_version=4)
    except (OSError, ValueError):
        return None
    recorded = run.metadata.get("racing_lib_run")
    current = stamp(nbformat.read(path, as_version=4))
    if json.loads(json.dumps(recorded)) != current:
        return None
    return target
