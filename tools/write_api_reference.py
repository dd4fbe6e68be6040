"""Write book/api.md, the API reference, from the package's layers.

Run after adding, moving or removing a module: ``python tools/write_api_reference.py``. The test
``tests/test_book.py`` fails while the page is not what this script writes. Sections follow the
layers of ``racing_lib`` from the bottom up (the contract in ``pyproject.toml``,
``[tool.importlinter]``).
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import racing_lib

BOOK = Path(__file__).resolve().parents[1] / "book"

#: (section title, package or module prefixes), bottom layer first.
SECTIONS = [
    ("Geometry: paths, Frenet coordinates and tracks", ["racing_lib.geometry"]),
    ("Optimizers", ["racing_lib.optim"]),
    ("The built-in tracks and the track registry", ["racing_lib.tracks"]),
    ("The car: parameters, force laws, equations of motion", ["racing_lib.vehicle"]),
    ("The planning and control model", ["racing_lib.model"]),
    ("What plants and controllers exchange", ["racing_lib.interfaces"]),
    ("The simulated car", ["racing_lib.sim"]),
    ("Plants nobody here wrote", ["racing_lib.plants"]),
    ("Planning", ["racing_lib.planning"]),
    ("Control", ["racing_lib.control"]),
    ("Experiments: laps, identification, tuning, the paper's tables", ["racing_lib.experiments"]),
    ("A Gymnasium environment", ["racing_lib.envs"]),
    ("Plots, notebooks and the command line", ["racing_lib.face"]),
    ("Exercise checks", ["racing_lib.grading"]),
    (
        "Settings, errors, files and provenance (imported by every layer)",
        [
            "racing_lib.config",
            "racing_lib.errors",
            "racing_lib.io",
            "racing_lib.jit",
            "racing_lib.provenance",
        ],
    ),
]

#: Documented elsewhere: the command line in the README, the package's errors in racing_lib.errors.
SKIP = {"racing_lib", "racing_lib.face.cli"}


def public_modules() -> list[str]:
    """Every module of racing_lib whose last name part does not start with an underscore."""
    names = []
    for info in pkgutil.walk_packages(racing_lib.__path__, "racing_lib."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            names.append(info.name)
    return sorted(names)


def _entry(name: str) -> str:
    module = importlib.import_module(name)
    is_package = hasattr(module, "__path__")
    # A package's own page is its docstring only: its members are documented in their modules
    # (re-exported names would otherwise appear twice).
    members = "" if is_package else "   :members:\n"
    return f"### `{name}`\n\n```{{eval-rst}}\n.. automodule:: {name}\n{members}```\n"


def render() -> str:
    """The text of book/api.md."""
    modules = [m for m in public_modules() if m not in SKIP]
    out = [
        "# API reference\n",
        "The library `racing_lib`, from its docstrings. Units are SI (m, s, rad, m/s, m/s^2,\n"
        "N, kg); symbols as in the paper (see the table in `CONTRIBUTING.md`). The sections\n"
        "follow the layers, from the bottom up: each imports only from the sections above it\n"
        "and from the base utilities of the last section (the contract is in `pyproject.toml`,\n"
        "`[tool.importlinter]`; `CONTRIBUTING.md` maps where things go).\n",
    ]
    placed: set[str] = set()
    for title, prefixes in SECTIONS:
        mine = [
            m
            for m in modules
            if m not in placed and any(m == p or m.startswith(p + ".") for p in prefixes)
        ]
        if not mine:
            continue
        placed.update(mine)
        out.append(f"## {title}\n")
        out.extend(_entry(m) for m in mine)
    left = [m for m in modules if m not in placed]
    if left:
        raise SystemExit(f"modules in no section of SECTIONS: {left}; add them to a section.")
    return "\n".join(out)


def main() -> None:
    (BOOK / "api.md").write_text(render())
    print(f"wrote {BOOK / 'api.md'}")


if __name__ == "__main__":
    main()
