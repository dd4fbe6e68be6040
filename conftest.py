"""Shared test set-up: fast mode for everything the tests start, and paths to shared data."""

from __future__ import annotations

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
