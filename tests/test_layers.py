"""The layers of docs/explanation/architecture.md point one way (issue 26): the result sits below
the reports, which read it; the result reaches its notebook view and figures through
what the reports register, never by importing them."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest
from test_structure import MODULES, _imports

import tsid_fmu
from tsid_fmu.result import _VIEWS

REPO = Path(__file__).resolve().parents[1]


def _reaches(start: str) -> set[str]:
    graph = {n: _imports(n, ast.parse(p.read_text(encoding="utf-8"))) for n, p in MODULES.items()}
    seen, todo = set(), [start]
    while todo:
        for nxt in graph[todo.pop()] - seen:
            seen.add(nxt)
            todo.append(nxt)
    return seen


def test_the_result_module_does_not_import_the_reports():
    reached = _reaches("tsid_fmu.result")
    assert not {m for m in reached if m.startswith("tsid_fmu.report")}
    assert "tsid_fmu.identify" not in reached and "tsid_fmu.cli" not in reached


def test_the_reports_register_the_views_of_a_result():
    assert tsid_fmu.IdentificationResult is not None
    assert set(_VIEWS) == {
        "result_html",
        "plot_fit",
        "plot_convergence",
        "plot_main_effects",
        "plot_parameters",
        "fit_report",
        "text_report",
    }


@pytest.mark.slow
def test_importing_the_result_alone_registers_the_views():
    code = (
        "from tsid_fmu.result import IdentificationResult as R\n"
        "r = R(params={'a': 1.0}, fun=0.5, nfev=3, success=True, status=0, message='ok')\n"
        "assert 'a' in r._repr_html_()\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_every_module_of_search_is_on_the_architecture_pages_map():
    """docs/explanation/architecture.md names every module of ``search/`` with what it
    decides; a module added without a line there fails here."""
    page = (REPO / "docs" / "explanation" / "architecture.md").read_text(encoding="utf-8")
    section = page.split("## The modules of `search/`", 1)[1]
    listed = {line.split()[0] for line in section.splitlines() if line.startswith("  ")}
    search = REPO / "tsid_fmu" / "search"
    modules = {
        p.relative_to(search).as_posix()
        for n, p in MODULES.items()
        if n.startswith("tsid_fmu.search.") and p.name != "__init__.py"
    }
    assert modules and modules - listed == set()


def test_search_and_uncertainty_share_numerics_only_through_the_neutral_module():
    """search/ and uncertainty/ imported each other (issue 61): local/columns.py took
    UNSEEN from uncertainty/intervals.py, and uncertainty/ took Space from search/space.py
    and the noise cache from local/fdstep.py. Both now import tsid_fmu.numerics."""
    graph = {n: _imports(n, ast.parse(p.read_text(encoding="utf-8"))) for n, p in MODULES.items()}
    crossing = sorted(
        (a, b)
        for a, imported in graph.items()
        for b in imported
        if (a.startswith("tsid_fmu.search.") and b.startswith("tsid_fmu.uncertainty"))
        or (a.startswith("tsid_fmu.uncertainty.") and b.startswith("tsid_fmu.search"))
    )
    assert crossing == []
    numerics = {n for n in MODULES if n.startswith("tsid_fmu.numerics")}
    assert numerics and all(
        not b.startswith(("tsid_fmu.search", "tsid_fmu.uncertainty"))
        for n in numerics
        for b in graph[n]
    )
