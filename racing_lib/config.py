"""Settings read from the environment, in one place.

``RACING_LIB_FAST=1`` turns on the fast mode used by tests and CI: it shrinks workloads (number of
trials, CMA-ES generations, demo lengths) but never changes an algorithm or its settings.
"""

from __future__ import annotations

import os


def fast_mode() -> bool:
    """Return True when ``RACING_LIB_FAST`` is set to a true value (1, true, yes)."""
    return os.environ.get("RACING_LIB_FAST", "").strip().lower() in {"1", "true", "yes", "on"}
