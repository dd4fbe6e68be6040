"""Settings read from the environment, in one place.

``RACING_LIB_FAST=1`` turns on the fast mode used by tests and CI: it shrinks workloads (number of
trials, CMA-ES generations, demo lengths) but never changes an algorithm or its settings.
"""

from __future__ import annotations

import os


def fast_mode() -> bool:
    """Return True when ``RACING_LIB_FAST`` is set to a true value (1, true, yes)."""
    return os.environ.get("RACING_LIB_FAST", "").strip().lower() in {"1", "true", "yes", "on"}


#: The variables by which OpenBLAS, OpenMP and MKL read their thread count at start-up.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread_for_children() -> None:
    """Make processes started from here on use one BLAS thread, unless the user chose a count.

    For a parent that already runs one worker per core (test workers, notebook kernels): a BLAS
    thread per core in each worker would oversubscribe the cores. Sets the environment only, so
    it acts on child processes and on a BLAS loaded later, not on one already loaded here.
    """
    for var in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(var, "1")
