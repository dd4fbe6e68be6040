"""The course's figures: the diagrams draw what they name, the lap animation and the lap-time
distribution show the lap they are given, the corner zooms are labelled."""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.patches import FancyArrowPatch  # noqa: E402

from racing_lib.face import plotting, schematics  # noqa: E402
from racing_lib.tracks import corner_positions, load_track  # noqa: E402


def _texts(ax) -> str:
    return " ".join(t.get_text() for t in ax.texts)


def test_the_frenet_diagram_names_every_quantity_of_the_model():
    ax = schematics.draw_frenet_frame()
    text = _texts(ax)
    for symbol in ("$s$", "$e_y$", r"$e_\psi$", "$v_x$", "$v_y$", "$r$", r"$\delta$", "$l_f$"):
        assert symbol in text, symbol
    plt.close(ax.figure)


def test_the_pipeline_diagram_has_every_stage_and_the_loop():
    ax = schematics.draw_pipeline()
    text = _texts(ax)
    for stage in ("curvature QP", "time-optimal", "coupled MPC", "simulated car", "CMA-ES"):
        assert stage in text, stage
    for flow in ("warm\nstart", "optional", "steer, pedal", "state", "weights", "lap score"):
        assert flow in text, flow
    # The warm start is optional in the library (the NLP starts cold by default): its one arrow
    # is dashed, every other arrow solid.
    styles = [p.get_linestyle() for p in ax.patches if isinstance(p, FancyArrowPatch)]
    assert sum(style != "-" for style in styles) == 1, styles
    plt.close(ax.figure)


@pytest.fixture(scope="module")
def circle_lap():
    """A made-up lap round the circle track: 40 s at 20 m/s."""
    from types import SimpleNamespace

    from racing_lib.tracks import circle_track

    track = circle_track(radius=100.0, width=10.0)
    t = np.arange(0.0, 40.0, 0.1)
    angle = 0.2 * t
    log = SimpleNamespace(
        t=t, x=100.0 * np.cos(angle), y=100.0 * np.sin(angle), vx=np.full(t.size, 20.0),
        in_lap=(t > 1.0) & (t < 32.0),
    )  # fmt: skip
    return track, log


def test_the_lap_animation_follows_the_lap(circle_lap):
    track, log = circle_lap
    anim = plotting.lap_animation(track, log, frames=12)
    frames = list(anim.new_frame_seq())
    assert len(frames) == 12
    path, car, label = anim._func(11)  # the last frame: the end of the lap, with its trail
    x, y = car.get_data()
    last = int(np.flatnonzero(log.in_lap)[-1])
    assert x[0] == pytest.approx(log.x[last]) and y[0] == pytest.approx(log.y[last])
    assert len(path.get_data()[0]) == 81  # 8 s of trail at 0.1 s
    assert "72 km/h" in label.get_text()
    html = anim.to_jshtml()
    assert html.count("data:image/png;base64") == 12


def test_the_lap_time_plot_marks_wall_contacts_and_plans():
    trial = {"completed": True, "lap_time_s": 106.0, "wall_contacts": 0}
    rows = [
        {"name": "clean", "planned_lap_time_s": 105.0, "trial_metrics": [trial, trial]},
        {"name": "walls", "planned_lap_time_s": 104.0,
         "trial_metrics": [trial, {**trial, "lap_time_s": 107.0, "wall_contacts": 2}]},
    ]  # fmt: skip
    ax = plotting.plot_lap_times(rows, best=103.0)
    dots = [c for c in ax.collections]
    colors = [tuple(np.round(c, 3)) for d in dots for c in d.get_facecolors()]
    red = tuple(np.round(matplotlib.colors.to_rgba("crimson"), 3))
    assert colors.count(red) == 1
    assert [t.get_text() for t in ax.get_yticklabels()] == ["clean", "walls"]
    plt.close(ax.figure)


def test_the_corner_zooms_are_labelled_in_metres():
    track = load_track("expressway")
    corners = corner_positions(track)
    fig, axes = plotting.plot_corners(track, corners)
    assert axes[0].get_ylabel() == "$y$ [m]" and axes[3].get_ylabel() == "$y$ [m]"
    assert axes[1].get_ylabel() == ""
    assert all(ax.get_xlabel() == "$x$ [m]" for ax in axes[3:6])
    plt.close(fig)


