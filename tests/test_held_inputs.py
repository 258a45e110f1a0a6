"""An FMU input that no data column feeds is held at one value and can be identified.

OpenModelica's ``MassSpringSystem`` exposes its masses and stiffnesses as inputs; tsid
refused it ("no real parameter to identify") without naming what could be identified
(issue 43). The lag FMU's input ``u`` plays that role here: held at 0.7 over the run.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, lag_response

from tsid_fmu import Experiment, Method, Parameter, Study, identify
from tsid_fmu.errors import FMUError
from tsid_fmu.fmu import FMUSession
from tsid_fmu.scaffold import init_study


@pytest.fixture(scope="module")
def held(tmp_path_factory):
    d = tmp_path_factory.mktemp("held")
    fmu = build_c_fmu(d, "Lag", interfaces=("cs",))
    t = np.arange(0, 5.0 + 1e-9, 0.01)
    y = lag_response(t, np.full(t.size, 0.7), 0.37, 0.8)
    y = y + np.random.default_rng(2).normal(0, 0.002, t.size)
    data = d / "y.csv"
    pd.DataFrame({"time": t, "y": y}).to_csv(data, index=False)
    return fmu, data


def test_init_offers_the_input_without_a_column_as_a_parameter(held, tmp_path):
    text = init_study(*held, tmp_path / "study.toml")
    line = next(x for x in text.splitlines() if x.startswith("u = { levels"))
    assert "an input without a data column, held at one value over each run" in line
    assert "# FMU inputs without a column (held at one value over each run" in text


def test_the_held_input_is_identified_with_the_parameters(held, tmp_path):
    fmu, data = held
    study = Study(
        fmu=fmu,
        parameters=[
            Parameter("tau", [0.1, 0.3, 1.0], min=0.0),
            Parameter("x0", [-1.0, 0.0, 1.0]),
            Parameter("u", [-1.0, 0.0, 1.0]),
        ],
        experiments=[Experiment(data=data, inputs={}, outputs={"y": "y"})],
        method=Method(cost="sse", weighting="noise", replicates=1),  # as tsid init writes
    )
    res = identify(study, tmp_path / "out", plots=False, workers=1, timeout=0)
    assert res.status == 0, res.message
    truth = {"tau": 0.37, "x0": 0.8, "u": 0.7}
    for name, value in truth.items():
        assert abs(res.params[name] / value - 1) < 0.01, res.params
        low, high = res.intervals[name]
        assert low <= value <= high, (name, low, high)


def test_an_input_fed_by_data_cannot_also_be_a_parameter(held):
    with pytest.raises(FMUError, match="'u' is both an input from the data and a parameter"):
        FMUSession(held[0], ["u"], ["y"], parameters=["u", "tau"])
