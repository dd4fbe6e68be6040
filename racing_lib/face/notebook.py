"""The one set-up call at the top of every notebook of the course.

``setup()`` fixes the plot style, NumPy's print options (so printed numbers are short and stable
under nbval), and the random seed, and reports the versions of the solvers the chapter relies on.
"""

from __future__ import annotations

import importlib.metadata

import numpy as np

from racing_lib.config import fast_mode
from racing_lib.face.plotting import set_style

_SOLVERS = ("numpy", "scipy", "casadi", "cvxpy", "osqp", "control", "cma")


def versions() -> dict[str, str]:
    """Installed versions of racing_lib and the packages it solves with."""
    out = {"racing-lib": importlib.metadata.version("racing-lib")}
    for name in _SOLVERS:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "missing"
    return out


def setup(seed: int = 0, quiet: bool = False) -> np.random.Generator:
    """Prepare a notebook: style, print options, seed; return the chapter's random generator.

    Parameters
    ----------
    seed : int
        Seed of the returned generator (every random draw of a chapter should come from it).
    quiet : bool
        Do not print the version line.

    Returns
    -------
    numpy.random.Generator
    """
    set_style()
    np.set_printoptions(precision=4, suppress=True, linewidth=100)
    if not quiet:
        line = ", ".join(f"{k} {v}" for k, v in versions().items())
        mode = " (fast mode: shortened demos)" if fast_mode() else ""
        print(f"{line}{mode}")
    return np.random.default_rng(seed)
