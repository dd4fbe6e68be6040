"""The library's docstring examples: run by a plain ``pytest``, and skipped only with a reason.

pyproject.toml puts ``racing_lib`` in ``testpaths`` and ``--doctest-modules`` in ``addopts``, so
the suite runs every ``>>>`` example (one test per docstring). An example too slow for the suite
(minutes) may carry ``# doctest: +SKIP``, and the prose line just above it (or above the run of
skipped examples it belongs to) must say why, with the word "skip" in it, as in
"Two rows, two trials each, on two worker processes (minutes, so skipped by the tests):".
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil
import re
import subprocess
import sys
import tomllib
from functools import cache
from pathlib import Path

import racing_lib

REPO = Path(__file__).resolve().parents[1]
REASON = re.compile(r"\bskip", re.IGNORECASE)
# Most examples run: at most this share of them is skipped.
MAX_SKIPPED_SHARE = 0.1


@cache
def _docstrings() -> tuple[doctest.DocTest, ...]:
    """Every docstring of racing_lib that holds an example, as doctest (and pytest) find them."""
    finder = doctest.DocTestFinder()
    found = []
    for info in pkgutil.walk_packages(racing_lib.__path__, "racing_lib."):
        if info.name.rsplit(".", 1)[-1] == "__main__":
            continue  # a command: importing it runs it (pytest does not collect it either)
        module = importlib.import_module(info.name)
        found += [t for t in finder.find(module) if t.examples]
    return tuple(found)


def _examples() -> list[tuple[doctest.DocTest, doctest.Example]]:
    return [(t, ex) for t in _docstrings() for ex in t.examples]


def _skipped(ex: doctest.Example) -> bool:
    return bool(ex.options.get(doctest.SKIP, False))


def _lines(ex: doctest.Example) -> range:
    """The docstring lines of an example: its source and its expected output."""
    return range(ex.lineno, ex.lineno + ex.source.count("\n") + ex.want.count("\n"))


def _missing_reason(test: doctest.DocTest, ex: doctest.Example) -> str | None:
    """None when the prose line above a skipped example (or above its run) says why."""
    lines = (test.docstring or "").splitlines()
    in_example = {i for other in test.examples for i in _lines(other)}
    in_skipped = {i for other in test.examples if _skipped(other) for i in _lines(other)}
    i = ex.lineno - 1
    while i >= 0 and (not lines[i].strip() or i in in_skipped):
        i -= 1
    where = f"{test.name} (line {test.lineno + ex.lineno + 1} of {test.filename})"
    if i < 0 or i in in_example:
        return f"{where}: {ex.source.strip()!r} is skipped, with no prose line above it saying why"
    if not REASON.search(lines[i]):
        return f"{where}: the line above the skipped {ex.source.strip()!r} does not say why"
    return None


def test_examples_exist_and_most_of_them_run():
    examples = _examples()
    skipped = [ex for _, ex in examples if _skipped(ex)]
    counts = f"{len(examples)} examples, {len(examples) - len(skipped)} run, {len(skipped)} skipped"
    print(counts)
    assert len(examples) - len(skipped) > 0, counts
    assert len(skipped) <= MAX_SKIPPED_SHARE * len(examples), counts


def test_every_skipped_example_says_why():
    problems = [_missing_reason(t, ex) for t, ex in _examples() if _skipped(ex)]
    problems = [p for p in problems if p]
    assert not problems, "\n".join(problems)


def test_the_reason_check_catches_a_bare_skip():
    text = """Intro.

    >>> x = 1  # doctest: +SKIP

    Slow (minutes, so skipped by the tests):

    >>> y = 2  # doctest: +SKIP
    >>> y  # doctest: +SKIP
    2
    >>> z = 3
    >>> z  # doctest: +SKIP
    3
    """
    test = doctest.DocTestParser().get_doctest(text, {}, "t", "t.py", 0)
    missing = [_missing_reason(test, ex) for ex in test.examples if _skipped(ex)]
    assert [m is not None for m in missing] == [True, False, False, True]


def test_the_default_configuration_collects_the_doctests():
    ini = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert "racing_lib" in ini["testpaths"]
    assert "--doctest-modules" in ini["addopts"].split()
    # Collected by the configuration alone (no --doctest-modules here), one item per docstring.
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-n", "0"]
        + ["-p", "no:cacheprovider", "racing_lib"],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    collected = {line.split("::")[1] for line in proc.stdout.splitlines() if "::" in line}
    assert collected == {t.name for t in _docstrings()}, proc.stdout
