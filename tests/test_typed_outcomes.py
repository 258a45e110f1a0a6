"""No decision of the search reads a key of ``extra``: its outcomes are typed.

Issue 61, item 4: ``StageResult``, ``IterationRecord`` and the structure
``Candidate`` carry what the search decides by as attributes; ``extra`` and its keys
exist only where :class:`~tsid_fmu.search.record.Kept` writes and reads the JSON form
(``tsid_fmu/search/record.py``). A keyed access anywhere else in the search core fails.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

from tsid_fmu.search.outcome import SolverNotes
from tsid_fmu.search.stage import StageResult

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("numerics", "search", "uncertainty")
CODEC = "tsid_fmu/search/record.py"
METHODS = {"get", "pop", "setdefault", "update", "keys", "items", "values"}


def _is_extra(node: ast.AST) -> bool:
    return (isinstance(node, ast.Name) and node.id == "extra") or (
        isinstance(node, ast.Attribute) and node.attr == "extra"
    )


def _key(node: ast.AST) -> str:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else "?"


def keyed(source: str) -> list[tuple[int, str]]:
    """(line, key) where ``extra`` is indexed, has a dict method called, or is built
    with keys ("?" where the key is not a literal)."""
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Subscript) and _is_extra(node.value):
            found.add((node.lineno, _key(node.slice)))
        elif isinstance(node, ast.Attribute) and node.attr in METHODS and _is_extra(node.value):
            found.add((node.lineno, "?"))
        elif isinstance(node, ast.keyword) and node.arg == "extra":
            if isinstance(node.value, ast.Dict) and node.value.keys:
                found |= {(node.value.lineno, _key(k)) for k in node.value.keys}
    return sorted(found)


# The notes that remain, written once each for the report and the trail and read by no
# decision: the structure stage's factors and levels, the comparison's table, a
# candidate's summary. Any other key, or a read, fails.
REPORT_NOTES = {
    "tsid_fmu/search/structure/arrays.py": {"factors", "levels"},
    "tsid_fmu/search/structure/compare.py": {"structures", "structure", "stages"},
}


def test_the_search_core_reads_and_writes_no_key_of_extra():
    found = {}
    for package in PACKAGES:
        for path in sorted((REPO / "tsid_fmu" / package).rglob("*.py")):
            rel = path.relative_to(REPO).as_posix()
            allowed = REPORT_NOTES.get(rel, set())
            lines = [(n, k) for n, k in keyed(path.read_text(encoding="utf-8")) if k not in allowed]
            if rel != CODEC and lines:
                found[rel] = lines
    assert found == {}, found


def test_the_scanner_sees_a_keyed_access():
    assert keyed("stage.extra['start'] = 1\n") == [(1, "start")]
    assert keyed("x = s.extra.get('k')\n") == [(1, "?")]
    assert keyed("extra.update(a=1)\n") == [(1, "?")]
    assert keyed("StageResult(extra={'k': 1, 'j': 2})\n") == [(1, "j"), (1, "k")]
    assert keyed("StageResult(extra=dict(other.extra))\nn = s.extra\n") == []


def test_a_refinements_solver_notes_and_a_horizons_fraction_read_back_typed():
    stage = StageResult("r", "refinement", {"w": 1.0}, 2.0, 3, "done", fraction=0.25)
    stage.solver = SolverNotes("trf", 10, 2, {"stop": "ftol"}, None)
    written = stage.to_dict()["extra"]
    assert written["method"] == "trf" and written["njev"] == 2 and "off_the_floor" not in written
    back = StageResult.from_dict(json.loads(json.dumps(stage.to_dict())))
    assert back.solver == stage.solver and back.fraction == 0.25 and back.extra == {}
