"""The book: its table of contents points at files that exist, the API page covers every module,
the reference list matches the paper's citations, the rendered-page check catches each fault it
names, and (opt-in, as CI does) the book builds without a warning, no page shows raw markup and
every equation is typeset in headless Chromium.

The full build executes every notebook, so it is not part of a plain ``pytest`` run: CI runs
``book/build.sh``, ``book/check_rendered.py`` and ``book/screenshot.py`` as their own step. Set
``RACING_LIB_BOOK=1`` to run that build here too (it needs ``pip install -e ".[book]"`` and
Chromium).
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BOOK = REPO / "book"
PAPER = REPO.parent / "shared" / "paper" / "outracing_human_racers.tex"

yaml = pytest.importorskip("yaml")


def _toc_entries(node) -> list[dict]:
    """Every dict of the ToC tree that names a file or a glob."""
    out = []
    if isinstance(node, dict):
        if "file" in node or "glob" in node:
            out.append(node)
        for value in node.values():
            out += _toc_entries(value)
    elif isinstance(node, list):
        for item in node:
            out += _toc_entries(item)
    return out


def _exists(doc: str) -> bool:
    return any((REPO / f"{doc}{ext}").exists() for ext in (".md", ".ipynb", ""))


def test_toc_points_at_existing_files():
    toc = yaml.safe_load((BOOK / "_toc.yml").read_text())
    assert _exists(toc["root"]), f"the book's root page {toc['root']} is missing"
    entries = _toc_entries(toc)
    assert entries
    for entry in entries:
        if "file" in entry:
            assert _exists(entry["file"]), f"_toc.yml names {entry['file']}, which does not exist"
        else:
            assert sorted(REPO.glob(entry["glob"] + ".*")), (
                f"_toc.yml glob {entry['glob']} is empty"
            )


def test_every_chapter_and_exercise_notebook_is_in_the_book():
    config = yaml.safe_load((BOOK / "_config.yml").read_text())
    assert config["only_build_toc_files"] is True
    toc_text = (BOOK / "_toc.yml").read_text()
    assert "glob: notebooks/*" in toc_text
    assert "glob: exercises/0*" in toc_text
    assert config["execute"]["execute_notebooks"] in ("force", "cache")


def _api_writer():
    spec = importlib.util.spec_from_file_location(
        "write_api_reference", BOOK.parent / "tools" / "write_api_reference.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_api_reference_covers_every_public_module():
    writer = _api_writer()
    api = (BOOK / "api.md").read_text()
    documented = re.findall(r"\.\. automodule:: ([\w.]+)", api)
    missing = set(writer.public_modules()) - set(documented) - writer.SKIP
    assert not missing, f"run `python tools/write_api_reference.py`; missing: {sorted(missing)}"
    assert len(documented) == len(set(documented)), "a module is documented twice"
    assert api == writer.render(), "book/api.md is stale: run `python tools/write_api_reference.py`"


def test_references_are_citations_of_the_paper():
    if not PAPER.exists():
        pytest.skip("the paper's source is not beside the repository")
    cited = set()
    for group in re.findall(r"\\cite[tp]?\{([^}]*)\}", PAPER.read_text()):
        cited.update(key.strip() for key in group.split(","))
    listed = re.findall(r"^- \[([^\]]+)\]", (BOOK / "references.md").read_text(), re.M)
    assert listed
    not_cited = set(listed) - cited
    assert not not_cited, f"references.md lists works the paper does not cite: {not_cited}"


def test_build_command_fails_on_warnings():
    script = (BOOK / "build.sh").read_text()
    assert "--warningiserror" in script and "--keep-going" in script
    assert "RACING_LIB_FAST" in script
    assert "check_rendered.py" in script  # the rendered pages are checked as part of the build
    assert os.access(BOOK / "build.sh", os.X_OK), "book/build.sh must be executable"


@pytest.mark.slow
def test_book_builds_and_renders():
    """Opt-in (RACING_LIB_BOOK=1): the documented build, its rendered-page check, screenshots."""
    if os.environ.get("RACING_LIB_BOOK", "") != "1":
        pytest.skip("set RACING_LIB_BOOK=1 to build the book here (CI builds it in its own step)")
    if shutil.which("jupyter-book") is None:
        pytest.fail('RACING_LIB_BOOK=1 but jupyter-book is missing: pip install -e ".[book]"')
    build = subprocess.run(["bash", str(BOOK / "build.sh")], capture_output=True, text=True)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    assert (BOOK / "_build" / "html" / "book" / "intro.html").exists()
    looked = subprocess.run(
        [sys.executable, str(BOOK / "check_rendered.py")], capture_output=True, text=True
    )
    assert looked.returncode == 0, looked.stdout + looked.stderr
    shots = subprocess.run(
        [sys.executable, str(BOOK / "screenshot.py")], capture_output=True, text=True
    )
    assert shots.returncode == 0, shots.stdout + shots.stderr
    chapters = list((REPO / "notebooks").glob("*.ipynb"))
    assert len(list((BOOK / "_build" / "screenshots").glob("*.png"))) >= len(chapters) + 1


def _check_rendered():
    spec = importlib.util.spec_from_file_location("check_rendered", BOOK / "check_rendered.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_CLEAN_PAGE = """<html><head><script>var x = "$$";</script></head><body>
