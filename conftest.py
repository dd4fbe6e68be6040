"""Shared test set-up: fast mode for everything the tests start, and paths to shared data."""

from __future__ import annotations

import functools
import importlib.util
import os
from pathlib import Path

import matplotlib
import pytest

# Fast mode shrinks workloads (trials, generations, demo lengths), never algorithms. Set before any
# notebook kernel starts, so nbval's kernels inherit it too.
os.environ.setdefault("RACING_LIB_FAST", "1")
matplotlib.use("Agg")

# Under pytest-xdist every core already runs a worker: a BLAS that also starts a thread per core
# oversubscribes them, and its threads' busy waiting made dense solves several times slower (an
# exercise's reference solve went from 4 s to over 12 s beside one busy process). One BLAS thread
# per worker, and per notebook kernel the worker starts (they inherit the environment).
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")
    from threadpoolctl import threadpool_limits

    # Also for a BLAS this process loaded before the variables were set (kept: it stays applied).
    _ONE_BLAS_THREAD = threadpool_limits(1)

REPO = Path(__file__).resolve().parent

# racing_lib.plants.commonroad needs the optional [commonroad] extra (the test extra installs it);
# without it the module refuses to import, so its docstrings are not collected either.
collect_ignore = (
    [] if importlib.util.find_spec("vehiclemodels") else ["racing_lib/plants/commonroad.py"]
)
SHARED_TRACKS = REPO.parent / "shared" / "tracks"


@pytest.fixture(scope="session")
def real_track_files() -> list[Path]:
    """The real circuits of ../shared/tracks (skipped when that folder is not beside the repo)."""
    files = sorted(SHARED_TRACKS.glob("*.csv"))
    if not files:
        pytest.skip("../shared/tracks is not beside the repository")
    return files


# --------------------------------------------------------------------------------------------------
# The notebooks' runs, kept for the book (book/kept_runs.py): a notebook whose every code cell ran
# without error here is written with its outputs to build/notebook-runs/, and book/execute.py takes
# it instead of running the notebook again while nothing it depends on has changed.
@functools.cache
def _kept_runs():
    spec = importlib.util.spec_from_file_location("kept_runs", REPO / "book" / "kept_runs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_CELL_OUTPUTS: dict[str, dict[int, list]] = {}


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    if call.when == "call" and type(item).__name__ == "IPyNbCell":
        cells = _CELL_OUTPUTS.setdefault(str(item.fspath), {})
        if outcome.get_result().passed and item.test_outputs is not None:
            cells[item.cell_num] = item.test_outputs


def pytest_runtest_teardown(item, nextitem):
    # The last cell of a notebook: write its run now, so an interrupted session keeps it.
    last = nextitem is None or nextitem.parent is not item.parent
    if type(item).__name__ == "IPyNbCell" and last:
        cells = _CELL_OUTPUTS.pop(str(item.fspath), {})
        try:
            _kept_runs().keep(Path(str(item.fspath)), cells)
        except Exception as exc:  # the book then runs the notebook itself; the test is unaffected
            print(f"note: the run of {item.fspath} was not kept for the book ({exc})")
