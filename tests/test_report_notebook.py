"""Notebook display and plot helpers of a result, and the report's number formatting."""

from __future__ import annotations

from html.parser import HTMLParser

import matplotlib
import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, lag_response, lag_study

from tsid_fmu import Experiment, Parameter, Study, identify
from tsid_fmu.errors import StudyError
from tsid_fmu.report.style import fmt, fmt_levels
from tsid_fmu.report.svg import nice_ticks


class _Rows(HTMLParser):
    """Collect the cells of every table row."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: list[list[str]] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "tr":
            self.rows.append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.rows[-1].append("".join(self._cell).strip())
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    d = tmp_path_factory.mktemp("lag")
    study = lag_study(d)
    return identify(study, d / "out", plots=True)


def test_repr_html_holds_every_parameter_with_its_interval_and_the_stages(result):
    html = result._repr_html_()
    parser = _Rows()
    parser.feed(html)
    header = parser.rows[0]
    assert header[:4] == ["parameter", "value", "unit", "95 % interval"]
    rows = {r[0]: r for r in parser.rows[1:] if r and r[0] in result.params}
    assert set(rows) == set(result.params) == {"tau", "x0"}
    assert rows["tau"][2] == "s"
    assert rows["tau"][1] == fmt(result.params["tau"])
    low, high = result.intervals["tau"]
    assert low < result.params["tau"] < high
    lo_txt, hi_txt = rows["tau"][3].split(" .. ")
    assert float(lo_txt) <= result.params["tau"] <= float(hi_txt) and lo_txt != hi_txt
    stages = [r for r in parser.rows if r and r[0] == "taguchi"]
    assert stages and stages[0][1] == "taguchi"
    assert "report.html" in html


def test_plot_helpers_return_figures_with_units(result):
    fig = result.plot_fit()
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert "y" in labels[0] and labels[1].startswith("residual")
    assert isinstance(fig, matplotlib.figure.Figure)
    conv = result.plot_convergence()
    costs = [r.best_cost for r in result.iterations]
    scale = "log" if max(costs) / min(costs) > 10 else "linear"
    assert conv.axes[0].get_yscale() == scale and conv.axes[0].get_ylabel() == "best IAE"
    me = result.plot_main_effects(1)
    titles = " ".join(t.get_text() for ax in me.axes for t in ax.texts)
    assert "tau [s]" in titles and "rank" in titles
    assert me.axes[0].get_ylabel() == "mean S/N [dB]"
    legend = [t.get_text() for t in me.legends[0].get_texts()]
    assert legend == [
        "mean of the runs at the level",
        "grand mean (all runs)",
        "chosen level (largest S/N)",
    ]
    with pytest.raises(StudyError, match="iterations"):
        result.plot_main_effects(result.nit + 1)
    par = result.plot_parameters()
    assert [ax.get_title() for ax in par.axes if ax.get_visible()] == ["tau [s]", "x0"]
    assert (result.out_dir / "report.html").is_file()
    assert (result.out_dir / "iteration_01" / "main_effects.svg").read_text().startswith("<svg")


def test_numbers_are_rounded_alike():
    assert fmt(0.0534125) == "0.053413"
    assert fmt(88.500275) == "88.5"
    assert fmt(11780.4) == "11780"
    assert fmt(1.178e-5) == "1.178e-5"
    assert fmt(2.5e7) == "2.5e7"
    assert fmt(float("nan")) == "-"
    assert fmt(3) == "3"
    assert fmt_levels([10000, 11780, 12000]) == ["10000", "11780", "12000"]
    assert fmt_levels([1.0, 1.0001, 1.0002]) == ["1", "1.0001", "1.0002"]
    assert nice_ticks(0, 1, 5) == [0, 0.25, 0.5, 0.75, 1.0]
    assert nice_ticks(-85.45, -85.41, 4)[0] >= -85.45


@pytest.mark.slow
def test_report_html_lists_failed_runs_and_diagnostics(tmp_path):
    d = tmp_path
    fmu = build_c_fmu(d)
    t = np.arange(0, 3.0 + 1e-9, 0.01)
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5)
    y = lag_response(t, u, 0.37, 0.8) + np.random.default_rng(2).normal(0, 0.005, t.shape)
    pd.DataFrame({"time": t, "u": u, "y_meas": y}).to_csv(d / "lag.csv", index=False)
    study = Study(
        fmu=fmu,
        parameters=[Parameter("tau", [0.0, 0.4, 1.0], min=0.0), Parameter("x0", [-1.0, 0.0, 2.0])],
        experiments=[Experiment(data=d / "lag.csv", inputs={"u": "u"}, outputs={"y": "y_meas"})],
    )
    res = identify(study, d / "out", plots=False)
    html = (d / "out" / "report.html").read_text()
    failed = html.split('id="failed"')[1].split("<h2")[0]
    rows = _Rows()
    rows.feed(failed)
    failures = sum(e is not None for rec in res.iterations for e in rec.errors)
    assert failures >= 3 and len([r for r in rows.rows[1:] if r]) == failures
    assert "condition" in html.split('id="diagnostics"')[1]  # a scalar of result.uncertainty
    assert "<img" not in html  # no plots asked for: tables only
    assert "Response table for S/N ratios" in html and "ANOVA of S/N" in html


@pytest.mark.slow
def test_a_paused_study_is_drawn_for_review_and_resume_reuses_the_figures(result, tmp_path):
    study = result.study
    out = tmp_path / "paused"
    part = identify(study, out, pause_after=1, plots=True)
    assert part.status == 3  # the exit status of --pause-after
    first = out / "iteration_01" / "main_effects.svg"
    assert first.is_file() and (out / "report.html").is_file()
    assert not (out / "result.json").exists()
    stamp = first.stat().st_mtime_ns
    done = identify(study, out, resume=True, plots=True)
    assert done.nit > 1 and (out / f"iteration_{done.nit:02d}" / "main_effects.svg").is_file()
    assert first.stat().st_mtime_ns == stamp  # read back, not drawn again
    assert (out / "result.json").is_file()
