"""Look at the built book as a reader gets it: fail on markup that did not render.

Usage (after ``book/build.sh``)::

    python book/check_rendered.py                 # every page of book/_build/html
    python book/check_rendered.py PAGE.html ...   # only these files

A Sphinx build can succeed while a page shows raw source: a ``$$`` block glued to the line above
is read as text (and its ``+`` lines as a list), a Markdown table printed by a cell stays pipe
text, a cell's last expression prints an object's repr. This script reads each page's HTML,
removes what is meant to show source (code blocks, cell inputs, typeset math) and reports what is
left of:

* ``$$`` and ``\\begin{...}``: mathematics that reached the page as text;
* ``|---|``: a Markdown table that reached the page as text;
* ``<... object at 0x...>`` and ``<matplotlib...>``: a Python repr printed by accident.

Code in prose (inline code, literal blocks) and cell inputs are skipped; what cells print is
checked. It also compares, page by page, the display equations of the source notebook (``$$`` blocks
outside code) with the math blocks in the HTML: fewer in the HTML means some were not parsed as
math. Exits 1 with one line per problem (page, what, the text around it), else 0.
"""

from __future__ import annotations

import argparse
import html
import json
import re
import sys
from html.parser import HTMLParser
from pathlib import Path

BOOK = Path(__file__).resolve().parent
REPO = BOOK.parent
HTML_ROOT = BOOK / "_build" / "html"

#: What must not be visible outside code and math: (name, pattern).
PATTERNS = (
    ("raw display math ($$)", re.compile(r"\$\$")),
    ("raw LaTeX environment", re.compile(r"\\begin\{")),
    ("Markdown table as text", re.compile(r"\|\s*:?-{3,}:?\s*\|")),
    ("Python repr", re.compile(r"<[\w.]+ object at 0x[0-9a-f]+>")),
    ("matplotlib repr", re.compile(r"<matplotlib\.[\w.]+ (?:at|object)")),
)
#: Elements whose text is never shown as prose.
_HIDDEN_TAGS = {"script", "style", "textarea", "head"}
#: Classes whose text is source on purpose: cell inputs, and math that MathJax typesets.
_SOURCE_CLASSES = {"cell_input", "math"}
#: Code shown on purpose in prose (inline code, literal blocks); inside a cell's output the same
#: tags hold what the cell printed, which is checked.
_CODE_TAGS = {"pre", "code", "kbd", "samp"}
_VOID_TAGS = {"br", "img", "hr", "meta", "link", "input", "wbr", "source", "col", "area"}


class _VisibleText(HTMLParser):
    """Collects the text a reader sees as prose or as cell output; counts the math blocks."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.parts: list[str] = []
        self.display_math = 0
        # Per open element: (its text is hidden, it is inside a cell's output).
        self._stack: list[tuple[bool, bool]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag in _VOID_TAGS:
            return
        classes = set((dict(attrs).get("class") or "").split())
        if tag == "div" and "math" in classes:
            self.display_math += 1
        hidden, in_output = self._stack[-1] if self._stack else (False, False)
        in_output = in_output or "cell_output" in classes
        hidden = (
            hidden
            or tag in _HIDDEN_TAGS
            or bool(classes & _SOURCE_CLASSES)
            or (tag in _CODE_TAGS and not in_output)
        )
        self._stack.append((hidden, in_output))

    def handle_endtag(self, tag: str) -> None:
        if tag not in _VOID_TAGS and self._stack:
            self._stack.pop()

    def handle_data(self, data: str) -> None:
        if not (self._stack and self._stack[-1][0]):
            self.parts.append(data)


def visible_text(page_html: str) -> tuple[str, int]:
    """(text a reader sees outside code and math, number of display-math blocks) of a page."""
    parser = _VisibleText()
    parser.feed(page_html)
    return "".join(parser.parts), parser.display_math


def source_display_math(notebook: Path) -> int:
    """Number of ``$$ ... $$`` display equations in a notebook's Markdown cells."""
    count = 0
    for cell in json.loads(notebook.read_text(encoding="utf-8"))["cells"]:
        if cell["cell_type"] != "markdown":
            continue
        text = "".join(cell["source"])
        text = re.sub(r"```.*?```", "", text, flags=re.S)  # fenced code shows $$ on purpose
        count += text.count("$$") // 2
    return count


def check_page(page: Path, source: Path | None = None) -> list[str]:
    """Problems found on one built page (empty when it renders cleanly)."""
    text, n_math = visible_text(page.read_text(encoding="utf-8"))
    problems = []
    for name, pattern in PATTERNS:
        for match in pattern.finditer(text):
            around = text[max(0, match.start() - 40) : match.end() + 40]
            around = " ".join(html.unescape(around).split())
            problems.append(f"{page}: {name}: ...{around}...")
    if source is not None and source.exists():
        want = source_display_math(source)
        if n_math < want:
            problems.append(
                f"{page}: {want} display equations in {source.name}, {n_math} rendered as math "
                "(a $$ block glued to the line above, or unbalanced $$, is read as text)"
            )
    return problems


def source_of(page: Path) -> Path | None:
    """The notebook a built page was made from, if any."""
    try:
        rel = page.resolve().relative_to(HTML_ROOT.resolve())
    except ValueError:
        return None
    candidate = REPO / rel.with_suffix(".ipynb")
    return candidate if candidate.exists() else None


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pages", nargs="*", type=Path, help="HTML files (default: the whole book)")
    args = parser.parse_args(argv)
    pages = args.pages or sorted(
        p for p in HTML_ROOT.rglob("*.html") if not {"_static", "_sources"} & set(p.parts)
    )
    if not pages:
        print(f"check_rendered: no pages under {HTML_ROOT}; build the book first", file=sys.stderr)
        return 2
    problems = [line for page in pages for line in check_page(page, source_of(page))]
    for line in problems:
        print(line, file=sys.stderr)
    print(f"check_rendered: {len(pages)} pages, {len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
