"""Sphinx extension of the book: read ``|x|`` in racing_lib's docstrings as absolute values.

The library's NumPy-style docstrings write absolute values and norms the way the equations do,
``|e_y|`` or ``max |Delta e_y|``. reStructuredText reads ``|name|`` as a substitution reference
and fails the build ("Undefined substitution referenced"). Before autodoc parses a docstring,
this escapes every bar outside inline literals and table rows, so it is shown as written.
"""

from __future__ import annotations

from typing import Any


def _escape_line(line: str) -> str:
    stripped = line.lstrip()
    # Table borders ("+---+") and rows or line blocks ("| ...") use bars as markup.
    if stripped.startswith(("+-", "+=", "| ")) or stripped == "|":
        return line
    parts = line.split("``")
    for i in range(0, len(parts), 2):  # even parts are outside ``inline literals``
        pieces = parts[i].split("`")
        for j in range(0, len(pieces), 2):  # and outside `interpreted text`
            pieces[j] = pieces[j].replace("|", "\\|")
        parts[i] = "`".join(pieces)
    return "``".join(parts)


def escape_bars(app: Any, what: str, name: str, obj: Any, options: Any, lines: list[str]) -> None:
    """``autodoc-process-docstring`` handler: escape bars in place."""
    lines[:] = [_escape_line(line) for line in lines]


def setup(app: Any) -> dict[str, Any]:
    app.connect("autodoc-process-docstring", escape_bars)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
