"""The result in SciPy's and lmfit's manner: ``params[name]`` with its standard error,
interval, unit and bounds; ``x``, ``cov`` and ``jac`` in one order in every study (a
structure's discrete choices included); ``status`` equal to the exit status;
``to_dict()`` holding what the attributes hold; ``fit_report()``; the stage messages
as a list."""

from __future__ import annotations

import copy
import json
import math
import pickle

import numpy as np
import pytest
from fmu_factory import lag_study

from tsid_fmu import Choice, IdentificationResult, Param, Parameters, Study, identify, load
from tsid_fmu.result import PAUSED, STATUS


@pytest.fixture(scope="module")
def lag(tmp_path_factory):
    d = tmp_path_factory.mktemp("lag")
    study = lag_study(d, max_iterations=4, replicates=1)
    return identify(study, d / "out", plots=False, workers=1), d / "out"


@pytest.fixture(scope="module")
def lag_sse(tmp_path_factory):
    """The lag identified on the cost lmfit's statistics are defined for: SSE / noise²."""
    d = tmp_path_factory.mktemp("lag_sse")
    study = lag_study(d, max_iterations=4, replicates=1, cost="sse", weighting="noise")
    return identify(study, d / "out", plots=False, workers=1), d / "out"


@pytest.fixture(scope="module")
def chosen(tmp_path_factory):
    """A structure study: the lag's Boolean ``offset_on`` (adds 1 to y) is chosen."""
    d = tmp_path_factory.mktemp("choice")
    plain = lag_study(d, max_iterations=3, replicates=1, cost="sse", weighting="noise")
    study = Study(
        fmu=plain.fmu,
        parameters=[*plain.parameters, Choice("offset_on", [0, 1])],
        experiments=plain.experiments,
        method=plain.method,
    )
    return identify(study, d / "out", plots=False, workers=1)


def test_each_parameter_carries_its_standard_error_interval_unit_and_bounds(lag):
    res, _ = lag
    assert isinstance(res.params, Parameters)
    tau = res.params["tau"]
    assert isinstance(tau, Param) and isinstance(tau, float) and tau.value == float(tau)
    assert tau.name == "tau" and tau.unit == "s" and (tau.min, tau.max) == (0.0, math.inf)
    assert tau.stderr == pytest.approx(math.sqrt(res.cov[0, 0]), rel=1e-12)
    assert tau.stderr == res.uncertainty.std_error["tau"] and tau.vary
    assert list(tau.interval) == res.intervals["tau"]
    assert tau.interval[0] < tau < tau.interval[1]
    assert res.params.valuesdict() == {n: float(v) for n, v in zip(res.names, res.x, strict=True)}


def test_a_parameter_is_still_the_number_it_was(lag):
    """Arithmetic, formatting, JSON and pickling see the value."""
    res, _ = lag
    tau = res.params["tau"]
    assert repr(tau) == repr(float(tau)) and str(tau) == str(float(tau))
    assert f"{tau:.3f}" == f"{float(tau):.3f}" and 2 * tau == 2 * float(tau)
    assert json.loads(json.dumps({"tau": tau})) == {"tau": float(tau)}
    again = pickle.loads(pickle.dumps(tau))
    assert again == tau and again.stderr == tau.stderr and again.unit == "s"
    assert copy.deepcopy(res.params)["tau"].interval == tau.interval


def test_load_gives_the_parameters_their_attributes_back(lag):
    res, out = lag
    back = load(out, study=res.study)  # units and bounds are the study's
    for name in res.names:
        a, b = res.params[name], back.params[name]
        assert (float(a), a.stderr, a.interval, a.unit, a.min, a.max) == (
            float(b), b.stderr, b.interval, b.unit, b.min, b.max,
        )  # fmt: skip


def test_to_dict_holds_what_the_attributes_hold(lag):
    res, out = lag
    data = res.to_dict()
    assert data["names"] == res.names and data["x"] == res.x.tolist()
    assert data["params"] == dict(zip(res.names, res.x.tolist(), strict=True))
    assert data["status"] == res.status and data["fun"] == res.fun
    saved = json.loads((out / "result.json").read_text())
    assert {k: saved[k] for k in ("names", "x", "params")} == {
        k: data[k] for k in ("names", "x", "params")
    }


def test_a_folder_of_an_older_tsid_fmu_with_x_by_name_still_loads(lag):
    """tsid-fmu 0.2 wrote ``x`` by name and no ``params``; such a folder reads back."""
    from tsid_fmu.load import _params

    assert _params({"x": {"tau": 0.5, "x0": 1.0}}) == {"tau": 0.5, "x0": 1.0}
    assert _params({"x": [0.5, 1.0], "params": {"tau": 0.5, "x0": 1.0}}) == {"tau": 0.5, "x0": 1.0}


def test_text_report_is_the_text_tsid_identify_prints(lag):
    res, _ = lag
    text = res.text_report()
    lines = text.splitlines()
    assert lines[0].split()[:2] == ["parameter", "value"]
    assert any(line.startswith("tau ") and " s " in line for line in lines)
    assert f"{res.message} (exit status {res.status})" in lines
    assert f"{res.nfev} simulations" in text
    assert "how the study got there:" not in text
    verbose = res.text_report(verbose=True)
    assert all(f"  {line}" in verbose.splitlines() for line in res.account)
    assert "[[Fit Statistics]]" in verbose


