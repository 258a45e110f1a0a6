"""A study with ``uncertainty = "bootstrap"`` (issue 29, item 5): the sampled intervals
beside the primary ones in the result, its DataFrames, result.json and ``load``, the
reports and the command line; the primary intervals stay as they were."""

from __future__ import annotations

import json
import math

import pytest
from fmu_factory import lag_study

from tsid_fmu import identify, load
from tsid_fmu.cli import _print_result

pytestmark = pytest.mark.slow  # two identifications of the lag FMU (about 30 s)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("lag")
    options = dict(name="lag", max_iterations=4, replicates=1, cost="sse", seed=3)
    study = lag_study(d, uncertainty="bootstrap", uncertainty_replicates=40, **options)
    path = study.to_toml(d / "study" / "lag.toml")
    res = identify(path, d / "out", plots=False, workers=1)
    plain = identify(lag_study(d, **options), plots=False, workers=1)
    return res, d / "out", plain


def test_the_result_has_sampled_intervals_beside_the_primary_ones(run):
    res, _, plain = run
    assert plain.sampled is None and "bootstrap low" not in plain.parameters_frame()
    assert res.intervals == plain.intervals  # the primary intervals are unchanged
    s = res.sampled
    assert s.kind == "bootstrap" and s.replicates == 40 and s.failed == 0
    assert 0 < s.nfev <= 40 * 8
    for name, (low, high) in res.intervals.items():
        s_low, s_high = s.intervals[name]
        assert s_low < res.params[name] < s_high
        # the same noise, seen two ways: widths of the same order
        assert 0.3 < (s_high - s_low) / (high - low) < 3.0
    frame = res.parameters_frame()
    assert frame.loc["tau", "bootstrap low"] == s.intervals["tau"][0]
    assert len(s.to_pandas()) == 40


def test_result_json_and_load_give_the_sampled_intervals_back(run):
    res, out, _ = run
    data = json.loads((out / "result.json").read_text())
    assert data["sampled"]["kind"] == "bootstrap"
    back = load(out)
    assert back.sampled == res.sampled
    assert back.parameters_frame().equals(res.parameters_frame())
    assert "block length" in (out / "report.md").read_text()


def test_the_reports_and_the_command_line_show_them(run, capsys):
    res, out, plain = run
    md = (out / "report.md").read_text()
    page = (out / "report.html").read_text()
    for text in (md, page):
        assert "Bootstrap 95 % intervals, beside the primary ones" in text
    assert "bootstrap 95 % interval" in page
    _print_result(res, out)
    printed = capsys.readouterr().out
    assert "bootstrap 95 % interval" in printed and "replicates (0 failed" in printed
    _print_result(plain, out)
    assert "bootstrap" not in capsys.readouterr().out
    # tsid identify --json: the summary carries it, as its schema says
    import jsonschema
    from test_cli_shell import _schema

    summary = res.summary()
    jsonschema.validate(summary, _schema())
    assert summary["parameters"]["tau"]["sampled_interval"] == res.sampled.intervals["tau"]
    assert "sampled_interval" not in plain.summary()["parameters"]["tau"]
    assert math.isfinite(res.sampled.std_error["tau"])


def test_init_mentions_the_option_and_it_reads_back_when_uncommented(tmp_path):
    from test_init import _ball

    from tsid_fmu import Study
    from tsid_fmu.scaffold import init_study

    fmu, data = _ball(tmp_path)
    text = init_study(fmu, data, tmp_path / "study.toml")
    keys = ("# uncertainty = ", "# uncertainty_replicates = ")
    assert all(k in text for k in keys)
    lines = [ln.removeprefix("# ") if ln.startswith(keys) else ln for ln in text.splitlines()]
    (tmp_path / "sampled.toml").write_text("\n".join(lines) + "\n")
    method = Study.from_toml(tmp_path / "sampled.toml").method
    assert (method.uncertainty, method.uncertainty_replicates) == ("bootstrap", 100)