# --- what every figure of the course may use: a size for the column, fonts a reader can read and
# --- symbols typeset as math. Read from the source, so a new cell is checked the day it is written.

_ROOT = Path(__file__).resolve().parents[1]
_LABEL_CALLS = {"set_xlabel", "set_ylabel", "set_title", "suptitle", "annotate", "text"}
_LABEL_KEYWORDS = {"xlabel", "ylabel", "title", "label"}
# A symbol written in plain text: an identifier with a subscript such as e_y, v_x or r_ss.
_PLAIN_SYMBOL = re.compile(r"\b[A-Za-z]+_[A-Za-z0-9]+\b")


def _figure_sources() -> list[tuple[str, str]]:
    sources = []
    for notebook in sorted((_ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(notebook.read_text())["cells"]
        for number, cell in enumerate(cells):
            if cell["cell_type"] == "code":
                lines = "".join(cell["source"]).splitlines(keepends=True)
                code = "".join(line for line in lines if not line.lstrip().startswith(("%", "!")))
                sources.append((f"{notebook.name} cell {number}", code))
    for module in sorted((_ROOT / "racing_lib" / "face").glob("*.py")):
        sources.append((module.name, module.read_text()))
    return sources


def _literal_strings(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, ast.JoinedStr):
        return ["".join(v.value if isinstance(v, ast.Constant) else "{}" for v in node.values)]
    if isinstance(node, ast.Tuple | ast.List):
        return [s for element in node.elts for s in _literal_strings(element)]
    return []


def _calls(source: str) -> list[ast.Call]:
    return [node for node in ast.walk(ast.parse(source)) if isinstance(node, ast.Call)]


def _outside_math(text: str) -> str:
    return "".join(text.split("$")[0::2])


def test_every_figure_fits_the_book_column_and_uses_readable_fonts():
    too_wide, too_small = [], []
    for where, source in _figure_sources():
        for call in _calls(source):
            for keyword in call.keywords:
                value = keyword.value
                if keyword.arg == "figsize" and isinstance(value, ast.Tuple):
                    width = value.elts[0]
                    if isinstance(width, ast.Constant) and width.value > plotting.COLUMN_WIDTH_IN:
                        too_wide.append(f"{where}: figsize width {width.value} in")
                if keyword.arg == "fontsize" and isinstance(value, ast.Constant):
                    if (
                        isinstance(value.value, int | float)
                        and value.value < plotting.SMALLEST_FONT_PT
                    ):
                        too_small.append(f"{where}: fontsize {value.value}")
    assert not too_wide, f"wider than the book's column ({plotting.COLUMN_WIDTH_IN} in): {too_wide}"
    assert not too_small, f"smaller than {plotting.SMALLEST_FONT_PT} pt: {too_small}"


def test_axis_labels_and_legends_typeset_their_symbols():
    plain = []
    for where, source in _figure_sources():
        for call in _calls(source):
            name = getattr(call.func, "attr", getattr(call.func, "id", ""))
            texts = [s for a in call.args[:1] if name in _LABEL_CALLS for s in _literal_strings(a)]
            texts += [
                s
                for k in call.keywords
                if k.arg in _LABEL_KEYWORDS or (k.arg or "").endswith("label")
                for s in _literal_strings(k.value)
            ]
            plain += [f"{where}: {t!r}" for t in texts if _PLAIN_SYMBOL.search(_outside_math(t))]
    assert not plain, f"write symbols as math ($e_y$, not e_y): {plain}"


def test_the_checks_above_catch_a_wide_figure_and_a_plain_symbol():
    source = 'fig, ax = plt.subplots(figsize=(12, 3))\nax.set_ylabel("e_y [m]")\n'
    (call_subplots, call_label) = sorted(_calls(source), key=lambda c: c.lineno)[:2]
    assert call_subplots.keywords[0].value.elts[0].value > plotting.COLUMN_WIDTH_IN
    text = _literal_strings(call_label.args[0])[0]
    assert _PLAIN_SYMBOL.search(_outside_math(text))
    assert not _PLAIN_SYMBOL.search(_outside_math("$e_y$ [m]"))
