"""Code-health counts of racing_lib, read from its syntax trees (nothing is imported).

Usage: ``python tools/code_counts.py [--list] [--json] [--root PATH]``

* ``Any`` in public signatures: parameters and return annotations of public functions and methods
  (no leading underscore in the name, nor in the module's or class's) whose annotation mentions
  ``Any`` anywhere (``Any | None``, ``dict[str, Any]``: once per parameter; not through a type
  alias), against the number of public parameters (``self`` and ``cls`` left out) and return
  annotations. Dunder methods (``__init__``) have a leading underscore and are not counted;
* long functions: body over 80 and over 100 lines (the docstring left out, as in
  ``tests/test_layers.py``), longest first, marked where a ``# long function:`` comment says why;
* the ten largest modules by line count;
* imports of the package's own modules inside function bodies (``racing_lib...`` or relative), and
  how many of them a comment on the same or the previous line explains (linter directives such as
  ``# noqa`` are no reason; a comment above a group of imports explains only the first);
* docstring examples (``>>>`` lines) and how many of them are marked ``+SKIP``.

``--list`` prints every ``Any`` (``module:function:param``) and every function-level import
(``path:line``); ``--json`` prints everything, lists included, as one JSON object.
"""

from __future__ import annotations

import argparse
import ast
import io
import json
import re
import tokenize
from dataclasses import asdict, dataclass, field
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "racing_lib"
LONG, VERY_LONG = 80, 100
LONG_FUNCTION_MARK = "# long function:"
#: Comments that silence a tool instead of giving a reason.
DIRECTIVE = re.compile(r"#\s*(noqa|type:|fmt:|pragma|pylint|ruff)", re.IGNORECASE)
Function = ast.FunctionDef | ast.AsyncFunctionDef


@dataclass
class Counts:
    """Everything the script reports (see the module docstring)."""

    modules: int = 0
    any_in_public_signatures: int = 0
    public_parameters: int = 0
    public_returns: int = 0
    any_locations: list[str] = field(default_factory=list)
    functions_over_80: list[dict] = field(default_factory=list)
    functions_over_100: int = 0
    largest_modules: list[dict] = field(default_factory=list)
    function_level_imports: int = 0
    function_level_imports_with_reason: int = 0
    import_locations: list[str] = field(default_factory=list)
    doctest_examples: int = 0
    doctest_examples_skipped: int = 0


def module_name(path: Path, root: Path) -> str:
    parts = [root.name, *path.relative_to(root).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def mentions_any(annotation: ast.expr | None) -> bool:
    """``Any`` (or ``typing.Any``) anywhere in an annotation, quoted ones included."""
    for node in ast.walk(annotation) if annotation is not None else ():
        if isinstance(node, ast.Name) and node.id == "Any":
            return True
        if isinstance(node, ast.Attribute) and node.attr == "Any":
            return True
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            try:
                if mentions_any(ast.parse(node.value, mode="eval").body):
                    return True
            except SyntaxError:
                pass
    return False


def public_functions(tree: ast.Module):
    """(qualified name, node) of the module's public functions and its public classes' methods."""
    todo: list[tuple[str, ast.AST]] = [("", tree)]
    while todo:
        prefix, scope = todo.pop()
        for node in scope.body:
            if isinstance(node, Function) and not node.name.startswith("_"):
                yield prefix + node.name, node
            elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                todo.append((f"{prefix}{node.name}.", node))


def count_signatures(counts: Counts, name: str, tree: ast.Module) -> None:
    for qualname, fn in public_functions(tree):
        a = fn.args
        params = [*a.posonlyargs, *a.args, *a.kwonlyargs, a.vararg, a.kwarg]
        for p in params:
            if p is None or p.arg in ("self", "cls"):
                continue
            counts.public_parameters += 1
            if mentions_any(p.annotation):
                counts.any_locations.append(f"{name}:{qualname}:{p.arg}")
        if fn.returns is not None:
            counts.public_returns += 1
            if mentions_any(fn.returns):
                counts.any_locations.append(f"{name}:{qualname}:return")


def body_length(fn: Function) -> int:
    body = fn.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        body = body[1:]
    start = body[0].lineno if body else fn.end_lineno
    return fn.end_lineno - start + 1


def comments_by_line(source: str) -> dict[int, str]:
    tokens = tokenize.generate_tokens(io.StringIO(source).readline)
    return {t.start[0]: t.string for t in tokens if t.type == tokenize.COMMENT}


def is_own_import(node: ast.AST, package: str) -> bool:
    if isinstance(node, ast.ImportFrom):
        return node.level > 0 or (node.module or "").split(".")[0] == package
    if isinstance(node, ast.Import):
        return any(alias.name.split(".")[0] == package for alias in node.names)
    return False


def count_functions(counts: Counts, rel: str, tree: ast.Module, source: str, package: str) -> None:
    lines, comments = source.splitlines(), comments_by_line(source)
    seen: set[ast.AST] = set()  # an import in a nested function is counted once
    for fn in ast.walk(tree):
        if not isinstance(fn, Function):
            continue
        length = body_length(fn)
        if length > LONG:
            first = min([fn.lineno, *(d.lineno for d in fn.decorator_list)])
            k = first - 2  # the comment block just above the def (or its decorators)
            while (
                k >= 0 and lines[k].strip().startswith("#") and LONG_FUNCTION_MARK not in lines[k]
            ):
                k -= 1
            says_why = k >= 0 and lines[k].strip().startswith(LONG_FUNCTION_MARK)
            where = f"{rel}:{fn.lineno} {fn.name}"
            counts.functions_over_80.append({"function": where, "lines": length, "why": says_why})
        for node in ast.walk(fn):
            if not is_own_import(node, package) or node in seen:
                continue
            seen.add(node)
            counts.function_level_imports += 1
            counts.import_locations.append(f"{rel}:{node.lineno}")
            near = [comments.get(k, "") for k in range(node.lineno - 1, node.end_lineno + 1)]
            if any(c and not DIRECTIVE.match(c) for c in near):
                counts.function_level_imports_with_reason += 1


def count_doctests(counts: Counts, tree: ast.Module) -> None:
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | Function):
            doc = ast.get_docstring(node, clean=False) or ""
            examples = [ln for ln in doc.splitlines() if ln.lstrip().startswith(">>>")]
            counts.doctest_examples += len(examples)
            counts.doctest_examples_skipped += sum("+SKIP" in ln for ln in examples)


