"""The committed Cascaded Tanks FMUs (``models/CascadedTanks.mo``) on the Est record's input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

ROOT = Path(__file__).resolve().parents[1]
FMUS = [ROOT / "fmus" / "CascadedTanks.fmu", ROOT / "fmus" / "fmi3" / "CascadedTanks.fmu"]
DATA = ROOT / "shared" / "data" / "cascaded_tanks" / "dataBenchmark.csv"
if not DATA.is_file():  # the shared data folder of the workspace
    DATA = Path("/work/shared/data/cascaded_tanks/dataBenchmark.csv")
TS = 4.0


def _est_input() -> np.ndarray:
    """The ``uEst`` column as an FMPy input signal at Ts = 4 s (a fixed stand-in without it)."""
    if DATA.is_file():
        u = np.genfromtxt(DATA, delimiter=",", names=True)["uEst"]
    else:  # pragma: no cover - data not in this checkout
        k = np.arange(1024)
        u = 2.8 + 2.5 * np.sin(2 * np.pi * k / 300) * np.sin(2 * np.pi * k / 37)
    sig = np.zeros(len(u), dtype=[("time", float), ("u", float)])
    sig["time"], sig["u"] = TS * np.arange(len(u)), u
    return sig


@pytest.mark.parametrize("fmu", FMUS, ids=["fmi2", "fmi3"])
def test_fmu_is_valid_with_parameter_initial_levels(fmu):
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    v = {x.name: x for x in md.modelVariables}
    assert [x.name for x in md.modelVariables if x.causality == "input"] == ["u"]
    assert [x.name for x in md.modelVariables if x.causality == "output"] == ["y"]
    for state, param in (("x1", "x1_0"), ("x2", "x2_0")):
        assert v[param].causality == "parameter" and v[param].variability == "fixed"
        assert v[state].initial == "approx" and float(v[state].start) == float(v[param].start)
    assert float(v["fixedStepSize"].start) == 0.5
    assert float(md.defaultExperiment.stepSize) == TS


@pytest.mark.parametrize("fmu", FMUS, ids=["fmi2", "fmi3"])
@pytest.mark.parametrize("fmi_type", ["CoSimulation", "ModelExchange"])
def test_est_input_gives_finite_outputs_in_the_sensor_range(fmu, fmi_type):
    sig = _est_input()
    stop = float(sig["time"][-1])
    kw = {"stop_time": stop, "output_interval": TS, "input": sig, "fmi_type": fmi_type}
    r = simulate_fmu(str(fmu), output=["y", "x2"], **kw)
    assert len(r) == len(sig)
    y = r["y"]
    assert np.all(np.isfinite(y)) and y.min() >= 0.0 and y.max() <= 10.0
    assert y[0] == pytest.approx(5.2) and np.ptp(y) > 1.0  # the level moves with the pump
    # the initial level follows its parameter
    r2 = simulate_fmu(str(fmu), output=["y"], start_values={"x2_0": 3.0}, **kw)
    assert r2["y"][0] == pytest.approx(3.0)
    assert np.all(np.isfinite(r2["y"])) and r2["y"].min() >= 0 and r2["y"].max() <= 10
