"""Input delays ``delay(<input>)`` and initial states as identified parameters.

The delay data come from an exact solution of the lag ``tau y' = u(t - d) - y`` by
``solve_ivp`` on the continuous input (not from the FMU), sampled at 10 ms with a delay of
1.37 samples, so that only a sub-sample shift of the input explains them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu
from scipy.integrate import solve_ivp

import tsid_fmu
from tsid_fmu import Experiment, Parameter, Study, identify
from tsid_fmu.errors import FMUError, StudyError
from tsid_fmu.fmu.delay import delay_input, delayed_inputs, split_delays

REPO = Path(__file__).resolve().parents[1]
TAU, DELAY, NOISE = 0.2, 0.0137, 0.002


def signal(t: np.ndarray) -> np.ndarray:
    """A smooth input: three sinusoids between 0.4 and 2.9 Hz."""
    return np.sin(2.5 * t) + 0.5 * np.sin(7.3 * t + 1.0) + 0.3 * np.sin(18.0 * t + 2.0)


def test_names_and_split():
    assert delay_input("delay(F_m)") == "F_m" and delay_input("delay( u )") == "u"
    assert delay_input("tau") is None and delay_input("delay(a)(b)") is None
    assert split_delays({"tau": 1.0, "delay(u)": 0.5}) == ({"tau": 1.0}, {"u": 0.5})


def test_delayed_inputs_shift_a_ramp_exactly_and_average_a_step():
    t = np.arange(10) * 0.1
    u = np.column_stack([2.0 * t, (t >= 0.5).astype(float)])
    out = delayed_inputs(t, u, ("ramp", "step"), {"ramp": 0.03, "step": 0.03})
    np.testing.assert_allclose(out[1:, 0], 2.0 * (t[1:] - 0.03))  # the shifted ramp
    assert out[0, 0] == 0.0  # before the record: its first sample
    # the step's interval [0.5, 0.6) holds 0.3 of the previous value and 0.7 of the new
    np.testing.assert_allclose(out[4:7, 1], [0.0, 0.7, 1.0])
    assert delayed_inputs(t, u, ("ramp", "step"), {"ramp": 0.0}) is u  # nothing to do


@pytest.fixture(scope="module")
def lag(tmp_path_factory) -> Path:
    return build_c_fmu(tmp_path_factory.mktemp("lag"))


@pytest.fixture(scope="module")
def delayed_data(tmp_path_factory) -> Path:
    t = np.arange(0, 10.0 + 1e-9, 0.01)
    sol = solve_ivp(
        lambda s, y: (signal(s - DELAY) - y) / TAU,
        (0.0, t[-1]),
        [signal(-DELAY)],  # at rest on the (delayed) input at t = 0
        t_eval=t,
        rtol=1e-11,
        atol=1e-12,
        method="DOP853",
    )
    y = sol.y[0] + np.random.default_rng(5).normal(0, NOISE, t.size)
    path = tmp_path_factory.mktemp("data") / "delayed.csv"
    pd.DataFrame({"time": t, "u": signal(t), "y": y}).to_csv(path, index=False)
    return path


@pytest.mark.slow
def test_a_sub_sample_input_delay_is_identified(lag, delayed_data):
    study = Study(
        fmu=lag,
        parameters=[
            Parameter("tau", [0.05, 0.15, 0.5], min=0.01, unit="s"),
            Parameter("x0", [-1.0, 0.0, 1.0]),
            Parameter("delay(u)", [0.0, 0.01, 0.03], min=-0.05, max=0.05, unit="s"),
        ],
        experiments=[
            Experiment(
                data=delayed_data, inputs={"u": "u"}, outputs={"y": "y"}, hold={"u": "linear"}
            )
        ],
        cost="sse",
        weighting="noise",
        replicates=1,
        refine="least_squares",
    )
    res = identify(study, plots=False, workers=1)
    assert res.status in (0, 1), res.message
    assert res.params["delay(u)"] == pytest.approx(DELAY, abs=0.3e-3)  # 0.03 of a sample
    assert res.params["tau"] == pytest.approx(TAU, rel=0.01)
    for name, truth in (("tau", TAU), ("delay(u)", DELAY)):
        low, high = res.intervals[name]
        assert low is not None and high is not None and low <= truth <= high, (name, low, high)
    # without the delay the same model misses the data by far more than the noise
    zero = tsid_fmu.simulate(
        lag,
        pd.read_csv(delayed_data)[["time", "u"]],
        parameters={"tau": res.params["tau"], "x0": res.params["x0"]},
        hold={"u": "linear"},
    )
    shifted = tsid_fmu.simulate(
        lag,
        pd.read_csv(delayed_data)[["time", "u"]],
        parameters={n: res.params[n] for n in ("tau", "x0", "delay(u)")},
        hold={"u": "linear"},
    )
    y = pd.read_csv(delayed_data)["y"].to_numpy()
    rms = [float(np.sqrt(np.mean((f["y"].to_numpy() - y) ** 2))) for f in (zero, shifted)]
    assert rms[1] < 1.2 * NOISE < 3 * NOISE < rms[0], rms


def test_a_delay_of_an_unknown_input_is_a_clear_error(lag, delayed_data):
    frame = pd.read_csv(delayed_data)[["time", "u"]]
    with pytest.raises(StudyError, match=r"'delay\(v\)': 'v' is not an input of"):
        tsid_fmu.simulate(lag, frame, parameters={"tau": 0.2, "delay(v)": 0.01})
    study = Study(
        fmu=lag,
        parameters=[Parameter("delay(w)", [0.0, 0.01])],
        experiments=[Experiment(data=delayed_data, inputs={"u": "u"}, outputs={"y": "y"})],
        max_iterations=1,
    )
    with pytest.raises(StudyError, match=r"'w' is not an input of experiment"):
        identify(study, plots=False, workers=1)


def test_an_initial_state_is_identified_like_a_parameter(tmp_path):
    """LSEA_SISO's motor position ``x_m`` (local, continuous, initial exact) is set before
    initialization: with no motor force the nut stays stuck by friction (K_s x_m = 8.6 N
    is below F_cm = 88.5 N), so F_o = K_s x_m throughout."""
    fmu = REPO / "fmus" / "LSEA_SISO.fmu"
    t = np.arange(0, 0.2 + 1e-9, 1e-3)
    frame = pd.DataFrame({"time": t, "F_m": np.zeros_like(t)})
    out = tsid_fmu.simulate(fmu, frame, outputs=["F_o"], parameters={"x_m": 0.001})
    np.testing.assert_allclose(out["F_o"], 8600.0 * 0.001, rtol=1e-9)
    rng = np.random.default_rng(2)
    frame["F_o"] = 8600.0 * 0.0012 + rng.normal(0, 0.05, t.size)
    frame.to_csv(tmp_path / "rest.csv", index=False)
    study = Study(
        fmu=fmu,
        parameters=[Parameter("x_m", [0.0, 0.0005, 0.002], unit="m")],
        experiments=[
            Experiment(data=tmp_path / "rest.csv", inputs={"F_m": "F_m"}, outputs={"F_o": "F_o"})
        ],
        cost="sse",
        replicates=1,
    )
    res = identify(study, plots=False, workers=1)
    assert res.params["x_m"] == pytest.approx(0.0012, rel=2e-3)
    with pytest.raises(FMUError, match=r"'der\(x_m\)' .*cannot be"):
        tsid_fmu.simulate(fmu, frame[["time", "F_m"]], parameters={"der(x_m)": 0.1})
