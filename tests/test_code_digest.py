"""The ablation cache keys follow the code a computation imports, read from its imports."""

from __future__ import annotations

from pathlib import Path

from racing_lib.provenance import code_digest, imported_modules


def _package(root: Path, files: dict[str, str]) -> Path:
    pkg = root / "pkg"
    for name, text in files.items():
        path = pkg / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return pkg


FILES = {
    "__init__.py": '"""The package."""\n',
    "low.py": '"""Low."""\n\ndef f(x):\n    """Twice x."""\n    return 2 * x\n',
    "mid/__init__.py": "from pkg.mid import side\n",  # re-exports a sibling
    # A lazy (function-level) import counts too.
    "mid/core.py": "def g(x):\n    from pkg.low import f\n    return f(x)\n",
    "mid/side.py": "SIDE = 1\n",
    "unrelated.py": "U = 0\n",
}


def test_the_modules_of_a_computation_are_read_from_its_imports(tmp_path):
    pkg = _package(tmp_path, FILES)
    got = imported_modules(["pkg.mid.core"], root=pkg)
    # The lazy import is followed; the parents' __init__ run, but what they re-export does not.
    assert got == ["pkg", "pkg.low", "pkg.mid", "pkg.mid.core"]


def test_the_digest_moves_with_the_code_and_not_with_its_documentation(tmp_path):
    pkg = _package(tmp_path, FILES)
    before = code_digest(["pkg.mid.core"], root=pkg)
    low = pkg / "low.py"
    low.write_text(low.read_text().replace('"""Twice x."""', '"""Two times x, reworded."""'))
    low.write_text(low.read_text() + "# a comment\n")
    assert code_digest(["pkg.mid.core"], root=pkg) == before
    (pkg / "unrelated.py").write_text("U = 1\n")
    (pkg / "mid" / "side.py").write_text("SIDE = 2\n")
    assert code_digest(["pkg.mid.core"], root=pkg) == before
    low.write_text(low.read_text().replace("2 * x", "x + x"))
    assert code_digest(["pkg.mid.core"], root=pkg) != before


def test_the_laps_of_the_tables_depend_on_the_car_and_not_on_the_tables_text():
    lap = imported_modules(["racing_lib.experiments.ablation.runner"])
    for needed in ("racing_lib.sim", "racing_lib.vehicle.forces", "racing_lib.control.mpc.coupled",
                   "racing_lib.experiments.configs", "racing_lib.model.equations"):  # fmt: skip
        assert needed in lap
    assert "racing_lib.experiments.ablation.table" not in lap
    assert not any(m.startswith("racing_lib.face") for m in lap)