<p>The lap time is</p>
<div class="math notranslate nohighlight">\\[T = \\int_0^L \\frac{ds}{\\dot s}\\]</div>
<p>Inline <span class="math notranslate nohighlight">\\(\\kappa\\)</span>
and code <code>|---|</code>.</p>
<div class="cell docutils container"><div class="cell_input docutils container"><pre>
print("$$ \\\\begin{x} <object at 0x1>")</pre></div>
<div class="cell_output docutils container"><pre>lap 105.743 s</pre></div></div>
<table><tr><td>a</td></tr></table></body></html>"""

_BROKEN_PAGE = """<html><body>
<p>The lap time is
$$ T = \\int ds $$</p>
<ul><li><p>\\lambda_k \\bigr) \\begin{cases} 1</p></li></ul>
<p>| row | lap |
|---|---|
| main | 105.7 |</p>
<div class="cell docutils container"><div class="cell_output docutils container">
<pre>&lt;matplotlib.legend.Legend at 0x7f3a2c1d&gt;</pre>
<pre>&lt;racing_lib.planning.PlanResult object at 0x7f00ff&gt;</pre></div></div>
</body></html>"""


def test_the_rendered_page_check_passes_a_clean_page_and_names_each_fault(tmp_path):
    check = _check_rendered()
    clean, broken = tmp_path / "clean.html", tmp_path / "broken.html"
    clean.write_text(_CLEAN_PAGE)
    broken.write_text(_BROKEN_PAGE)
    assert check.check_page(clean) == []
    problems = "\n".join(check.check_page(broken))
    for name in ("raw display math", "raw LaTeX environment", "Markdown table as text",
                 "matplotlib repr", "Python repr"):  # fmt: skip
        assert name in problems, (name, problems)
    assert check.main([str(broken)]) == 1 and check.main([str(clean)]) == 0


def test_the_rendered_page_check_counts_equations_against_the_source(tmp_path):
    import json

    check = _check_rendered()
    cells = [
        {"cell_type": "markdown", "metadata": {}, "source": ["Lap\n\n$$\nT\n$$\n\nand $$x$$\n"]},
        {"cell_type": "markdown", "metadata": {}, "source": ["```\n$$ not math $$\n```\n"]},
        {"cell_type": "code", "metadata": {}, "source": ["x = '$$'"], "outputs": []},
    ]
    source = tmp_path / "ch.ipynb"
    source.write_text(json.dumps({"cells": cells, "metadata": {}, "nbformat": 4,
                                  "nbformat_minor": 5}))  # fmt: skip
    assert check.source_display_math(source) == 2
    page = tmp_path / "ch.html"
    page.write_text('<p>Lap</p><div class="math">\\[T\\]</div><p>and</p>')
    (problem,) = check.check_page(page, source)
    assert "2 display equations" in problem and "1 rendered as math" in problem
    page.write_text('<div class="math">\\[T\\]</div><div class="math">\\[x\\]</div>')
    assert check.check_page(page, source) == []


#: A line Markdown reads as the start of a list item or a quote.
_BLOCK_START = re.compile(r"\s*(?:[-+*>]\s|\d+[.)]\s)")


def _markdown_cells(notebook: Path) -> list[str]:
    import json

    cells = json.loads(notebook.read_text(encoding="utf-8"))["cells"]
    return ["".join(c["source"]) for c in cells if c["cell_type"] == "markdown"]


@pytest.mark.parametrize(
    "notebook",
    sorted((REPO / "notebooks").glob("*.ipynb"))
    + sorted((REPO / "exercises").glob("*.ipynb"))
    + sorted((REPO / "exercises" / "solutions").glob("*.ipynb")),
    ids=lambda p: f"{p.parent.name}/{p.stem}",
)
def test_display_math_stands_in_its_own_block(notebook):
    # MyST reads a $$ glued to the line above as text inside the paragraph (and a "+" or ">" line
    # of the equation as a list or a quote): the equation reaches the page as raw LaTeX.
    for cell in _markdown_cells(notebook):
        lines = cell.split("\n")
        inside = False
        for k, line in enumerate(lines):
            if not line.strip().startswith("$$") and not (inside and line.strip().endswith("$$")):
                continue
            if not inside:
                above = lines[k - 1].strip() if k else ""
                assert above == "", (
                    f"{notebook.name}: $$ right after {above[:60]!r}: add a blank line"
                )
            closes = line.strip().count("$$") >= 2 if not inside else True
            inside = not closes
            if inside:
                # The block's next lines, up to its closing $$: none may start like a list item or
                # a quote, or Markdown ends the equation there.
                for following in lines[k + 1 :]:
                    assert not _BLOCK_START.match(following), (
                        f"{notebook.name}: a line of display math starts like a list item or a "
                        f"quote ({following.strip()[:40]!r}): move the sign to the line above"
                    )
                    if "$$" in following:
                        break
            if closes and k + 1 < len(lines):
                below = lines[k + 1].strip()
                assert below == "", (
                    f"{notebook.name}: text {below[:60]!r} right after $$: add a blank line"
                )
        assert not inside, f"{notebook.name}: a $$ block is not closed"


def test_the_rendered_page_check_catches_glued_display_math(tmp_path):
    # The fault this book had: the same Markdown rendered by MyST's own parser, with and without
    # the blank line before $$.
    markdown_it = pytest.importorskip("markdown_it")
    dollarmath = pytest.importorskip("mdit_py_plugins.dollarmath")
    import json

    check = _check_rendered()
    md = markdown_it.MarkdownIt("commonmark").use(dollarmath.dollarmath_plugin)
    for text, broken in (("The lap time is\n$$\nT = \\int ds\n$$\n", True),
                         ("The lap time is\n\n$$\nT = \\int ds\n$$\n", False)):  # fmt: skip
        source = tmp_path / "ch.ipynb"
        cell = {"cell_type": "markdown", "metadata": {}, "source": [text]}
        source.write_text(json.dumps({"cells": [cell], "metadata": {}, "nbformat": 4,
                                      "nbformat_minor": 5}))  # fmt: skip
        page = tmp_path / "ch.html"
        page.write_text(f"<html><body>{md.render(text)}</body></html>")
        assert bool(check.check_page(page, source)) == broken, md.render(text)


# --- launch buttons: Binder builds the course from binder/, and the book links to it once it is
# --- told where the repository lives.


def _book_script(name: str):
    """The module of ``book/<name>.py`` (the book's scripts are not a package)."""
    spec = importlib.util.spec_from_file_location(name, BOOK / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    # Registered first: a dataclass looks its module up while it is being defined.
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _launch_config():
    return _book_script("launch_config")


def test_binder_installs_the_course_as_the_readme_does():
    post_build = (REPO / "binder" / "postBuild").read_text()
    assert os.access(REPO / "binder" / "postBuild", os.X_OK)
    install = [line for line in post_build.splitlines() if line.startswith("pip install")]
    assert install and "-e" in install[0] and "book" in install[0] and "test" in install[0]
    runtime = (REPO / "binder" / "runtime.txt").read_text().strip()
    major, minor = (int(part) for part in runtime.removeprefix("python-").split("."))
    requires = re.search(
        r'requires-python = ">=(\d+)\.(\d+)"', (REPO / "pyproject.toml").read_text()
    )
    assert (major, minor) >= (int(requires[1]), int(requires[2]))


def test_launch_buttons_appear_only_with_a_repository(tmp_path, monkeypatch, capsys):
    launch = _launch_config()
    base = yaml.safe_load((BOOK / "_config.yml").read_text())
    assert not base["launch_buttons"]["binderhub_url"]  # the offline book has no buttons

    config = launch.launch_config(base, "https://github.com/someone/racing-lab/", branch="dev")
    assert config["repository"]["url"] == "https://github.com/someone/racing-lab"
    assert config["repository"]["branch"] == "dev"
    assert config["launch_buttons"]["binderhub_url"] == "https://mybinder.org"
    assert config["sphinx"] == base["sphinx"] and config["execute"] == base["execute"]
    assert not base["launch_buttons"]["binderhub_url"]  # the original is not changed
    with pytest.raises(ValueError, match="RACING_LAB_REPOSITORY must be a web address"):
        launch.launch_config(base, "someone/racing-lab")

    monkeypatch.delenv("RACING_LAB_REPOSITORY", raising=False)
    assert launch.main() == 0
    assert capsys.readouterr().out.strip() == str(BOOK / "_config.yml")

    target = tmp_path / "_config.launch.yml"
    monkeypatch.setattr(launch, "BOOK", tmp_path)
    (tmp_path / "_config.yml").write_text((BOOK / "_config.yml").read_text())
    monkeypatch.setenv("RACING_LAB_REPOSITORY", "https://github.com/someone/racing-lab")
    assert launch.main() == 0
    assert capsys.readouterr().out.strip() == str(target)
    written = yaml.safe_load(target.read_text())
    assert written["launch_buttons"]["binderhub_url"] == "https://mybinder.org"

    monkeypatch.setenv("RACING_LAB_REPOSITORY", "not a url")
    assert launch.main() == 2
    assert "must be a web address" in capsys.readouterr().err


@pytest.mark.skipif(shutil.which("jupyter-book") is None, reason="needs the [book] extras")
def test_a_book_built_with_a_repository_links_each_notebook_to_binder(tmp_path):
    """A one-chapter book with the written configuration: its notebook page gets the Binder link."""
    launch = _launch_config()
    base = yaml.safe_load((BOOK / "_config.yml").read_text())
    config = launch.launch_config(base, "https://github.com/someone/racing-lab")
    # Only what a one-page book without our static files and extensions can take.
    config["sphinx"].pop("local_extensions")
    for key in ("html_static_path", "html_css_files"):
        config["sphinx"]["config"].pop(key)
    config["execute"]["execute_notebooks"] = "off"
    (tmp_path / "_config.yml").write_text(yaml.safe_dump(config))
    (tmp_path / "_toc.yml").write_text("format: jb-book\nroot: intro\nchapters:\n- file: chapter\n")
    (tmp_path / "intro.md").write_text("# A book\n")
    shutil.copy(REPO / "notebooks" / "00_introduction.ipynb", tmp_path / "chapter.ipynb")
    done = subprocess.run(
        ["jupyter-book", "build", str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    page = (tmp_path / "_build" / "html" / "chapter.html").read_text()
    assert (
        "https://mybinder.org/v2/gh/someone/racing-lab/main?urlpath=lab/tree/chapter.ipynb" in page
    )


def test_the_parallel_run_executes_every_notebook_the_book_shows():
    listed = _book_script("execute").toc_notebooks()
    expected = sorted(REPO.glob("notebooks/*.ipynb")) + sorted(REPO.glob("exercises/0*.ipynb"))
    assert sorted(listed) == sorted(expected)
    assert not any("solutions" in str(nb) for nb in listed)


def test_the_build_finds_the_parallel_runs_outputs_and_reruns_a_failed_notebook(tmp_path):
    """What book/execute.py caches, myst-nb's cache mode matches; a failed run is not cached."""
    jupyter_cache = pytest.importorskip("jupyter_cache", reason="needs the [book] extras")
    nbformat = pytest.importorskip("nbformat")
    good, bad = tmp_path / "good.ipynb", tmp_path / "bad.ipynb"
    for path, code in ((good, "print(6 * 7)"), (bad, "raise ValueError('on purpose')")):
        nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(code)])
        nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3"}
        nbformat.write(nb, path)
    cache_path = tmp_path / "cache"
    (cache_path / "stale").mkdir(parents=True)  # an earlier build's cache: emptied first

    failed, reused = _book_script("execute").execute_all(
        [good, bad], cache_path, timeout=60, kept=tmp_path / "no-kept-runs"
    )

    assert failed == [bad] and reused == []
    assert not (cache_path / "stale").exists()
    cache = jupyter_cache.get_cache(str(cache_path))
    _, merged = cache.merge_match_into_notebook(nbformat.read(good, as_version=4))
    assert merged.cells[0].outputs[0]["text"].strip() == "42"
    with pytest.raises(KeyError):
        cache.match_cache_notebook(nbformat.read(bad, as_version=4))


def _one_cell_notebook(path: Path, code: str) -> Path:
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(code)])
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3"}
    nbformat.write(nb, path)
    return path


