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


# Where the JSON form is written and read: the trail, the stages' codec, and load()'s
# reading of result.json (IdentificationResult.to_dict writes its "extra" as a literal).
BOUNDARY = ("tsid_fmu/trail/", CODEC, "tsid_fmu/load.py")


def test_no_view_or_command_reads_a_key_of_a_results_extra():
    """Issue 61, item 4: the result's structure, fidelity, conformance, comparison,
    on_bound and rounds are attributes; the reports, the design, the CLI and the
    result itself read them by name, never as ``result.extra[...]``."""
    found = {}
    for path in sorted((REPO / "tsid_fmu").rglob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        if rel.startswith(BOUNDARY):
            continue
        allowed = REPORT_NOTES.get(rel, set())
        lines = [(n, k) for n, k in keyed(path.read_text(encoding="utf-8")) if k not in allowed]
        if lines:
            found[rel] = lines
    assert found == {}, found


def test_a_results_kept_attributes_go_through_result_json_and_back(tmp_path):
    """The attributes kept under result.json's "extra" come back from load() by name."""
    from tsid_fmu.result import EXTRA_KEYS, IdentificationResult

    res = IdentificationResult({"k": 1.0}, 2.0, 3, True, 0, "converged")
    res.structure = {"chosen": "law=1", "values": {}}
    res.fidelity = {"interface": "cs", "checked": False}
    res.conformance = {"fresh": False, "deterministic": True}
    res.comparison = {"grouped": 1.0}
    written = json.loads(json.dumps(res.to_dict()))
    assert set(written["extra"]) == set(EXTRA_KEYS) and written["comparison"] == {"grouped": 1.0}
    assert written["extra"]["structure"]["chosen"] == "law=1"
    bare = IdentificationResult({"k": 1.0}, 2.0, 3, True, 0, "converged").to_dict()
    assert bare["extra"] == {} and bare["comparison"] is None


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


def _spelled_kinds(source: str) -> list[tuple[int, str]]:
    """(line, kind) where a stage kind is spelled as a string: ``kind == "taguchi"``,
    ``kind="check"``, ``kind in ("phase", ...)``."""
    from tsid_fmu.search.stage import KINDS

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and isinstance(node.left, ast.Attribute):
            if node.left.attr != "kind":
                continue
            for right in node.comparators:
                items = right.elts if isinstance(right, ast.Tuple | ast.List | ast.Set) else [right]
                found += [(node.lineno, _key(e)) for e in items if _key(e) in KINDS]
        elif isinstance(node, ast.keyword) and node.arg == "kind" and _key(node.value) in KINDS:
            found.append((node.lineno, _key(node.value)))
    return sorted(found)


def test_no_decision_spells_a_stage_kind_as_a_string():
    """Issue 61, item 4: a stage's kind is a :class:`StageKind`; the package compares
    with its members, never with a string it spells itself (a typo would be silent)."""
    found = {}
    for path in sorted((REPO / "tsid_fmu").rglob("*.py")):
        lines = _spelled_kinds(path.read_text(encoding="utf-8"))
        if lines:
            found[path.relative_to(REPO).as_posix()] = lines
    assert found == {}, found
    assert _spelled_kinds('if s.kind == "taguchi": pass\n') == [(1, "taguchi")]
    assert _spelled_kinds('StageResult(kind="check")\nok = s.kind in ("phase", 1)\n') == [
        (1, "check"),
        (2, "phase"),
    ]


def test_a_stage_kind_is_a_member_and_reads_back_as_one():
    import pytest

    from tsid_fmu.search.stage import StageKind

    stage = StageResult("r", "refinement", {"w": 1.0}, 2.0, 3, "done")
    assert stage.kind is StageKind.REFINEMENT and stage.kind == "refinement"
    written = json.loads(json.dumps(stage.to_dict()))
    assert written["kind"] == "refinement"
    assert StageResult.from_dict(written).kind is StageKind.REFINEMENT
    with pytest.raises(ValueError, match="refinment"):
        StageResult("r", "refinment", {"w": 1.0}, 2.0, 3, "done")
