"""tools/code_counts.py: code-health counts of racing_lib, on the repo and a made-up package."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "tools" / "code_counts.py"

_INIT = '''"""A made-up package.

>>> 1 + 1
2
>>> slow()  # doctest: +SKIP
"""

from typing import Any


def public(a: Any, b: int, c: dict[str, Any] | None = None, *args: "Any", **kw) -> Any:
    # lazy: the two modules import each other
    from pkg import _private
    from . import other  # noqa: PLC0415
    import json

    return json, _private, other


def _hidden(x: Any) -> Any:
    return x


class Thing:
    def method(self, x: Any) -> int:
        return 0

    def _private_method(self, y: Any) -> Any:
        return y

    def __init__(self, z: Any) -> None:
        self.z = z


class _Hidden:
    def method(self, x: Any) -> Any:
        return x
'''


def _function(name: str, lines: int) -> str:
    body = "".join("    x = 1\n" for _ in range(lines - 1))
    return f'def {name}():\n    """A docstring, not counted."""\n{body}    return x\n'


def _run(*args: str) -> subprocess.CompletedProcess:
    run = subprocess.run(
        [sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    return run


def test_the_counts_of_a_made_up_package(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(_INIT)
    (pkg / "_private.py").write_text("from typing import Any\n\n\ndef f(x: Any) -> Any:\n    ...\n")
    long = "# long function: a test needs one\n" + _function("long", 101)
    (pkg / "other.py").write_text(long + "\n\n" + _function("medium", 81))
    counts = json.loads(_run("--json", "--root", str(pkg)).stdout)
    assert counts["any_locations"] == [
        "pkg:public:a",
        "pkg:public:c",
        "pkg:public:args",
        "pkg:public:return",
        "pkg:Thing.method:x",
    ]
    assert counts["public_parameters"] == 5 + 1 + 0 + 0  # public, Thing.method, other's two
    assert counts["public_returns"] == 2
    assert counts["import_locations"] == ["pkg/__init__.py:13", "pkg/__init__.py:14"]
    assert counts["function_level_imports_with_reason"] == 1  # a noqa is no reason
    assert [(f["lines"], f["why"]) for f in counts["functions_over_80"]] == [
        (101, True),
        (81, False),
    ]
    assert counts["functions_over_100"] == 1
    assert counts["doctest_examples"] == 2 and counts["doctest_examples_skipped"] == 1
    assert [m["module"] for m in counts["largest_modules"]] == [
        "pkg/other.py",
        "pkg/__init__.py",
        "pkg/_private.py",
    ]


def test_the_counts_of_racing_lib_are_sane():
    counts = json.loads(_run("--json").stdout)
    assert counts["modules"] > 50
    assert 0 < counts["any_in_public_signatures"] == len(counts["any_locations"])
    assert (
        counts["any_in_public_signatures"] <= counts["public_parameters"] + counts["public_returns"]
    )
    assert all(loc.startswith("racing_lib") for loc in counts["any_locations"])
    assert counts["functions_over_100"] <= len(counts["functions_over_80"])
    lengths = [m["lines"] for m in counts["largest_modules"]]
    assert len(lengths) == 10 and lengths == sorted(lengths, reverse=True) and lengths[-1] > 0
    imports = counts["function_level_imports"]
    assert 0 < imports == len(counts["import_locations"])
    assert counts["function_level_imports_with_reason"] <= imports
    assert 0 < counts["doctest_examples_skipped"] <= counts["doctest_examples"]


def test_the_plain_report_lists_on_request():
    short, full = _run().stdout, _run("--list").stdout
    counts = json.loads(_run("--json").stdout)
    assert "Any in public signatures:" in short and "largest modules:" in short
    for listed in (counts["any_locations"][0], counts["import_locations"][0]):
        assert listed not in short and f"  {listed}\n" in full
