"""What a person reads (issue 64): a one-line verdict, and one story per parameter.

- the verdict is one sentence of at most 200 characters, made from a code and a table;
  the stage-by-stage account says each clause once;
- a parameter's interval and flag are the same in every view (console, markdown, HTML,
  CSV, ``--json``, lmfit's report, the design), half-open where one end is open;
- the combinations are listed best determined first, and one the Jacobian calls
  determined but whose leading parameter's interval is open says so.
"""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from fmu_factory import lag_study

from tsid_fmu import IdentificationResult, load
from tsid_fmu.design.outcome import _span
from tsid_fmu.report.html import html_report
from tsid_fmu.report.markdown import markdown_report
from tsid_fmu.search.outcome import Stationarity
from tsid_fmu.search.stage import StageResult
from tsid_fmu.status import MAX_MESSAGE, MESSAGES, Verdict, account, study_status
from tsid_fmu.story import determination, interval_text, listed_combinations, weak_reason

REPO = Path(__file__).resolve().parents[1]


def _stage(
    name: str, message: str, status: int = 0, stationarity: dict | None = None
) -> StageResult:
    kind = "taguchi" if name == "taguchi" else "refinement"
    test = Stationarity.from_dict(stationarity)
    return StageResult(name, kind, {"a": 1.0}, 2.0, 10, message, status, stationarity=test)


# ------------------------------------------------------------------ the verdict


def test_the_verdict_is_one_short_sentence_and_the_account_says_each_clause_once():
    long = "least squares: the last step lowered the cost by less than 0.0001 of it"
    test = {"holds": True, "test": "projected Gauss-Newton", "detail": "predicts 0.003"}
    stages = [
        _stage("taguchi", "iteration limit (25) reached before the levels converged", 1),
        _stage(
            "refinement",
            f"{long}; stopped before another Jacobian; again with wider steps: {long}; "
            "stopped before another Jacobian; stationary: predicts 0.003",
            stationarity=test,
        ),
    ]
    status, code, message, told = study_status(stages)
    assert (status, code) == (0, Verdict.STATIONARY)
    assert message == "converged: the answer is stationary (20 simulations)"
    clauses = [c for line in told for c in line.split(": ", 1)[1].split("; ")]
    assert len(clauses) == len(set(clauses)), told
    assert sum(long in line for line in told) == 1  # the second pass says "the same"
    assert "again with wider steps: the same" in told[1]
    assert told[-1] == "verdict: stationary at the answer (projected Gauss-Newton)"
    assert told[0] == "taguchi: iteration limit (25) reached before the levels converged"


def test_a_stop_at_a_limit_names_the_stage_and_stays_under_200_characters():
    why = "simulation limit (500) reached " + "because " * 60
    status, code, message, _ = study_status([_stage("refinement", why, 1)])
    assert (status, code) == (1, Verdict.LIMIT)
    assert len(message) <= MAX_MESSAGE
    assert message.startswith("stopped at a limit (refinement: simulation limit (500)")
    assert message.endswith("the answer may not be the optimum (10 simulations)")
    failed = {"holds": False, "test": "local probe", "detail": "a probe was lower"}
    status, code, message, told = study_status([_stage("refinement", "ok", stationarity=failed)])
    assert (status, code) == (1, Verdict.NOT_SHOWN) and "converged" not in message
    assert told[-1] == "verdict: not shown to be an optimum (local probe): a probe was lower"
    assert all(len(m.format(nfev=10**9, nit="9 Taguchi iterations", why="x" * 90)) <= 200
               for m in MESSAGES.values())  # fmt: skip


def test_a_paused_study_says_how_to_go_on():
    paused = _stage("taguchi", "paused after iteration 1 for review", 2)
    status, code, message, told = study_status([paused])
    assert (status, code) == (3, Verdict.PAUSED)
    assert message == (
        "paused for review after 0 Taguchi iterations (10 simulations): edit the levels, "
        "then --resume"
    )
    assert told[-1] == "taguchi: paused after iteration 1 for review"
    assert account([]) == []


# ------------------------------------------------------------------ one story


def test_an_interval_is_said_alike_whatever_end_is_open():
    def pair(values: list[float]) -> list[str]:
        return [f"{v:g}" for v in values]

    assert interval_text([1.0, 2.0], 1.5, pair) == "1 .. 2"
    assert interval_text([None, 2.0], 1.5, pair) == "open .. 2"
    assert interval_text([1.0, None], 1.5, pair) == "1 .. open"
    assert interval_text([1.0, float("inf")], 1.5, pair) == "1 .. open"
    assert interval_text([None, None], 1.5, pair) == "not determined"
    assert interval_text(None, 1.5, pair) == "not computed"  # a paused study
    assert [determination(v) for v in ([1, 2], [None, 2], [1, None], [None, None], None)] == [
        "determined", "open below", "open above", "not determined", "not computed",
    ]  # fmt: skip
    assert weak_reason([1, 2]) is None and "open below" in weak_reason([None, 2])


