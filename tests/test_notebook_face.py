"""The notebooks' helpers: bound numbers reach MyST-NB's glue as text, sliders carry a static
figure of their first position."""

from __future__ import annotations

import base64

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from racing_lib.errors import ArgumentError  # noqa: E402
from racing_lib.face import notebook  # noqa: E402


@pytest.fixture
def shown(monkeypatch):
    """Everything the helpers display: (object, keyword arguments) per call."""
    calls = []
    monkeypatch.setattr("IPython.display.display", lambda obj, **kw: calls.append((obj, kw)))
    return calls


def widgets_of(bundle: dict) -> list:
    """The widgets of a displayed widget view and of its children."""
    import warnings

    from ipywidgets import Widget

    with warnings.catch_warnings():  # the registry of live widgets is a deprecated attribute
        warnings.simplefilter("ignore", DeprecationWarning)
        registry = Widget.widgets
    root = registry[bundle["application/vnd.jupyter.widget-view+json"]["model_id"]]
    out, todo = [], [root]
    while todo:
        widget = todo.pop()
        out.append(widget)
        todo += list(getattr(widget, "children", ()))
    return out


def test_bind_stores_the_formatted_text_where_myst_nb_glue_finds_it(shown):
    from ast import literal_eval

    # None: a cell that ends with bind() prints nothing.
    assert notebook.bind("lap_s", 104.1634, ".2f") is None
    notebook.bind("walls", "1,234")
    (first, kw1), (second, _) = shown
    assert kw1["raw"] and kw1["metadata"]["scrapbook"] == {
        "name": "lap_s",
        "mime_prefix": notebook.GLUE_PREFIX,
    }
    # MyST-NB strips the prefix and literal-evaluates text/plain: the prose gets the text as is.
    assert literal_eval(first[notebook.GLUE_PREFIX + "text/plain"]) == "104.16"
    assert literal_eval(second[notebook.GLUE_PREFIX + "text/plain"]) == "1,234"
    # Nothing is shown in the notebook itself (every key carries the prefix).
    assert all(k.startswith(notebook.GLUE_PREFIX) for k in first)


def test_sliders_show_the_live_widget_and_a_png_of_the_first_position(shown):
    from ipywidgets import FloatSlider

    drawn = []

    def curve(gain: float) -> None:
        drawn.append(gain)
        plt.plot([0, 1], [0, gain])
        print("only in the widget")
        plt.show()

    plt.close("all")
    slider = FloatSlider(value=2.0, min=0.0, max=5.0)
    notebook.sliders(curve, gain=slider)
    bundle = shown[0][0]
    assert "application/vnd.jupyter.widget-view+json" in bundle
    assert base64.b64decode(bundle["image/png"]).startswith(b"\x89PNG")
    assert drawn == [2.0]  # the first frame is drawn once, for the PNG
    assert plt.get_fignums() == []  # and its figure closed: nothing else shows it
    # The widget's output area holds the same frame as state; a slider moved redraws there.
    box = next(w for w in widgets_of(bundle) if hasattr(w, "outputs"))
    assert box.outputs[0]["data"]["image/png"] == bundle["image/png"]
    slider.value = 3.0
    assert drawn == [2.0, 3.0]
    assert "live" in shown[1][0].data and "`gain`" in shown[1][0].data
    assert len(shown) == 2  # the bundle and the note: no other output


def test_sliders_refuse_a_function_that_draws_nothing(shown):
    from ipywidgets import IntSlider

    with pytest.raises(ArgumentError, match="drew no figure"):
        notebook.sliders(lambda n: None, n=IntSlider(value=1))


def test_a_table_aligns_number_columns_right_and_text_columns_left():
    table = notebook.Table(
        ["row", "lap (s)", "gap", "verdict"],
        [["main", "105.10", "+1.2 %", "agrees"], ["decoupled", "—", "-0.05 ± 0.1 s", "~ ties"]],
    )
    html = table._repr_html_()
    assert table._numeric_columns() == [False, True, True, False]
    assert '<th style="text-align:right">lap (s)</th>' in html
    assert '<td style="text-align:left">agrees</td>' in html


def test_a_table_reads_spreads_counts_and_a_parenthesis_as_numbers():
    table = notebook.Table(
        ["lap (s)", "walls", "completed", "circuit"],
        [["105.61 ± 0.057 (105.50)", "0 (0.0/lap)", "10/10", "generated-1000"]],
    )
    assert table._numeric_columns() == [True, True, True, False]
