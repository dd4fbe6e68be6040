"""Every number in a chapter's prose comes from a cell, or is declared as a fixed one.

Usage (from the repository root)::

    python book/prose_numbers.py                    # every chapter; exit 1 on an unbound number
    python book/prose_numbers.py notebooks/04_*.ipynb

A measured number typed into a sentence goes stale the next time the code changes, and nothing
notices: this is how fifteen sentences came to contradict the outputs beside them. So a chapter's
Markdown may hold a number in exactly three ways:

* **bound to a cell**: ``{glue:text}`key``` where a code cell of the same notebook calls
  ``racing_lib.face.notebook.bind("key", ...)``; the book pastes the value that cell computed;
* **declared fixed**: listed in the notebook's metadata ``racing_lab.fixed_numbers`` (the number
  as written -> why it is fixed), with a reason that starts with ``paper:`` (quoted from the
  paper), ``setting:`` (a value the page chooses, such as a step or a seed count) or ``fact:``
  (a property of the world or of a named circuit);
* **not a quantity**: a cell that starts with a ``## Further reading`` heading (years, volumes
  and pages of references), a structural number (``Eq. 5``, ``section 3``, ``chapter 04``,
  ``Table I``, ``4.1`` after "claim" or "section"), a small whole number without a unit (at most
  99: "three seeds" written as "3 seeds"), or a number inside math, code or a link target.

Everything else is *unbound* and fails ``tests/test_book.py``. A declaration that no sentence
uses any more fails too, so the list cannot rot.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from pathlib import Path

import nbformat

REPO = Path(__file__).resolve().parents[1]
CHAPTERS = sorted((REPO / "notebooks").glob("[0-9][0-9]_*.ipynb"))
#: Where a notebook declares its fixed numbers, and the reasons a number may be fixed.
METADATA_KEY = "racing_lab"
FIXED_KEY = "fixed_numbers"
REASONS = ("paper:", "setting:", "fact:")

_GLUE_ROLE = re.compile(r"\{glue(?::\w+)?\}`([^`]+)`")
_BIND_CALL = re.compile(r"\bbind\(\s*[\"']([\w.-]+)[\"']")
#: Spans whose digits are not prose: display and inline math, code, link targets, HTML tags,
#: MyST roles and directives' options.
_NOT_PROSE = (
    re.compile(r"\$\$.*?\$\$", re.S),
    re.compile(r"\\\[.*?\\\]", re.S),
    re.compile(r"(?<!\\)\$[^$\n]+\$"),
    re.compile(r"```.*?```", re.S),
    re.compile(r"\{[\w:-]+\}`[^`]*`"),
    re.compile(r"`[^`]*`"),
    re.compile(r"\]\([^)]*\)"),
    re.compile(r"<[^>]+>"),
    re.compile(r"^\s*:[\w-]+:.*$", re.M),
)
#: A number as prose writes it (thousands separators, decimals, ranges), with the unit after it.
_NUMBER = re.compile(
    r"(?<![\w.,/-])[-+−±]?(?P<digits>\d+(?:[,\u202f]\d{3})*(?:\.\d+)?)"
    # a range ("10-12 m", "2–7 km") is one number: its first end has no unit of its own
    r"(?:\s?[-–]\s?\d+(?:\.\d+)?)?"
    r"(?:\s?(?P<unit>%|km/h|km|m/s\^?2?|m/s²|ms|m|s|rad/s|rad|deg|°|×|x|g|kg|Hz|N)(?![\w]))?(?![\w])"
)
#: Words after which a number names a part of a text, not a quantity.
_STRUCTURAL = re.compile(
    r"\b(?:Eqs?\.|[Ee]quations?|[Ss]ections?|§|[Cc]hapters?|[Cc]laims?|Table|Fig\.|"
    r"[Ff]igures?|[Ee]xercises?|[Ss]teps?|[Aa]ppendix|[Ii]teration|[Ss]eeds?|[Ll]ines?|"
    r"[Cc]ells?|[Rr]ows?|[Cc]olumns?|[Pp]art|v|version|arXiv)\s*(?:\d+(?:\.\d+)*\s*(?:,|and|to|-|–)\s*)*$"
)
_BIBLIOGRAPHY = re.compile(r"\s*#+\s*Further reading")
_HEADING_NUMBER = re.compile(r"^(#+\s*)\d+(?:\.\d+)*\.?", re.M)


@dataclass(frozen=True)
class Unbound:
    """One number that is neither bound to a cell nor declared fixed."""

    notebook: str
    cell: int
    number: str
    context: str

    def __str__(self) -> str:
        return f"{self.notebook} cell {self.cell}: {self.number!r} in '...{self.context}...'"


def _prose(markdown: str) -> str:
    """The Markdown with math, code, roles, link targets and heading numbers blanked out."""
    text = _HEADING_NUMBER.sub(lambda m: m.group(1), markdown)
    for pattern in _NOT_PROSE:
        text = pattern.sub(lambda m: " " * len(m.group()), text)
    return text


def _is_quantity(text: str, match: re.Match[str]) -> bool:
    """Whether the number at ``match`` states a quantity (not a name of a part of the text)."""
    if _STRUCTURAL.search(text[max(0, match.start() - 40) : match.start()]):
        return False
    digits = match.group("digits")
    if "." in digits or match.group("unit"):
        return True
    # A small whole number without a unit counts things ("3 seeds", "the 2 axles").
    return int(re.sub(r"\D", "", digits)) >= 100


def numbers_in(markdown: str) -> list[tuple[str, str]]:
    """The quantities of one Markdown cell's prose, each with a little of its context."""
    text = _prose(markdown)
    found = []
    for match in _NUMBER.finditer(text):
        if _is_quantity(text, match):
            context = " ".join(text[max(0, match.start() - 30) : match.end() + 20].split())
            found.append((match.group().strip(), context))
    return found