def _stream(text: str):
    nbformat = pytest.importorskip("nbformat")
    return nbformat.v4.new_output("stream", name="stdout", text=text)


def test_a_kept_run_is_fresh_until_its_code_changes_and_an_incomplete_run_is_not_kept(tmp_path):
    kept_runs = _book_script("kept_runs")
    nb = _one_cell_notebook(tmp_path / "one.ipynb", "print(6 * 7)")
    kept = tmp_path / "kept"

    written = kept_runs.keep(nb, {0: [_stream("42\n")]}, kept)

    assert written is not None and kept_runs.fresh_run(nb, kept) == written
    _one_cell_notebook(nb, "print(6 * 8)")  # the notebook edited after the tests ran
    assert kept_runs.fresh_run(nb, kept) is None
    kept_runs.keep(nb, {0: [_stream("48\n")]}, kept)
    assert kept_runs.fresh_run(nb, kept) is not None
    assert kept_runs.keep(nb, {}, kept) is None  # its cell failed this time: nothing kept ...
    assert kept_runs.fresh_run(nb, kept) is None  # ... and the older run is gone


def test_a_kept_run_drops_the_result_a_trailing_semicolon_silences(tmp_path):
    nbformat = pytest.importorskip("nbformat")
    kept_runs = _book_script("kept_runs")
    result = nbformat.v4.new_output(
        "execute_result", data={"text/plain": "<matplotlib.legend.Legend at 0x7f00>"}
    )
    quiet = _one_cell_notebook(tmp_path / "quiet.ipynb", "ax.legend();  # silenced")
    loud = _one_cell_notebook(tmp_path / "loud.ipynb", "ax.legend()")
    for nb in (quiet, loud):
        kept_runs.keep(nb, {0: [_stream("drawn\n"), result]}, tmp_path / "kept")
    outputs = {
        nb.name: nbformat.read(kept_runs.fresh_run(nb, tmp_path / "kept"), 4).cells[0].outputs
        for nb in (quiet, loud)
    }
    assert [o["output_type"] for o in outputs["quiet.ipynb"]] == ["stream"]
    assert [o["output_type"] for o in outputs["loud.ipynb"]] == ["stream", "execute_result"]


