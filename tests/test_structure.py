"""The house rules of the package: small modules, short functions, no import cycles.

* no module of ``tsid_fmu`` over 500 lines (vendored C headers are not Python);
* no function or method over 80 lines, counting every line of its definition, its
  signature and docstring included (issue 26 counted so: ``anova`` 119 lines);
* the projected Gauss-Newton stationarity test is made in one place
  (``tsid_fmu.search.verdict.gauss_newton_test``), which every refinement calls;
* no import cycle between the package's modules, counting every ``import`` statement
  wherever it stands (inside functions and ``TYPE_CHECKING`` blocks too), and treating
  ``import tsid_fmu.x`` / ``from tsid_fmu.x import y`` as an edge to ``tsid_fmu.x``
  (and to ``tsid_fmu.x.y`` where that is a module).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "tsid_fmu"
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _function_lengths(tree: ast.AST) -> list[tuple[str, int, int]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            span = node.end_lineno - first + 1
            found.append((node.name, node.lineno, span))
    return found


def _imports(name: str, tree: ast.AST) -> set[str]:
    package = name if MODULES[name].name == "__init__.py" else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join([*base, node.module] if node.module else base)
            else:
                mod = node.module or ""
            targets.add(mod)
            targets.update(f"{mod}.{a.name}" for a in node.names)
    edges = set()
    for t in targets:
        while t and t not in MODULES:
            t = t.rpartition(".")[0]
        if t and t != name:
            edges.add(t)
    return edges


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    result: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                result.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return result


@pytest.mark.parametrize("name", sorted(MODULES))
def test_module_is_small_and_its_functions_short(name):
    path = MODULES[name]
    text = path.read_text(encoding="utf-8")
    lines = text.count("\n") + (not text.endswith("\n"))
    assert lines <= MAX_MODULE_LINES, f"{path}: {lines} lines > {MAX_MODULE_LINES}"
    long = [
        f"{fn} (line {ln}): {n} lines"
        for fn, ln, n in _function_lengths(ast.parse(text))
        if n > MAX_FUNCTION_LINES
    ]
    assert not long, f"{path}: functions over {MAX_FUNCTION_LINES} lines: {long}"


def test_no_import_cycles():
    graph = {n: _imports(n, ast.parse(p.read_text(encoding="utf-8"))) for n, p in MODULES.items()}
    # a package imports its own submodules from __init__; that alone is no cycle unless
    # a submodule imports the package back (which the graph shows as a cycle)
    cycles = _cycles(graph)
    assert not cycles, f"import cycles: {cycles}"


def test_cycle_detector_sees_a_cycle_inside_a_function():
    a = ast.parse("def f():\n    from tsid_fmu.errors import TsidError\n")
    assert "tsid_fmu.errors" in _imports("tsid_fmu", a)
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == [["a", "b", "c"]]


def test_the_projected_gauss_newton_test_is_made_in_one_place():
    """Its trials (``trial_fractions``) live in verdict.py, its verdicts' names (``GN_TRIED``)
    in outcome.py, beside the typed verdict."""
    made = {
        name
        for name, path in MODULES.items()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.Call)
        and getattr(node.func, "id", getattr(node.func, "attr", None))
        in ("trial_fractions", "trial_reaches_gate", "trial_detail")
    }
    assert made == {"tsid_fmu.search.verdict"}
    said = {
        name
        for name, path in MODULES.items()
        if '"projected Gauss-Newton, step tried"' in path.read_text(encoding="utf-8")
    }
    assert said == {"tsid_fmu.search.outcome"}
