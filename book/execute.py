"""Run the book's notebooks in parallel, one per core, before the book is built.

Jupyter Book 1 executes the notebooks one after another while Sphinx reads them, so a build on two
cores used one of them for most of its time. This script executes every notebook of the table of
contents in a pool of worker processes (jupyter-cache's ``local-parallel`` executor: one kernel per
worker, each notebook run in its own folder, as the book runs it) and stores the executed notebooks
in the book's jupyter-cache. The build (``execute_notebooks: cache`` in ``_config.yml``) then
takes each notebook's outputs from that cache, matched by the notebook's code, and executes itself
any notebook whose run failed here, so that a failing cell is still reported by the build (and
fails it).

The cache is emptied first, on every run: a notebook's outputs depend on ``racing_lib`` as well as
on its own code, and the cache only sees the code, so outputs kept from an earlier build could be
stale.

Run by ``book/build.sh``; by hand: ``python book/execute.py`` (from anywhere).
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))  # its sibling script book/kept_runs.py
from kept_runs import KEPT, fresh_run  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
TOC = REPO / "book" / "_toc.yml"
CONFIG = REPO / "book" / "_config.yml"
#: Where myst-nb looks by default with ``--path-output book``: ``<build folder>/.jupyter_cache``.
CACHE = REPO / "book" / "_build" / ".jupyter_cache"


def toc_notebooks(toc: Path = TOC, root: Path = REPO) -> list[Path]:
    """The notebooks that the table of contents puts in the book, in its order.

    Parameters
    ----------
    toc : Path
        The ``_toc.yml`` (paths in it are relative to ``root``, without a suffix).
    root : Path
        The book's source root.

    Returns
    -------
    list of Path
        Every ``.ipynb`` named by a ``file:`` entry or matched by a ``glob:`` entry.
    """
    found: list[Path] = []

    def walk(node: object) -> None:
        if isinstance(node, dict):
            if "file" in node:
                candidate = root / f"{node['file']}.ipynb"
                if candidate.exists():
                    found.append(candidate)
            if "glob" in node:
                found.extend(sorted(root.glob(f"{node['glob']}.ipynb")))
            for value in node.values():
                walk(value)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    walk(yaml.safe_load(toc.read_text(encoding="utf-8")))
    return list(dict.fromkeys(found))


def execute_all(
    notebooks: list[Path], cache_path: Path, timeout: int, kept: Path | None = None
) -> tuple[list[Path], list[Path]]:
    """Execute ``notebooks`` in parallel into a fresh jupyter-cache at ``cache_path``.

    A notebook with a fresh run kept by the test suite (``book/kept_runs.py``) is not executed:
    that run goes into the cache as it is.

    Parameters
    ----------
    notebooks : list of Path
        The notebooks to run.
    cache_path : Path
        The cache folder; removed and created anew.
    timeout : int
        Seconds any one cell may take (the book's ``execute.timeout``).
    kept : Path, optional
        The folder of the test suite's kept runs (default ``build/notebook-runs``; a folder
        without runs executes every notebook).

    Returns
    -------
    failed : list of Path
        The notebooks whose run failed (the build runs them again and reports the error).
    reused : list of Path
        The notebooks taken from the test suite's runs.
    """
    from jupyter_cache import get_cache
    from jupyter_cache.executors import load_executor

    shutil.rmtree(cache_path, ignore_errors=True)
    cache = get_cache(str(cache_path))
    reused = []
    for nb in notebooks:
        cache.add_nb_to_project(str(nb))
        run = fresh_run(nb, KEPT if kept is None else kept)
        if run is not None:
            cache.cache_notebook_file(str(run), uri=str(nb))
            reused.append(nb)
    executor = load_executor("local-parallel", cache=cache)
    result = executor.run_and_cache(timeout=timeout, allow_errors=False)
    return [Path(uri) for uri in (*result.excepted, *result.errored)], reused


def main() -> int:
    """Execute the book's notebooks and print what happened; 0 unless nothing could run."""
    config = yaml.safe_load(CONFIG.read_text(encoding="utf-8"))
    timeout = int(config.get("execute", {}).get("timeout", 300))
    notebooks = toc_notebooks()
    # One kernel per core already: a BLAS thread per core in each kernel would oversubscribe them.
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    start = time.perf_counter()
    failed, reused = execute_all(notebooks, CACHE, timeout)
    elapsed = time.perf_counter() - start
    if reused:
        print(
            f"book: {len(reused)} of {len(notebooks)} notebooks as the test suite ran them "
            "(same code, library, solver versions and mode; book/kept_runs.py)"
        )
    ran = len(notebooks) - len(reused)
    print(
        f"book: executed {ran - len(failed)} of {ran} notebooks in {elapsed:.0f} s "
        f"on {os.cpu_count()} cores"
    )
    for nb in failed:
        # Not fatal here: the build executes this notebook again and fails with its error.
        print(f"book: {nb.relative_to(REPO)} failed; the build runs it again and reports why")
    return 0


if __name__ == "__main__":
    sys.exit(main())