def test_the_book_takes_a_kept_run_instead_of_executing_the_notebook(tmp_path):
    jupyter_cache = pytest.importorskip("jupyter_cache", reason="needs the [book] extras")
    nbformat = pytest.importorskip("nbformat")
    # Executing this notebook would fail: a build that reports no failure did not execute it.
    nb = _one_cell_notebook(tmp_path / "kept.ipynb", "raise ValueError('executed after all')")
    kept = tmp_path / "kept"
    _book_script("kept_runs").keep(nb, {0: [_stream("as the tests ran it\n")]}, kept)

    failed, reused = _book_script("execute").execute_all([nb], tmp_path / "cache", 60, kept)

    assert (failed, reused) == ([], [nb])
    cache = jupyter_cache.get_cache(str(tmp_path / "cache"))
    _, merged = cache.merge_match_into_notebook(nbformat.read(nb, as_version=4))
    assert merged.cells[0].outputs[0]["text"] == "as the tests ran it\n"


# --- Every number in prose comes from a cell (book/prose_numbers.py) --------------------------


def _chapter(cells: list[tuple[str, str]], fixed: dict[str, str] | None = None):
    """A notebook of (kind, source) cells, with declared fixed numbers."""
    import nbformat

    nb = nbformat.v4.new_notebook()
    make = {"md": nbformat.v4.new_markdown_cell, "code": nbformat.v4.new_code_cell}
    nb.cells = [make[kind](source) for kind, source in cells]
    if fixed is not None:
        nb.metadata["racing_lab"] = {"fixed_numbers": fixed}
    return nb


