"""A report that can be shared and read: no local paths, honest colours, legible axes."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import pytest

from tsid_fmu import IdentificationResult
from tsid_fmu.report.figures import convergence_figure
from tsid_fmu.report.html import html_report
from tsid_fmu.report.html_tables import table
from tsid_fmu.report.markdown import markdown_report
from tsid_fmu.report.svg import Panel, nice_ticks
from tsid_fmu.search.stage import StageResult
from tsid_fmu.study import Study

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "examples" / "lsea_siso" / "study.toml"


@pytest.fixture(scope="module")
def study() -> Study:
    return Study.from_toml(STUDY)


def _result(study: Study, status: int = 0, warnings: tuple[str, ...] = ()) -> IdentificationResult:
    x = {n: 1.0 for n in study.parameter_names}
    res = IdentificationResult(
        params=x, fun=2.5, nfev=40, success=status == 0, status=status, message="done", study=study
    )
    res.warnings = list(warnings)
    return res


def test_reports_name_the_fmu_by_file_name_and_digest_not_by_its_path(study):
    digest = hashlib.sha256(study.fmu.read_bytes()).hexdigest()[:12]
    res = _result(study)
    for text in (html_report(res, None), markdown_report(res)):
        assert f"LSEA_SISO.fmu (SHA-256 {digest})" in text
        assert str(study.fmu) not in text
        assert str(study.fmu.parent) not in text


def _headline(html: str) -> str:
    match = re.search(r'<p class="headline[^"]*"', html)
    assert match is not None
    return match.group(0)


def test_the_verdict_colour_follows_the_worst_finding(study):
    clean = _headline(html_report(_result(study), None))
    assert "verdict-good" in clean
    poor = html_report(_result(study, warnings=("the fit is poor",)), None)
    assert "verdict-caution" in _headline(poor) and "verdict-good" not in _headline(poor)
    assert "1 warning(s)" in poor
    assert "verdict-caution" in _headline(html_report(_result(study, status=1), None))
    worst = html_report(_result(study, status=1, warnings=("the fit is poor",)), None)
    assert "verdict-bad" in _headline(worst)
    assert ".verdict-bad" in worst and ".verdict-caution" in worst  # styled


def test_table_headers_are_aligned_with_their_column():
    html = table(
        ["stage", "kind", "cost"], [["taguchi", "taguchi", 1.5], ["ls", "refinement", 2.0]]
    )
    heads = re.findall(r"<th( class=\"text\")?>(\w+)</th>", html.split("<tbody>")[0])
    assert heads == [(' class="text"', "stage"), (' class="text"', "kind"), ("", "cost")]


def test_tick_labels_are_large_enough_to_read():
    panel = Panel(80, 20, 300, 120, (0.0, 10.0), (0.0, 1.0))
    panel.frame([0.0, 0.5, 1.0])
    panel.xticks([0.0, 5.0, 10.0], ["0", "5", "10"])
    sizes = [float(s) for s in re.findall(r'font-size="([\d.]+)"', "".join(panel.parts))]
    assert len(sizes) == 6 and min(sizes) >= 12
    stage = StageResult("taguchi", "refinement", {}, 3.0, 10, "done")
    fig = convergence_figure([stage])
    labels = fig.axes[0].get_xticklabels() + fig.axes[0].get_yticklabels()
    assert labels and min(t.get_fontsize() for t in labels) >= 8.5


def test_large_tick_values_are_written_short():
    # costs of 1e15 and more: integer ticks were written with every digit
    # ("5000000000000000"), wider than the figure's left margin
    ticks = nice_ticks(0.0, 1.6e16, 4)
    assert all(isinstance(t, float) for t in ticks)
    panel = Panel(80, 20, 300, 120, (0.0, 1.0), (0.0, 1.6e16))
    panel.frame(ticks)
    labels = re.findall(r">([^<]+)</text>", "".join(panel.parts))
    assert labels == ["0", "1e16"], labels
