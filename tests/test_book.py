"""The book: its table of contents points at files that exist, the API page covers every module,
the reference list matches the paper's citations, and (opt-in, as CI does) it builds without a
warning and its pages render in headless Chromium.

The full build executes every notebook, so it is not part of a plain ``pytest`` run: CI runs
``book/build.sh`` and ``book/screenshot.py`` as their own step. Set ``RACING_LIB_BOOK=1`` to run
that build here too (it needs ``pip install -e ".[book]"`` and Chromium).
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
    assert os.access(BOOK / "build.sh", os.X_OK), "book/build.sh must be executable"


@pytest.mark.slow
def test_book_builds_and_renders():
    """Opt-in (RACING_LIB_BOOK=1): the documented build, then screenshots of two pages."""
    if os.environ.get("RACING_LIB_BOOK", "") != "1":
        pytest.skip("set RACING_LIB_BOOK=1 to build the book here (CI builds it in its own step)")
    if shutil.which("jupyter-book") is None:
        pytest.fail('RACING_LIB_BOOK=1 but jupyter-book is missing: pip install -e ".[book]"')
    build = subprocess.run(["bash", str(BOOK / "build.sh")], capture_output=True, text=True)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    assert (BOOK / "_build" / "html" / "book" / "intro.html").exists()
    shots = subprocess.run(
        [sys.executable, str(BOOK / "screenshot.py")], capture_output=True, text=True
    )
    assert shots.returncode == 0, shots.stdout + shots.stderr
    assert len(list((BOOK / "_build" / "screenshots").glob("*.png"))) >= 2