def _check(tmp_path: Path, nb) -> list[str]:
    import nbformat

    path = tmp_path / "chapter.ipynb"
    nbformat.write(nb, path)
    return _book_script("prose_numbers").check_notebook(path)


def test_every_number_in_the_chapters_prose_is_bound_to_a_cell_or_declared_fixed():
    checker = _book_script("prose_numbers")
    assert checker.CHAPTERS, "no chapter notebooks found"
    problems = [p for path in checker.CHAPTERS for p in checker.check_notebook(path)]
    assert not problems, "\n".join(problems)


def test_the_prose_number_check_fails_on_an_unbound_number_in_a_real_chapter(tmp_path):
    import nbformat

    checker = _book_script("prose_numbers")
    nb = nbformat.read(checker.CHAPTERS[2], as_version=4)
    assert _check(tmp_path, nb) == []
    prose = next(c for c in nb.cells if c.cell_type == "markdown")
    prose.source += "\n\nThe plan's lap takes 104.16 s."
    problems = _check(tmp_path, nb)
    assert len(problems) == 1 and "'104.16 s'" in problems[0] and "lap takes" in problems[0]


def test_the_prose_number_check_accepts_bound_declared_and_structural_numbers(tmp_path):
    clean = _chapter(
        [
            ("code", 'bind("lap_s", 104.163, ".2f")'),
            (
                "md",
                "## 3. Margins\n\nThe lap takes {glue:text}`lap_s` s (Eq. 5, section 3.2, claim "
                "4.1, with 3 seeds), $v = 50$ m/s in math, `0.25` in code, the paper's 99.48 s, "
                "and [a link](https://example.org/2305.07740).",
            ),
        ],
        fixed={"99.48 s": "paper: the planned lap, Table I"},
    )
    assert _check(tmp_path, clean) == []


@pytest.mark.parametrize(
    ("cells", "fixed", "named"),
    [
        ([("md", "It brakes from 45 m/s.")], {}, "'45 m/s'"),
        ([("md", "It is 16 % low.")], {}, "'16 %'"),
        ([("md", "It took 371 iterations.")], {}, "'371'"),
        ([("md", "The error is 0.071.")], {}, "'0.071'"),
        ([("md", "The lap takes {glue:text}`lap_s` s.")], {}, "not bound by any code cell"),
        ([("md", "A 2.5 s horizon.")], {"2.5 s": "because"}, "start it with one of"),
        ([("md", "No numbers here.")], {"2.5 s": "setting: horizon"}, "no sentence uses it"),
    ],
)
def test_the_prose_number_check_names_each_fault(tmp_path, cells, fixed, named):
    problems = _check(tmp_path, _chapter(cells, fixed))
    assert len(problems) == 1 and named in problems[0], problems
