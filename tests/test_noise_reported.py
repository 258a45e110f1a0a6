"""One noise per output everywhere (issue 26): the one the cost weights by, with its source.

The report, ``result.json`` and ``load()`` show the noise the cost uses: the sensor
noise the study states (``noise = {...}``), else the estimate from the measured data;
and say which. The residual diagnostics of report.html are tables with named columns:
the residual RMS is not written like an interval (``5.6 .. 2.7e-7``), and no raw key
of the uncertainty (``std_error``, ``rho1``, ``p_value``) is shown.
"""

from __future__ import annotations

import json
import math
import re
from html.parser import HTMLParser

import pytest
from fmu_factory import lag_study

from tsid_fmu import IdentificationResult, identify, load
from tsid_fmu.report.html import html_report
from tsid_fmu.study.prepare import data_noise
from tsid_fmu.uncertainty.intervals import Uncertainty

STATED = 0.2  # about 20 x the lag data's own noise


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for name, noise in (("estimated", {}), ("stated", {"y": STATED})):
        d = tmp_path_factory.mktemp(name)
        study = lag_study(d, name=name, max_iterations=2, replicates=1)
        study.experiments[0].noise = dict(noise)
        out[name] = identify(study, d / "out", plots=False, workers=1, timeout=0)
    return out


def test_the_noise_reported_is_the_one_the_cost_uses_and_says_whence(runs):
    stated, estimated = runs["stated"], runs["estimated"]
    (exp,) = stated.noise
    assert stated.noise[exp] == {"y": STATED} and stated.noise_source[exp] == {"y": "study"}
    measured = stated.study.experiments[0].data
    column = __import__("pandas").read_csv(measured)["y_meas"].to_numpy()
    own = float(data_noise(column[:, None])[0])
    assert own < STATED / 5  # the data's estimate is another number
    assert estimated.noise[exp]["y"] == pytest.approx(own, rel=1e-12)
    assert estimated.noise_source[exp] == {"y": "data"}
    md = (stated.out_dir / "report.md").read_text()
    assert f"noise, stated in the study: {STATED:g}" in md
    assert "noise, estimated from the data: " in (estimated.out_dir / "report.md").read_text()
    html = (stated.out_dir / "report.html").read_text()
    assert "stated in the study" in html.split('id="diagnostics"')[0]  # the fit table
    saved = json.loads((stated.out_dir / "result.json").read_text())
    assert saved["noise"][exp] == {"y": STATED} and saved["noise_source"][exp] == {"y": "study"}
    back = load(stated.out_dir)
    assert back.noise == stated.noise and back.noise_source == stated.noise_source


class _Cells(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.cells: list[str] = []
        self._in = False

    def handle_starttag(self, tag, attrs):
        if tag in ("td", "th"):
            self._in = True
            self.cells.append("")

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._in = False

    def handle_data(self, data):
        if self._in:
            self.cells[-1] += data


def _diagnostics_html() -> str:
    u = Uncertainty(
        values={"a": 2.0, "b": 3.0},
        std_error={"a": 0.1, "b": 0.001},
        relative={"a": 5.0, "b": 0.03},
        cramer_rao={"a": 2.0, "b": 0.01},
        intervals={"a": [1.8, 2.2], "b": [2.99, 3.01]},
        correlation={"a": {"a": 1.0, "b": 0.5}, "b": {"a": 0.5, "b": 1.0}},
        noise={"rig": [5.6, 2.7e-7]},
        whiteness={
            "rig": {
                "F": {"p_value": 0.8, "rho1": -0.01, "white": True, "bandwidth": 2},
                "x": {"p_value": 0.0, "rho1": 0.64, "white": False, "bandwidth": 42},
            }
        },
        resolution={"b": 0.03},
    )
    res = IdentificationResult(
        params={"a": 2.0, "b": 3.0}, fun=1.0, nfev=10, success=True, status=0, message="ok"
    )
    res.uncertainty = u
    res.noise = {"rig": {"F": 5.6, "x": 2.887e-7}}
    res.noise_source = {"rig": {"F": "data", "x": "study"}}
    return html_report(res, None).split('id="diagnostics"')[1].split("<h2")[0]


def test_the_residual_diagnostics_are_tables_not_a_dict_dump():
    html = _diagnostics_html()
    parser = _Cells()
    parser.feed(html)
    cells = [c.strip() for c in parser.cells]
    # the residual RMS of each output on its own row, beside its noise and whence
    assert "residual RMS" in cells and "noise from" in cells and "Ljung-Box p" in cells
    row = cells.index("rig / x")
    assert cells[row + 1 : row + 4] == ["2.7e-7", "2.887e-7", "stated in the study"]
    assert cells[row + 6] == "coloured"
    assert not any(re.fullmatch(r"5\.6 \.\. .*", c) for c in cells)  # not like an interval
    for raw in ("std_error", "cramer_rao", "p_value", "rho1", "bandwidth 2", "True", "False"):
        assert raw not in html, raw
    # a standard error at the profile's resolution is a bound
    b = cells.index("b")
    assert cells[b + 2].startswith("< ") and "resolution" in cells[b + 3]
    assert math.isfinite(float(cells[cells.index("a") + 2]))