def fixed_numbers(nb: nbformat.NotebookNode) -> dict[str, str]:
    """The notebook's declared fixed numbers (the number as written -> the reason)."""
    return dict(nb.metadata.get(METADATA_KEY, {}).get(FIXED_KEY, {}))


def check_notebook(path: Path) -> list[str]:
    """Every problem of one notebook's prose numbers, one line each (empty when it is clean)."""
    nb = nbformat.read(path, as_version=4)
    name = path.name
    fixed = fixed_numbers(nb)
    problems = [
        f"{name}: fixed number {number!r} has reason {reason!r}; start it with one of {REASONS}"
        for number, reason in fixed.items()
        if not reason.startswith(REASONS)
    ]
    bound = {key for c in nb.cells if c.cell_type == "code" for key in _BIND_CALL.findall(c.source)}
    used_fixed: set[str] = set()
    for index, cell in enumerate(nb.cells):
        if cell.cell_type != "markdown" or _BIBLIOGRAPHY.match(cell.source):
            continue
        for key in _GLUE_ROLE.findall(cell.source):
            key = key.split("::")[-1].rsplit(":", 1)[0] if ":" in key else key
            if key not in bound:
                problems.append(
                    f"{name} cell {index}: {{glue}} key {key!r} is not bound by any code cell "
                    "(call racing_lib.face.notebook.bind with it)"
                )
        for number, context in numbers_in(cell.source):
            if number in fixed:
                used_fixed.add(number)
            else:
                problems.append(str(Unbound(name, index, number, context)))
    problems += [
        f"{name}: fixed number {number!r} is declared but no sentence uses it; remove it"
        for number in sorted(set(fixed) - used_fixed)
    ]
    return problems


def main(argv: list[str] | None = None) -> int:
    """Check the given notebooks (default: every chapter); print problems; 1 if any."""
    paths = [Path(a) for a in (argv if argv is not None else sys.argv[1:])] or CHAPTERS
    problems = [p for path in paths for p in check_notebook(path)]
    for line in problems:
        print(line)
    print(f"{len(problems)} unbound or stale number(s) in {len(paths)} notebook(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