def test_fit_report_has_lmfits_sections_and_statistics(lag_sse, lag):
    """lmfit's fit_report: statistics, variables, correlations above a threshold (issue 64)."""
    iae = lag[0].fit_report()  # no chi-square for a cost that is not a sum of squares
    assert "    chi-square         = not a sum of squares (IAE)" in iae.splitlines()
    res, _ = lag_sse
    text = res.fit_report()
    for section in ("[[Fit Statistics]]", "[[Variables]]", "[[Correlations]]"):
        assert section in text
    for stat in ("chi-square", "reduced chi-square", "Akaike info crit", "Bayesian info crit",
                 "# data points", "# variables", "# function evals"):  # fmt: skip
        assert stat in text
    n, k = res.jac.shape[0], 2
    chi = res.fun
    assert f"    # data points      = {n}" in text.splitlines()
    aic = n * math.log(chi / n) + 2 * k
    bic = n * math.log(chi / n) + math.log(n) * k
    stats = {a.strip(): b.split()[0] for a, b in (line.split(" = ", 1) for line in text.splitlines()
             if " = " in line and line.startswith("    ") and "C(" not in line)}  # fmt: skip
    assert float(stats["Akaike info crit"]) == pytest.approx(aic, rel=1e-6)
    assert float(stats["Bayesian info crit"]) == pytest.approx(bic, rel=1e-6)
    c = res.params["tau"].correl["x0"]
    assert c == pytest.approx(res.uncertainty.correlation["tau"]["x0"])
    assert res.params["x0"].correl["tau"] == pytest.approx(c)
    listed = [line for line in text.splitlines() if line.strip().startswith("C(")]
    if abs(c) >= 0.1:
        assert listed == [f"    C(tau, x0) = {c:+.4f}"] or listed == [f"    C(x0, tau) = {c:+.4f}"]
    assert res.fit_report(min_correl=1.01).count("C(") == 0
    assert f"{res.message} (exit status {res.status})" in text


def test_the_result_is_a_scipy_optimize_result(lag):
    from scipy.optimize import OptimizeResult

    res, out = lag
    for r in (res, load(out)):
        assert isinstance(r, OptimizeResult)
        assert np.array_equal(r["x"], r.x) and r["fun"] == r.fun and r["nfev"] == r.nfev
        assert {"x", "fun", "nfev", "success", "status", "message", "nit"} <= set(r.keys())
        assert "x" in r and dict(r)["message"] == r.message
    again = load(out)
    assert again.message == res.message and again.account == res.account


def test_stage_messages_are_a_list_in_stage_order(lag):
    res, _ = lag
    assert res.messages == [f"{s.name}: {s.message}" for s in res.stages]
    told = " ".join(res.account)
    assert all(m.split(": ", 1)[1].split("; ")[0] in told for m in res.messages)
    assert len(res.message) <= 200 and res.message.startswith(("converged: ", "stopped"))


def test_a_paused_study_has_the_status_its_exit_status_is(tmp_path):
    study = lag_study(tmp_path, max_iterations=4, replicates=1)
    res = identify(study, tmp_path / "out", plots=False, workers=1, pause_after=1)
    assert res.status == PAUSED == 3 and STATUS[3] == "paused for review"
    assert set(STATUS) == {0, 1, 3}  # 2 is the exit status of bad input
    assert res.cov.shape == (2, 2) and np.isnan(res.cov).all()  # no intervals yet
    assert math.isnan(res.params["tau"].stderr) and res.params["tau"].interval is None


def test_x_cov_and_jac_keep_one_order_with_a_structures_choice(chosen):
    res = chosen
    assert res.names == ["tau", "x0", "offset_on"] and res.params["offset_on"] in (0.0, 1.0)
    n = len(res.x)
    assert res.cov.shape == (n, n) and res.jac.shape[1] == n
    assert np.isnan(res.cov[2]).all() and np.isnan(res.cov[:, 2]).all()
    assert np.isnan(res.jac[:, 2]).all() and np.isfinite(res.jac[:, :2]).all()
    assert np.isfinite(res.cov[:2, :2]).all()
    choice = res.params["offset_on"]
    assert not choice.vary and math.isnan(choice.stderr) and res.params["tau"].vary


def test_a_result_built_by_hand_takes_a_plain_dict():
    res = IdentificationResult(params={"a": 1.0}, fun=0.0, nfev=1, success=True, status=0,
                               message="")  # fmt: skip
    assert isinstance(res.params, Parameters) and res.cov.shape == (1, 1)


def test_a_study_paused_in_the_arrays_it_went_back_to_is_paused(tmp_path, monkeypatch):
    """The arrays hand over after their first iteration; the refinement is not settled
    (here by decree: every refinement reads as stopped short), so they go on, and
    --pause-after stops them. The refinement is then the last stage, but the study is
    paused (it said "converged", exit status 0)."""
    from tsid_fmu.search.local import flow

    monkeypatch.setattr(flow, "_collapsed", lambda stage: "it stopped short")
    study = lag_study(tmp_path, cost="sse", weighting="noise", replicates=2, seed=7)
    res = identify(study, tmp_path / "out", plots=False, workers=1, pause_after=2)
    kinds = [(s.kind, s.status) for s in res.stages]
    assert kinds[0] == ("taguchi", 2) and res.stages[0].records[0].handover
    assert res.status == PAUSED and not res.success and res.message.startswith("paused")


def test_the_structure_report_shows_no_dicts_or_booleans(chosen):
    """The structure report showed raw {'model': 0.0} and True/False (issue 64)."""
    from tsid_fmu.report.html import html_report
    from tsid_fmu.report.markdown import markdown_report

    res = chosen
    table = res.structures_table()
    assert len(table) == len(res.structures) >= 2
    assert set(table["chosen"]) == {"yes", ""} and "values" not in table and "x" not in table
    md = markdown_report(res)
    section = md[md.index("## Structure") :]
    section = section[: section.index("\n## ", 4)]
    html = html_report(res)
    part = html[html.index('id="structure"') : html.index('id="stages"')]
    for text in (section, part):
        assert "{" not in text and "True" not in text and "False" not in text, text
