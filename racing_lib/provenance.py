"""Where a result was made: the machine, the linear-algebra kernel, the versions and the code.

Shipped results (the ablation table) and benchmark reports record this, so that a reader who gets
other numbers can see at once whether the machine or a version differs. :func:`code_digest` hashes
the source a computation runs, found by reading imports rather than from a list of files, so that
a cache keyed by it follows every module moved, added or edited. Taught nowhere; used by
:mod:`racing_lib.experiments.ablation` and the scripts in ``benchmarks/``.
"""

from __future__ import annotations

import ast
import hashlib
import os
import platform
import sys
import time
from collections.abc import Iterable, Mapping
from importlib import metadata
from pathlib import Path

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


def environment() -> dict[str, str | int | list[str] | dict[str, str] | None]:
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


def describe(env: Mapping[str, object]) -> str:
    """One line for a person: date, CPU, BLAS kernel and the solver versions.

    ``env`` is an :func:`environment`, or one read back from a JSON file.
    """
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


# --------------------------------------------------------------------------------------------------
# The code a computation runs

#: The package's own folder (``racing_lib/``).
PACKAGE_ROOT = Path(__file__).resolve().parent


def _module_file(name: str, root: Path) -> Path | None:
    """The source file of package module ``name`` (``racing_lib.a.b``), or None if there is none."""
    parts = name.split(".")[1:]
    base = root.joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _imports_of(source: str, package: str) -> set[str]:
    """Every ``package`` module named by an import in ``source``, at any depth of the code.

    ``from package.a import b`` names ``package.a`` and, in case ``b`` is a submodule,
    ``package.a.b`` (names that are not modules are dropped by the caller).
    """
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == package)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] == package:
                found.add(node.module)
                found.update(f"{node.module}.{a.name}" for a in node.names)
    return found


def imported_modules(modules: Iterable[str], root: Path = PACKAGE_ROOT) -> list[str]:
    """``modules`` and every module of the package they import, directly or not, sorted.

    Read from the source (nothing is imported), function-level imports included. The packages
    whose ``__init__`` runs on the way (importing ``racing_lib.a.b`` runs ``racing_lib`` and
    ``racing_lib.a`` first) are listed too, but their own imports are not followed: a package's
    ``__init__`` that re-exports its siblings does not make them part of every computation that
    imports one of them.

    Parameters
    ----------
    modules : iterable of str
        Dotted module names of the package, e.g. ``["racing_lib.planning"]``.
    root : Path
        The package's folder (default: this installation's ``racing_lib/``).
    """
    todo = list(modules)
    followed: set[str] = set()
    parents: set[str] = set()
    while todo:
        name = todo.pop()
        if name in followed:
            continue
        path = _module_file(name, root)
        if path is None:
            continue  # an imported name that is not a module (a function, a class)
        followed.add(name)
        parts = name.split(".")
        parents.update(".".join(parts[:i]) for i in range(1, len(parts)))
        todo.extend(_imports_of(path.read_text(encoding="utf-8"), parts[0]))
    return sorted(followed | {p for p in parents if _module_file(p, root) is not None})


def _code_text(path: Path) -> str:
    """The code of a module as its syntax tree, without docstrings (comments never reach it).

    So that a cache keyed by the code follows what runs, not how it is explained: a reworded
    docstring or comment leaves the key alone, any change of a statement moves it.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                if isinstance(body[0].value.value, str):
                    node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree, include_attributes=False)


def code_digest(modules: Iterable[str], root: Path = PACKAGE_ROOT) -> str:
    """Hash (16 hex characters) of the code that ``modules`` run.

    The syntax trees, docstrings left out, of ``modules`` and of every package module they import
    (:func:`imported_modules`). Any change of a statement in that code, a move or a new import
    changes the hash; documentation and code the modules never import do not. Data files are not
    hashed: what a computation reads from them (parameters, weights) belongs in its cache key by
    value.
    """
    digest = hashlib.sha256()
    for name in imported_modules(modules, root):
        path = _module_file(name, root)
        assert path is not None  # imported_modules keeps modules with a file only
        digest.update(name.encode())
        digest.update(_code_text(path).encode())
    return digest.hexdigest()[:16]
