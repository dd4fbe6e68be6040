"""Shared test set-up: fast mode for everything the tests start, and paths to shared data."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import pytest

# Fast mode shrinks workloads (trials, generations, demo lengths), never algorithms. Set before any
# notebook kernel starts, so nbval's kernels inherit it too.
os.environ.setdefault("RACING_LIB_FAST", "1")
matplotlib.use("Agg")

REPO = Path(__file__).resolve().parent
SHARED_TRACKS = REPO.parent / "shared" / "tracks"


@pytest.fixture(scope="session")
def real_track_files() -> list[Path]:
    """The real circuits of ../shared/tracks (skipped when that folder is not beside the repo)."""
    files = sorted(SHARED_TRACKS.glob("*.csv"))
    if not files:
        pytest.skip("../shared/tracks is not beside the repository")
    return files
