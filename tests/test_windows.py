"""Time windows (issue 29, item 4): only the spans a study names are scored.

The data come from the lag's exact solution (``fmu_factory.lag_response``, numpy), not
from the FMU; a start-up transient the lag cannot produce is added to them.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, lag_response
from matplotlib.colors import to_hex

from tsid_fmu import Experiment, Parameter, Study, identify
from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate import Cost
from tsid_fmu.report.fitfig import FitFigure
from tsid_fmu.report.html import html_report
from tsid_fmu.report.svg import WINDOW_FILL
from tsid_fmu.report.svgfig import fit_svg
from tsid_fmu.scaffold import init_study
from tsid_fmu.study.prepare import prepare, serial_evaluator

TAU, X0, SIGMA = 0.37, 0.8, 0.01


@pytest.fixture(scope="module")
def lag_fmu(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("lag"), interfaces=("cs",))


def record(path, transient=0.5, seconds=8.0, seed=0):
    """The lag on a square wave, plus ``transient * exp(-t / 0.3)`` and white noise."""
    t = np.arange(0, seconds + 1e-9, 0.01)
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5) + 0.3 * np.sin(3 * t)
    y = lag_response(t, u, TAU, X0) + transient * np.exp(-t / 0.3)
    y = y + np.random.default_rng(seed).normal(0, SIGMA, t.size)
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(path, index=False)
    return path


def study(fmu, data, **windows) -> Study:
    return Study(
        fmu=fmu,
        parameters=[Parameter("tau", [0.1, 0.4, 1.6], min=0.01)],
        experiments=[Experiment(data=data, inputs={"u": "u"}, outputs={"y": "y"}, **windows)],
        start_values={"x0": X0},
        cost="sse",
        weighting="noise",
        replicates=1,
    )


@pytest.mark.slow
def test_a_transient_windowed_out_gives_the_truth_and_left_in_a_flagged_bias(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv")
    windowed = identify(study(lag_fmu, data, windows=[[2.0, 8.0]]), plots=False, workers=1)
    low, high = windowed.intervals["tau"]
    assert low <= TAU <= high
    assert windowed.uncertainty.coloured == [] and not windowed.warnings
    assert "Scored time windows" in html_report(windowed) and "d: 2 to 8 s" in html_report(windowed)
    whole = identify(study(lag_fmu, data), plots=False, workers=1)
    bias = abs(whole.params["tau"] - TAU)
    assert bias > 10 * abs(windowed.params["tau"] - TAU)
    assert not low <= whole.params["tau"] <= high  # outside the windowed interval
    # the residual diagnostics say the model does not explain the whole record
    assert whole.uncertainty.coloured == ["d / y"]
    assert any("mismatch" in w for w in whole.warnings)


def test_only_the_windows_samples_are_scored_with_their_weights(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv", seconds=4.0)
    x = {"tau": 0.3}
    plain = serial_evaluator(study(lag_fmu, data, warmup=0.0))
    whole = plain.evaluate([x])
    sim = plain.simulate([x], count=False)[0][0].outputs
    e = plain.spec.experiments[0]
    assert e.windows == () and whole.residuals[0].size == e.time.size
    spans = [[0.5, 1.5], [2.0, 3.0]]
    ev = serial_evaluator(study(lag_fmu, data, windows=spans, window_weights=[1.0, 4.0]))
    w = ev.spec.experiments[0]
    res = ev.evaluate([x])
    t = w.time
    first, second = (t >= 0.5) & (t <= 1.5), (t >= 2.0) & (t <= 3.0)
    assert res.residuals[0].size == first.sum() + second.sum() == w.n_scored
    r = (sim[:, 0] - w.measured[:, 0]) / w.scale[0]
    # the weights count relative to the largest (weight_norms): 1/4 and 1
    expected = (np.sum(r[first] ** 2) + 4.0 * np.sum(r[second] ** 2)) / 4.0
    assert res.costs[0, 0] == pytest.approx(expected, rel=1e-12)
    assert np.sum(res.residuals[0] ** 2) == pytest.approx(expected, rel=1e-12)
    # the integral cost integrates each window alone, never across the gap
    iae = w.output_costs(Cost("iae"), sim)[0]
    one = np.trapezoid(np.abs(sim[first, 0] - w.measured[first, 0]), t[first])
    two = np.trapezoid(np.abs(sim[second, 0] - w.measured[second, 0]), t[second])
    assert iae == pytest.approx((one + 4.0 * two) / 4.0, rel=1e-12)


def test_the_noise_and_weights_come_from_the_scored_samples(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv", seconds=4.0)
    frame = pd.read_csv(data)
    loud = frame["time"] < 1.0  # ten times the noise before the window
    frame.loc[loud, "y"] += np.random.default_rng(5).normal(0, 10 * SIGMA, loud.sum())
    frame.to_csv(data, index=False)
    whole = prepare(study(lag_fmu, data)).experiments[0]
    windowed = prepare(study(lag_fmu, data, windows=[[1.0, 4.0]])).experiments[0]
    assert windowed.scale[0] == pytest.approx(SIGMA, rel=0.1)
    assert whole.scale[0] > 1.5 * SIGMA


def test_a_warmup_skips_the_start_of_each_window(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv", seconds=4.0)
    a = prepare(study(lag_fmu, data, warmup=1.0)).experiments[0]
    b = prepare(study(lag_fmu, data, windows=[[1.0, 4.0]])).experiments[0]
    assert a.windows == b.windows == ((100, 401),)
    c = prepare(study(lag_fmu, data, windows=[[0, 2], [2, 4]], warmup=[0.5, 0.25])).experiments
    assert c[0].windows == ((50, 201), (225, 401))  # the shared sample 2 s is the first's


@pytest.mark.parametrize(
    ("windows", "message"),
    [
        ({"windows": [[1.0, 9.0]]}, "window 1 [1, 9] s lies outside the record"),
        ({"windows": [[-1.0, 2.0]]}, "lies outside the record, which runs from 0 to 4 s"),
        ({"windows": [[0.0, 2.0], [1.5, 3.0]]}, "window 2 [1.5, 3] overlaps window 1"),
        ({"windows": [[2.0, 1.0]]}, "window 1 [2, 1] is reversed or empty"),
        ({"windows": [[1.0, 1.004]]}, "window 1 [1, 1.004] s holds 1 samples"),
        ({"windows": [[1.0, 2.0]], "warmup": 1.0}, "holds 1 samples after its warm-up of 1 s"),
        ({"windows": [[1.0, 2.0]], "window_weights": [1, 2]}, "2 values for 1 windows"),
        ({"windows": [[1.0, 2.0]], "window_weights": [0]}, "not all 0"),
        ({"windows": [[1.0, 2.0]], "warmup": -1}, "warmup must be >= 0"),
        ({"windows": [[1.0, "2"]]}, "window 1 must be a number"),
        ({"windows": [1.0, 2.0]}, "window 1 must be a pair [start, end]"),
    ],
)
def test_bad_windows_are_refused_naming_the_experiment(lag_fmu, tmp_path, windows, message):
    data = record(tmp_path / "d.csv", seconds=4.0)
    with pytest.raises(StudyError) as err:
        prepare(study(lag_fmu, data, **windows))
    assert "experiment 'd'" in str(err.value) and message in str(err.value)


def test_windows_read_and_write_as_toml(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv", seconds=4.0)
    (tmp_path / "s.toml").write_text(
        f'[study]\nfmu = "{lag_fmu}"\n[data]\nfile = "d.csv"\ninputs = {{ u = "u" }}\n'
        'outputs = { y = "y" }\nwindows = [[0.5, 1.5], [2, 3]]\nwarmup = [0.1, 0]\n'
        "window_weights = [1, 2]\n[parameters]\ntau = { levels = [0.1, 1.0] }\n"
    )
    s = Study.from_toml(tmp_path / "s.toml")
    e = s.experiments[0]
    assert e.windows == [[0.5, 1.5], [2.0, 3.0]] and e.warmup == [0.1, 0.0]
    assert e.window_weights == [1.0, 2.0]
    assert Study.from_toml(s.to_toml(tmp_path / "again.toml")) == s
    assert data.exists()
    (tmp_path / "bad.toml").write_text(
        (tmp_path / "s.toml").read_text().replace("[[0.5, 1.5], [2, 3]]", "[[2, 3], [0.5, 1.5]]")
    )
    with pytest.raises(StudyError, match=r"bad.toml: \[data\] experiment 'd': window 2"):
        Study.from_toml(tmp_path / "bad.toml")


def test_a_horizon_scores_the_first_part_of_the_windows(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv", seconds=4.0)
    spec = prepare(study(lag_fmu, data, windows=[[1.0, 2.0], [3.0, 4.0]]))
    head = spec.head(0.25, min_samples=20).experiments[0]
    full = spec.experiments[0]
    assert head.n_scored == math.ceil(0.25 * full.n_scored)
    assert head.windows == ((100, 151),) and head.time.size == 151
    assert spec.head(1.0).experiments[0].windows == full.windows


def test_the_fit_figure_shades_the_windows(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv", seconds=4.0)
    ev = serial_evaluator(study(lag_fmu, data, windows=[[1.0, 2.0], [3.0, 4.0]]))
    sims = ev.simulate([{"tau": TAU}], count=False)[0]
    svg = fit_svg(ev.spec.experiments, sims)
    assert svg.count('class="window"') == 4  # two windows, in the fit and residual panels
    assert "shaded: the scored windows" in svg
    plain = serial_evaluator(study(lag_fmu, data))
    assert 'class="window"' not in fit_svg(plain.spec.experiments, sims)
    fig = FitFigure(ev.spec.experiments).draw(sims)
    shaded = [p for ax in fig.axes for p in ax.patches if to_hex(p.get_facecolor()) == WINDOW_FILL]
    assert len(shaded) == 4


def test_init_writes_a_window_hint_that_reads_back_when_uncommented(tmp_path):
    from test_init import _ball

    fmu, data = _ball(tmp_path)
    text = init_study(fmu, data, tmp_path / "study.toml")
    assert "# windows = [[0.199, 1.99]]" in text  # the record runs from 0 to 1.99 s
    keys = ("# windows = ", "# warmup = ", "# window_weights = ")
    lines = [ln.removeprefix("# ") if ln.startswith(keys) else ln for ln in text.splitlines()]
    (tmp_path / "windowed.toml").write_text("\n".join(lines) + "\n")
    e = Study.from_toml(tmp_path / "windowed.toml").experiments[0]
    assert e.windows == [[0.199, 1.99]] and e.warmup == 0.0 and e.window_weights == [1.0]
