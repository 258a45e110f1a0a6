"""The tuned constants live in one module, and the reference page lists them all.

Issue 61, item 5: every module-level number that numerics/, search/ and uncertainty/
decide by is defined in ``tsid_fmu/numerics/tuning.py``; ``docs/reference/tuning.md``
is what ``python -m tsid_fmu.numerics.tuning_page`` prints.
"""

from __future__ import annotations

import ast
from pathlib import Path

from tsid_fmu.numerics import tuning
from tsid_fmu.numerics.tuning_page import page

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("numerics", "search", "uncertainty")


def _numbers(tree: ast.Module) -> list[str]:
    """Module-level names bound to a number, or to arithmetic of numbers and names."""
    found = []
    for node in tree.body:
        if not isinstance(node, ast.Assign | ast.AnnAssign) or node.value is None:
            continue
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        value = node.value
        leaves = [n for n in ast.walk(value) if not isinstance(n, ast.operator | ast.unaryop)]
        plain = all(
            isinstance(n, ast.BinOp | ast.UnaryOp | ast.Name | ast.Load)
            or (isinstance(n, ast.Constant) and type(n.value) in (int, float))
            for n in leaves
        )
        if plain and any(isinstance(n, ast.Constant) for n in leaves):
            found += [t.id for t in targets if isinstance(t, ast.Name)]
    return found


def test_no_module_of_the_core_defines_a_number_of_its_own():
    own = {}
    for package in PACKAGES:
        for path in sorted((REPO / "tsid_fmu" / package).rglob("*.py")):
            if path.name == "tuning.py":
                continue
            names = _numbers(ast.parse(path.read_text(encoding="utf-8")))
            if names:
                own[path.relative_to(REPO).as_posix()] = names
    assert own == {}


def test_the_scanner_sees_a_number_where_one_is_defined():
    """The rule above fails where it should: a constant, arithmetic of one, not a name."""
    tree = ast.parse("A = 1e-4\nB: float = 2 * A\nC = -3\nD = A\nE = 'x'\nF = True\n")
    assert _numbers(tree) == ["A", "B", "C"]
    assert len(_numbers(ast.parse((REPO / "tsid_fmu/numerics/tuning.py").read_text()))) >= 80


def test_every_constant_has_a_text_and_the_page_is_current():
    source = Path(tuning.__file__).read_text(encoding="utf-8")
    body = ast.parse(source).body
    for k, node in enumerate(body):
        if isinstance(node, ast.Assign):
            following = body[k + 1] if k + 1 < len(body) else None
            assert isinstance(following, ast.Expr) and isinstance(following.value.value, str), (
                ast.unparse(node)
            )
    written = (REPO / "docs" / "reference" / "tuning.md").read_text(encoding="utf-8")
    assert written == page(), (
        "run: python -m tsid_fmu.numerics.tuning_page > docs/reference/tuning.md"
    )
