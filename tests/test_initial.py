"""Initial states from the data (issue 29, item 3): ``initial = { x0 = "from_data:y" }``.

The lag's record starts at y = 0.8 (data from the exact solution, ``lag_response``);
its FMU starts at x0 = 0 unless the study sets it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, lag_response

from tsid_fmu import Experiment, Parameter, Study, identify
from tsid_fmu.errors import StudyError
from tsid_fmu.report.html import html_report
from tsid_fmu.scaffold import init_study
from tsid_fmu.study.prepare import prepare

TAU, X0, SIGMA = 0.37, 0.8, 0.002


@pytest.fixture(scope="module")
def lag_fmu(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("lag"), interfaces=("cs",))


def record(path, seed=0):
    t = np.arange(0, 3.0 + 1e-9, 0.01)
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5) + 0.3 * np.sin(3 * t)
    y = lag_response(t, u, TAU, X0) + np.random.default_rng(seed).normal(0, SIGMA, t.size)
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(path, index=False)
    return path


def study(fmu, data, **experiment) -> Study:
    return Study(
        fmu=fmu,
        parameters=[Parameter("tau", [0.1, 0.4, 1.6], min=0.01)],
        experiments=[Experiment(data=data, inputs={"u": "u"}, outputs={"y": "y"}, **experiment)],
        cost="sse",
        weighting="noise",
        replicates=1,
    )


@pytest.mark.slow
def test_a_state_set_from_the_first_sample_gives_the_truth(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv")
    first = float(pd.read_csv(data)["y"].iloc[0])
    s = study(lag_fmu, data, initial={"x0": "from_data:y"})
    assert prepare(s).experiments[0].start_values == {"x0": first}
    res = identify(s, plots=False, workers=1)
    low, high = res.intervals["tau"]
    assert low <= TAU <= high and not res.warnings
    assert "first sample: d: x0 (from_data:y)" in html_report(res)
    # without it the lag starts at its x0 = 0: the fit is poor and tau biased
    plain = identify(study(lag_fmu, data), plots=False, workers=1)
    assert not low <= plain.params["tau"] <= high
    assert any("mismatch" in w for w in plain.warnings)


def test_the_first_sample_is_the_records_even_with_windows(lag_fmu, tmp_path):
    data = record(tmp_path / "d.csv")
    first = float(pd.read_csv(data)["y"].iloc[0])
    s = study(lag_fmu, data, initial={"x0": "from_data:y"}, windows=[[1.0, 3.0]])
    assert prepare(s).experiments[0].start_values == {"x0": first}


@pytest.mark.parametrize(
    ("initial", "message"),
    [
        ({"x": "from_data:y"}, "initial 'x': FirstOrderLag.fmu does not let it be set"),
        ({"y": "from_data"}, "initial 'y': FirstOrderLag.fmu does not let it be set"),
        ({"c_const": "from_data:y"}, "causality 'local', variability 'constant'"),
        ({"x00": "from_data:y"}, "initial 'x00': FirstOrderLag.fmu: unknown variable 'x00'"),
        ({"x0": "from_data:z"}, "initial 'x0' = 'from_data:z': "),
        ({"x0": "from_data"}, "'x0' is not an output of this experiment"),
        ({"x0": "y"}, 'must be "from_data:<column>"'),
        ({"tau": "from_data:y"}, "initial 'tau' is set from the data and also identified"),
    ],
)
def test_a_state_that_cannot_be_set_is_refused_naming_it(lag_fmu, tmp_path, initial, message):
    data = record(tmp_path / "d.csv")
    with pytest.raises(StudyError) as err:
        prepare(study(lag_fmu, data, initial=initial))
    assert "experiment 'd'" in str(err.value) and message in str(err.value)


def test_initial_reads_and_writes_as_toml(lag_fmu, tmp_path):
    record(tmp_path / "d.csv")
    (tmp_path / "s.toml").write_text(
        f'[study]\nfmu = "{lag_fmu}"\n[data]\nfile = "d.csv"\ninputs = {{ u = "u" }}\n'
        'outputs = { y = "y" }\ninitial = { x0 = "from_data:y" }\n'
        "[parameters]\ntau = { levels = [0.1, 1.0] }\n"
    )
    s = Study.from_toml(tmp_path / "s.toml")
    assert s.experiments[0].initial == {"x0": "from_data:y"}
    assert Study.from_toml(s.to_toml(tmp_path / "again.toml")) == s


def test_init_writes_an_initial_state_hint_that_reads_back(tmp_path):
    from test_init import SISO

    text = init_study(
        SISO.parents[1] / "fmus" / "LSEA_SISO.fmu", SISO / "measured.csv", tmp_path / "s.toml"
    )
    assert '# initial = { x_m = "from_data" }' in text
    lines = [
        ln.removeprefix("# ") if ln.startswith("# initial = ") else ln for ln in text.splitlines()
    ]
    (tmp_path / "s2.toml").write_text("\n".join(lines) + "\n")
    s = Study.from_toml(tmp_path / "s2.toml")
    assert s.experiments[0].initial == {"x_m": "from_data"}
    assert prepare(s).experiments[0].start_values["x_m"] == pytest.approx(0.0, abs=1e-5)
