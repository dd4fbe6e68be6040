"""The one set-up call at the top of every notebook of the course, and its tables.

``setup()`` fixes the plot style, NumPy's print options (so printed numbers are short and stable
under nbval), and the random seed, and reports the versions of the solvers the chapter relies on.
:class:`Table` shows rows of text as a real table in JupyterLab and in the book (a Markdown
string in ``display(Markdown(...))`` reaches the book's pages as raw pipes).
"""

from __future__ import annotations

import html
import importlib.metadata
import re
from collections.abc import Sequence

import numpy as np

from racing_lib.config import fast_mode
from racing_lib.errors import ArgumentError
from racing_lib.face.plotting import set_style

_SOLVERS = ("numpy", "scipy", "casadi", "cvxpy", "osqp", "control", "cma")
_CODE = re.compile(r"`([^`]+)`")


class Table:
    """Rows of text shown as a table: HTML in a notebook or the book, aligned text elsewhere.

    Parameters
    ----------
    header : sequence of str
        Column titles.
    rows : sequence of sequence of str
        One sequence of cell texts per row, as many as ``header``; text in backticks is shown
        as code.
    """

    def __init__(self, header: Sequence[str], rows: Sequence[Sequence[str]]) -> None:
        self.header = [str(h) for h in header]
        self.rows = [[str(c) for c in row] for row in rows]
        bad = [i for i, row in enumerate(self.rows) if len(row) != len(self.header)]
        if bad:
            raise ArgumentError(
                f"Table rows {bad} do not have {len(self.header)} cells, one per column title."
            )

    @classmethod
    def from_records(cls, records: Sequence[dict[str, str]]) -> Table:
        """A table of dicts with the same keys (the column titles), one per row."""
        header = list(records[0]) if records else []
        return cls(header, [[r[c] for c in header] for r in records])

    @staticmethod
    def _cell(text: str) -> str:
        return _CODE.sub(r"<code>\1</code>", html.escape(text))

    def _repr_html_(self) -> str:
        head = "".join(f"<th>{self._cell(h)}</th>" for h in self.header)
        body = "".join(
            "<tr>" + "".join(f"<td>{self._cell(c)}</td>" for c in row) + "</tr>"
            for row in self.rows
        )
        return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"

    def __repr__(self) -> str:
        cells = [self.header, *self.rows]
        widths = [max(len(r[i]) for r in cells) for i in range(len(self.header))]
        lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
        lines.insert(1, "  ".join("-" * w for w in widths))
        return "\n".join(line.rstrip() for line in lines)


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
