"""Where a result was made: the machine, the linear-algebra kernel and the package versions.

Shipped results (the ablation table) and benchmark reports record this, so that a reader who gets
other numbers can see at once whether the machine or a version differs. Taught nowhere; used by
:mod:`racing_lib.ablation` and the scripts in ``benchmarks/``.
"""

from __future__ import annotations

import os
import platform
import sys
import time
from importlib import metadata
from typing import Any

#: The distributions whose versions can move a number of this package.
KEY_PACKAGES = (
    "racing-lib",
    "numpy",
    "scipy",
    "casadi",
    "cvxpy",
    "osqp",
    "clarabel",
    "cma",
    "control",
)


def package_versions(names: tuple[str, ...] = KEY_PACKAGES) -> dict[str, str]:
    """Installed versions of ``names`` ("not installed" for a missing one)."""
    out = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def blas_libraries() -> list[dict[str, str]]:
    """Every BLAS library loaded in this process: ``{"library", "kernel", "path"}`` each.

    NumPy, SciPy and CasADi may each bring their own OpenBLAS, and each picks a CPU kernel
    (``OPENBLAS_CORETYPE`` forces one); threadpoolctl reads them from the loaded libraries.
    """
    try:
        import numpy  # noqa: F401  (loads the BLAS library that threadpoolctl inspects)
        from threadpoolctl import threadpool_info

        return [
            {
                "library": f"{lib.get('internal_api', '?')} {lib.get('version') or '?'}",
                "kernel": str(lib.get("architecture") or "?"),
                "path": str(lib.get("filepath", "")),
            }
            for lib in threadpool_info()
            if lib.get("user_api") == "blas"
        ]
    except Exception:  # noqa: BLE001 - a description must never break the run it describes
        return []


def blas_kernel() -> str:
    """NumPy's BLAS library and the CPU kernel it chose, e.g. ``openblas 0.3.31 SkylakeX``.

    The kernel changes the last digits of floating-point sums and so, through chaotic laps,
    closed-loop numbers.
    """
    libs = blas_libraries()
    mine = [lib for lib in libs if "numpy" in lib["path"]] or libs
    return f"{mine[0]['library']} {mine[0]['kernel']}" if mine else "unknown"


def environment() -> dict[str, Any]:
    """A JSON-ready description of this machine and installation, with the time (UTC).

    Keys: ``created_utc``, ``python``, ``platform``, ``cpu``, ``cpu_count``, ``blas`` (NumPy's),
    ``blas_libraries`` (every BLAS loaded), ``openblas_coretype`` (the environment variable, or
    None), ``packages`` (name -> version).
    """
    return {
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "cpu": _cpu_name(),
        "cpu_count": os.cpu_count(),
        "blas": blas_kernel(),
        "blas_libraries": [f"{b['library']} {b['kernel']}" for b in blas_libraries()],
        "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE"),
        "packages": package_versions(),
    }


def describe(env: dict[str, Any]) -> str:
    """One line for a person: date, CPU, BLAS kernel and the solver versions."""
    pk = env.get("packages", {})
    versions = ", ".join(f"{n} {pk[n]}" for n in ("numpy", "casadi", "osqp", "cvxpy") if n in pk)
    return (
        f"made {env.get('created_utc', '?')} on {env.get('cpu_count', '?')} cores of "
        f"{env.get('cpu', '?')}, BLAS {env.get('blas', '?')}, Python {env.get('python', '?')}, "
        f"{versions}"
    )


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"