def test_combinations_are_best_determined_first_and_contradictions_are_said():
    combos = [
        {"terms": {"lg a": 0.6, "lg b": 0.8}, "std_error": 3e-3, "determined": True},
        {"terms": {"lg b": 0.999}, "std_error": 1e-4, "determined": True},
        {"terms": {"lg a": 0.7, "lg c": -0.7}, "std_error": 5.0, "determined": False},
        {"terms": {"lg a": 1.0}, "std_error": 2e-5, "determined": True},
    ]
    listed = listed_combinations(combos, {"a": [1, 2], "b": [None, 5.0], "c": [None, None]})
    assert [c["std_error"] for c in listed] == [2e-5, 1e-4, 3e-3, 5.0]
    assert [c["state"] for c in listed] == [
        "determined",
        "determined only locally (the profile leaves b's interval open)",
        "determined",
        "not determined",
    ]


@pytest.fixture(scope="module")
def half_open(tmp_path_factory):
    """A result whose x0 is open below: every view is rendered from it."""
    study = lag_study(tmp_path_factory.mktemp("story"))
    iv = {"tau": [0.35, 0.39], "x0": [None, 1.2]}
    res = IdentificationResult(
        params={"tau": 0.37, "x0": 0.8}, fun=1.0, nfev=10, success=True, status=0,
        message="converged: the answer is stationary (10 simulations)", intervals=iv,
        study=study, weak={n: weak_reason(v) for n, v in iv.items() if weak_reason(v)},
    )  # fmt: skip
    res.describe_parameters()
    return res


def _views(res: IdentificationResult, name: str) -> dict[str, str]:
    """Each view's interval text for ``name`` (and the flag where the view has one)."""
    text = next(x for x in res.text_report().splitlines() if x.startswith(f"{name} "))
    md = next(x for x in markdown_report(res).splitlines() if x.startswith(f"| {name} |"))
    lm = next(x for x in res.fit_report().splitlines() if x.strip().startswith(f"{name}:"))
    views = {"console": text, "markdown": md, "lmfit": lm}
    views.update(_html_rows(html_report(res), name))
    return views


def _html_rows(html: str, name: str) -> dict[str, str]:
    """The HTML report's table rows of ``name`` that show an interval, by position."""
    rows = re.findall(rf'<tr><th class="text">{re.escape(name)}</th>(.*?)</tr>', html, re.S)
    shown = [r for r in rows if re.search(r"open \.\.|\.\. open|not determined", r)]
    assert shown, html[:2000]
    return {f"html row {k}": r for k, r in enumerate(shown)}


def test_every_view_shows_one_interval_and_flag(half_open):
    res = half_open
    shown = interval_text(res.intervals["x0"], 0.8, lambda v: [f"{x:g}" for x in v])
    assert shown == "open .. 1.2"
    for view, line in _views(res, "x0").items():
        assert shown in line, (view, line)
        assert "not determined" not in line, (view, line)
    flag = "open below"
    assert res.summary()["parameters"]["x0"]["determined"] == flag
    assert res.parameters_frame().loc["x0", "determined"] == flag
    assert f"({flag})" in _views(res, "x0")["lmfit"]
    assert flag in _views(res, "x0")["markdown"]
    assert res.weak["x0"] in _views(res, "x0")["console"]
    assert _span(res.intervals["x0"]) == shown  # the design's table


# ------------------------------------------------------------------ the SISO example


@pytest.fixture(scope="module")
def siso(tmp_path_factory):
    """``tsid identify`` on the README's example, stdout and stderr to files."""
    out = tmp_path_factory.mktemp("siso") / "out"
    with open(out.parent / "stdout", "w") as so, open(out.parent / "stderr", "w") as se:
        code = subprocess.run(
            [sys.executable, "-m", "tsid_fmu", "identify", "examples/lsea_siso/study.toml",
             "--out", str(out)], cwd=REPO, stdout=so, stderr=se, timeout=600,
        ).returncode  # fmt: skip
    return code, out, (out.parent / "stdout").read_text(), (out.parent / "stderr").read_text()


