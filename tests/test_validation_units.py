"""Validation in the user's units (issue 63 item 4): the console, report.md, report.html
and ``--json`` give each validation experiment's RMSE in the output's unit, its NRMSE
and fit % beside the weighted cost, and the console the identification fit alike."""

from __future__ import annotations

import json
import re

import pytest
from fmu_factory import lag_study

import tsid_fmu.study.units as units_module
from tsid_fmu import Experiment, Study, identify


@pytest.fixture(scope="module")
def validated(tmp_path_factory):
    """The lag fitted on its record and validated on the same record, ``y`` in volts."""
    d = tmp_path_factory.mktemp("validated")
    plain = lag_study(d, max_iterations=2, replicates=1, cost="sse", weighting="noise")
    fitted = plain.experiments[0]
    check = Experiment(
        data=fitted.data, inputs={"u": "u"}, outputs={"y": "y_meas"}, name="check",
        role="validate",
    )  # fmt: skip
    study = Study(
        fmu=plain.fmu,
        parameters=plain.parameters,
        experiments=[fitted, check],
        method=plain.method,
    )
    with pytest.MonkeyPatch.context() as mp:
        # the lag FMU declares no unit for y: give it one, as a modeller's FMU would
        real = units_module.fmu_units
        mp.setattr(units_module, "fmu_units", lambda fmu: {**real(fmu), "y": "V"})
        result = identify(study, d / "out", plots=False, workers=1)
        text = result.text_report()
        summary = result.summary()
    return result, text, (d / "out" / "report.md").read_text(), summary, d / "out"


def test_the_console_gives_the_validation_rmse_in_volts_beside_the_cost(validated):
    result, text, _, _, _ = validated
    fit = result.validation["check"]["fit"]["y"]
    line = next(x for x in text.splitlines() if x.startswith("validation check:"))
    rmse = float(re.search(r"RMSE y (\S+) V, NRMSE (\S+), fit (\S+) %; cost", line)[1])
    assert rmse == pytest.approx(fit["rmse"], rel=1e-2)
    ident = next(x for x in text.splitlines() if x.startswith("fit lag:"))
    assert re.search(r"RMSE y \S+ V, NRMSE \S+, fit \S+ %$", ident), ident


def test_report_md_and_html_give_the_validation_rmse_with_its_unit(validated):
    _, _, md, _, out = validated
    section = md.split("## Validation experiments", 1)[1].split("\n## ", 1)[0]
    assert re.search(r"- check: RMSE y \S+ V, NRMSE \S+, fit \S+ %; cost \(SSE", section)
    html = (out / "report.html").read_text()
    section = html.split('id="validation"', 1)[1].split("<h2", 1)[0]
    assert ">RMSE</th>" in section and re.search(r"<td[^>]*>y \S+ V</td>", section)


def test_the_json_summary_holds_rmse_nrmse_fit_and_unit_per_output(validated):
    from importlib.resources import files

    import jsonschema

    result, _, _, summary, _ = validated
    schema = json.loads((files("tsid_fmu") / "schemas" / "result-summary.schema.json").read_text())
    jsonschema.validate(summary, schema)
    val = summary["validation"]["check"]
    assert val["cost"] == pytest.approx(result.validation["check"]["cost"])
    y = val["outputs"]["y"]
    assert y["unit"] == "V" and y["rmse"] == pytest.approx(
        result.validation["check"]["fit"]["y"]["rmse"]
    )
    assert y["fit_percent"] == pytest.approx(100 * (1 - y["nrmse"]))
    assert summary["fit"]["lag"]["y"]["unit"] == "V"


def test_tsid_identify_json_prints_the_validation_rmse_with_its_unit(tmp_path, capsys, monkeypatch):
    """The command line's ``--json``, not only ``summary()``: the same figures on stdout."""
    from tsid_fmu.cli import main

    plain = lag_study(tmp_path, max_iterations=2, replicates=1, cost="sse", weighting="noise")
    fitted = plain.experiments[0]
    check = Experiment(
        data=fitted.data, inputs={"u": "u"}, outputs={"y": "y_meas"}, name="check",
        role="validate",
    )  # fmt: skip
    study = Study(fmu=plain.fmu, parameters=plain.parameters, experiments=[fitted, check],
                  method=plain.method).to_toml(tmp_path / "lag.toml")  # fmt: skip
    real = units_module.fmu_units
    monkeypatch.setattr(units_module, "fmu_units", lambda fmu: {**real(fmu), "y": "V"})
    main(["identify", str(study), "--out", str(tmp_path / "out"), "--json", "-q",
          "--no-plots", "--workers", "1"])  # fmt: skip
    summary = json.loads(capsys.readouterr().out)
    y = summary["validation"]["check"]["outputs"]["y"]
    assert y["unit"] == "V" and 0 < y["rmse"] < 1 and 0 < y["fit_percent"] <= 100
