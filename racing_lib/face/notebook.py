"""The one set-up call at the top of every notebook, its tables, bound numbers and sliders.

``setup()`` fixes the plot style, NumPy's print options (so printed numbers are short and stable
under nbval), and the random seed, and reports the versions of the solvers the chapter relies on.
:class:`Table` shows rows of text as a real table in JupyterLab and in the book (a Markdown
string in ``display(Markdown(...))`` reaches the book's pages as raw pipes). :func:`bind` hands a
computed number to the chapter's prose, and :func:`sliders` shows a figure with sliders that the
book renders at their first position.
"""

from __future__ import annotations

import contextlib
import html
import importlib.metadata
import io
import re
from collections.abc import Callable, Sequence
from typing import Any
from unittest import mock

import numpy as np

from racing_lib.config import fast_mode
from racing_lib.errors import ArgumentError
from racing_lib.face.plotting import set_style

_SOLVERS = ("numpy", "scipy", "casadi", "cvxpy", "osqp", "control", "cma")
_CODE = re.compile(r"`([^`]+)`")
#: Cells that hold no value (they do not decide how a column aligns).
_BLANK = {"", "-", "–", "—", "n/a", "nan"}
#: A table cell that states a number: an optional sign or mark, digits (or a count "3/10"), then
#: at most a unit or a spread, and at most one parenthesis after it ("105.61 ± 0.057 (105.50)").
_NUMBER = re.compile(
    r"^\s*[-+−±~≠<>]?\s*\d[\d.,]*(?:/\d+)?\s*(?:[%a-zA-Z/^²°]{0,5}|±\s*[\d.]+\s*\w{0,3})"
    r"\s*(?:\([^()]*\))?\s*$"
)


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

    def _numeric_columns(self) -> list[bool]:
        """Per column, whether every non-empty body cell is a number (aligned right)."""
        return [
            any(row[i].strip() not in _BLANK for row in self.rows)
            and all(_NUMBER.match(row[i]) for row in self.rows if row[i].strip() not in _BLANK)
            for i in range(len(self.header))
        ]

    def _repr_html_(self) -> str:
        # Numbers align right so their digits line up; text aligns left to read.
        align = ["right" if n else "left" for n in self._numeric_columns()]
        head = "".join(
            f'<th style="text-align:{a}">{self._cell(h)}</th>'
            for h, a in zip(self.header, align, strict=True)
        )
        body = "".join(
            "<tr>"
            + "".join(
                f'<td style="text-align:{a}">{self._cell(c)}</td>'
                for c, a in zip(row, align, strict=True)
            )
            + "</tr>"
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


#: The MIME prefix under which MyST-NB's ``glue`` stores a value without showing it.
GLUE_PREFIX = "application/papermill.record/"


def bind(key: str, value: object, fmt: str = "") -> None:
    """Hand a computed number to the chapter's prose, where ``{glue:text}`key``` shows it.

    The book (MyST-NB) pastes the text into the sentence, so a sentence can never disagree with
    the cell that computed its number; ``book/prose_numbers.py`` fails on any number typed into
    prose instead. In JupyterLab the sentence shows the key, and the cell prints the value.
    This writes the output MyST-NB's ``glue`` writes, so the course needs MyST-NB only to build
    the book, not to run.

    Parameters
    ----------
    key : str
        The name the prose uses; unique within the notebook.
    value : object
        The number (or any value) to show.
    fmt : str
        A format specification applied to ``value`` here (``".2f"``, ``"+.1%"``); the prose
        gets the formatted text, units included if ``value`` is already a string.

    Nothing is returned, so a cell may end with a ``bind`` call without printing anything.
    """
    from IPython.display import display

    text = format(value, fmt) if fmt else str(value)
    # repr: MyST-NB literal-evaluates the stored text, so "1,234" would otherwise become a tuple.
    display(
        {GLUE_PREFIX + "text/plain": repr(text)},
        raw=True,
        metadata={"scrapbook": {"name": key, "mime_prefix": GLUE_PREFIX}},
    )


def _first_frame(draw: Callable[..., None], values: dict[str, Any]) -> bytes:
    """PNG of the figure ``draw`` makes at ``values`` (its ``plt.show`` held back)."""
    import matplotlib.pyplot as plt

    before = set(plt.get_fignums())
    # A blank current figure, so that a draw that plots into "the current figure" draws here.
    plt.figure()
    # What draw prints goes to the widget in JupyterLab; printed here it would show twice.
    with (
        mock.patch.object(plt, "show", lambda *args, **kwargs: None),
        contextlib.redirect_stdout(io.StringIO()),
    ):
        draw(**values)
    new = [n for n in plt.get_fignums() if n not in before]
    drawn = [n for n in new if plt.figure(n).get_axes()]
    if not drawn:
        for number in new:
            plt.close(number)
        raise ArgumentError(f"{draw.__name__} drew no figure; sliders() needs one to show")
    buffer = io.BytesIO()
    figure = plt.figure(drawn[-1])
    figure.savefig(buffer, format="png", bbox_inches="tight")
    for number in new:
        plt.close(number)
    return buffer.getvalue()


def sliders(draw: Callable[..., None], **controls: Any) -> None:
    """Show ``draw``'s figure with sliders: live in JupyterLab, at their first position in the book.

    ``ipywidgets.interact`` alone leaves a static page empty (the figure lives in the widget's
    state, which the book cannot run), and a client without widget support (nbval) records its
    first frame as a plain output. So the first frame is drawn once, as a PNG, and put in two
    places: in the state of the widget's output area (JupyterLab shows it until a slider moves,
    then ``draw`` redraws there) and beside the widget view in the same output, where the book,
    which is told to skip widget views (``book/_config.yml``), finds it.

    Parameters
    ----------
    draw : callable
        Draws one figure from keyword arguments and calls ``plt.show()``.
    **controls
        One ``ipywidgets`` control per keyword argument of ``draw`` (their ``value`` is the
        first position).
    """
    import base64

    from IPython.display import Markdown, display
    from ipywidgets import Output, VBox

    first = {name: control.value for name, control in controls.items()}
    png = base64.b64encode(_first_frame(draw, first)).decode("ascii")
    area = Output()
    # Set as state, not displayed: no output message, so no client records the frame twice.
    area.outputs = (
        {
            "output_type": "display_data",
            "data": {"image/png": png, "text/plain": f"<{draw.__name__} at the first position>"},
            "metadata": {},
        },
    )

    def redraw(_change: object) -> None:
        with area:
            area.clear_output(wait=True)
            draw(**{name: control.value for name, control in controls.items()})

    for control in controls.values():
        control.observe(redraw, names="value")
    bundle = VBox([*controls.values(), area])._repr_mimebundle_()
    bundle["image/png"] = png
    bundle["text/plain"] = (
        f"{draw.__name__}: sliders for {', '.join(controls)} (live in JupyterLab)"
    )
    display(bundle, raw=True)
    names = ", ".join(f"`{name}`" for name in controls)
    display(
        Markdown(
            f"*Sliders ({names}): live when the notebook runs in JupyterLab; a static page shows "
            "the figure at their first position.*"
        )
    )