@pytest.mark.slow
def test_the_examples_verdict_is_one_line_and_progress_reaches_a_file(siso):
    code, out, stdout, stderr = siso
    assert code == 0
    res = load(out)
    verdict = [x for x in stdout.splitlines() if x.startswith(res.message)]
    assert verdict == [f"{res.message} (exit status 0)"]
    assert len(res.message) <= MAX_MESSAGE and res.message.startswith("converged: ")
    # no clause twice on stdout: every line but the table's is said once
    lines = [x for x in stdout.splitlines() if x.strip()]
    assert len(lines) == len(set(lines))
    clauses = [c for x in lines for c in x.split("; ") if len(c) > 30]
    assert len(clauses) == len(set(clauses)), clauses
    # stderr a file: a plain line per iteration and stage, no terminal control
    assert "taguchi, iteration 1 (L25): best cost" in stderr
    assert "== refinement (least squares)" in stderr and "\r" not in stderr
    assert json.loads((out / "result.json").read_text())["message"] == res.message


@pytest.mark.slow
def test_the_examples_b_s_is_one_story_in_every_view(siso):
    _, out, stdout, _ = siso
    res = load(out)
    low, high = res.intervals["B_s"]
    assert low is None and high is not None  # open below (the README's figure)
    flag = determination(res.intervals["B_s"])
    assert flag == "open below"
    row = next(x for x in stdout.splitlines() if x.startswith("B_s "))
    shown = re.search(r"open \.\. (\S+)", row)
    assert shown, row
    end = shown[0]
    views = _views(res, "B_s")
    views["report.md"] = next(
        x for x in (out / "report.md").read_text().splitlines() if x.startswith("| B_s |")
    )
    views.update({f"report.{k}": r for k, r in _html_rows((out / "report.html").read_text(),
                                                          "B_s").items()})  # fmt: skip
    for view, line in views.items():
        assert end in line, (view, line)
        assert "not determined" not in line, (view, line)
    with open(out / "parameters.csv", newline="") as f:
        csv_row = next(r for r in csv.DictReader(f) if r["parameter"] == "B_s")
    assert csv_row["determined"] == flag and csv_row["95% low"] == ""
    assert float(csv_row["95% high"]) == pytest.approx(high)
    assert res.summary()["parameters"]["B_s"]["determined"] == flag
    assert res.params["B_s"].stderr == float("inf")  # as the fresh result has it
    md = (out / "report.md").read_text()
    local = [x for x in md.splitlines() if x.startswith("- ") and "B_s" in x and "lg B_s" in x]
    assert all("determined only locally" in x or "+0." in x or "-0." in x for x in local)


# ------------------------------------------------------------------ figures


def test_no_figure_of_a_single_point(tmp_path):
    """A one-iteration study drew "parameters per iteration" on one point (issue 64)."""
    from tsid_fmu import identify
    from tsid_fmu.report.figures import MIN_POINTS, points

    study = lag_study(tmp_path, max_iterations=1, replicates=1, refine="none")
    res = identify(study, tmp_path / "out", plots=True, workers=1)
    assert len(res.iterations) == 1 and points(res)["parameters.png"] < MIN_POINTS
    assert not (tmp_path / "out" / "parameters.png").exists()
    assert not (tmp_path / "out" / "convergence.png").exists()
    assert "parameters.png" not in (tmp_path / "out" / "report.md").read_text()
    assert "parameters.png" not in (tmp_path / "out" / "report.html").read_text()
    assert (tmp_path / "out" / "fit.png").exists()


def test_an_error_near_zero_is_said_in_the_parameters_units(half_open):
    """A start near zero read "below the profile's resolution (< 210)" beside "determined
    only to +/-2.1e+02 %" (issue 64): its error is absolute, in every view."""
    import dataclasses

    from tsid_fmu.report.notebook import _std_error
    from tsid_fmu.uncertainty.intervals import Uncertainty
    from tsid_fmu.weak import weak_parameters as _weak

    u = Uncertainty(values={"tau": 0.37, "x0": 0.0024}, std_error={"tau": 0.004, "x0": 0.5},
                    relative={"tau": 1.08, "x0": 210.0},
                    intervals={"tau": [0.36, 0.38], "x0": [-0.4, 1.6]})  # fmt: skip
    res = dataclasses.replace(half_open, params={"tau": 0.37, "x0": 0.0024}, uncertainty=u,
                              intervals=dict(u.intervals), weak={})  # fmt: skip
    res.describe_parameters()
    assert _std_error(u, "x0", "m") == "+/-0.5 m (absolute)"
    assert _std_error(u, "tau", "s") == 1.08
    u.resolution = {"x0": 210.0}
    assert _std_error(u, "x0", "m") == "< 0.5 m (absolute)"
    u.resolution = {}
    # weak against its first range (-1 .. 2): 0.5 is 17 % of it, above the 5 % mark
    assert _weak(res)["x0"] == (
        "the data determine it only to +/-0.5 (standard error; it is near zero)"
    )
    u.std_error["x0"] = 0.003  # an offset the data fix to +/-0.003: not weak
    assert "x0" not in _weak(res)
    assert "+/- 0.5 [95 %" in next(x for x in res.fit_report().splitlines() if "x0:" in x)