def measure(root: Path = PACKAGE) -> Counts:
    counts, sizes = Counts(), {}
    for path in sorted(root.rglob("*.py")):
        rel = str(path.relative_to(root.parent))
        source = path.read_text(encoding="utf-8")
        tree = ast.parse(source)
        name = module_name(path, root)
        counts.modules += 1
        sizes[rel] = len(source.splitlines())
        if not any(part.startswith("_") for part in name.split(".")):
            count_signatures(counts, name, tree)
        count_functions(counts, rel, tree, source, root.name)
        count_doctests(counts, tree)
    counts.any_in_public_signatures = len(counts.any_locations)
    counts.import_locations.sort(key=lambda loc: (loc.split(":")[0], int(loc.split(":")[1])))
    counts.functions_over_80.sort(key=lambda f: -f["lines"])
    counts.functions_over_100 = sum(f["lines"] > VERY_LONG for f in counts.functions_over_80)
    largest = sorted(sizes.items(), key=lambda kv: -kv[1])[:10]
    counts.largest_modules = [{"module": m, "lines": n} for m, n in largest]
    return counts


def report(c: Counts, listing: bool) -> str:
    out = [
        f"modules: {c.modules}",
        f"Any in public signatures: {c.any_in_public_signatures} "
        f"(of {c.public_parameters} public parameters and {c.public_returns} return annotations)",
    ]
    out += [f"  {loc}" for loc in c.any_locations] if listing else []
    over_80 = len(c.functions_over_80)
    out.append(f"functions over {LONG} lines: {over_80}, over {VERY_LONG}: {c.functions_over_100}")
    for f in c.functions_over_80:
        out.append(f"  {f['lines']:4d}  {f['function']}{'  (says why)' if f['why'] else ''}")
    out.append("largest modules:")
    out += [f"  {m['lines']:4d}  {m['module']}" for m in c.largest_modules]
    out.append(
        f"imports of the package inside functions: {c.function_level_imports} "
        f"({c.function_level_imports_with_reason} with a comment giving a reason)"
    )
    out += [f"  {loc}" for loc in c.import_locations] if listing else []
    out.append(
        f"docstring examples (>>>): {c.doctest_examples} ({c.doctest_examples_skipped} +SKIP)"
    )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="list every Any and every import")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--root", type=Path, default=PACKAGE, help="the package's folder")
    args = parser.parse_args(argv)
    counts = measure(args.root.resolve())
    print(json.dumps(asdict(counts), indent=1) if args.json else report(counts, args.list))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
