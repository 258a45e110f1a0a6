"""The identified model as an SSP 1.0 package: ``model.ssp`` of every study.

Small, fast variants of both examples (a second of data, one Taguchi iteration) are
identified; their ``model.ssp`` is checked against the SSP 1.0 schemas (FMPy's copies)
and simulated with FMPy's SSP importer (``fmpy.ssp.simulation.simulate_ssp``, which
reads the parameter binding through ``read_ssd``), and its output compared with
``tsid_fmu.simulate`` at the identified values.

How FMPy's SSP master steps (a Jacobi scheme over the system's connections): in the
iteration at time ``t_k`` the component computes with the input value copied from the
system connector in the iteration before, ``u_{k-1}`` (0 in the first one), and the
recorded output is read right after the step. Both plants start at rest, where zero
input keeps them at rest, so the recorded states coincide with ours at ``t_k``; an
output with direct feed-through (the MISO load-cell force depends on the stage motion)
is then ``y(x_k, u_{k-1})`` where ``tsid_fmu.simulate`` reports ``y(x_k, u_k)``; the
difference is exactly ``D (u_k - u_{k-1})`` with the feed-through ``D`` of the model's
output equation, which the MISO comparison adds back.
"""

from __future__ import annotations

import dataclasses
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmpy.ssp.simulation import simulate_ssp
from fmpy.ssp.ssd import read_ssd

import tsid_fmu
from tsid_fmu import Experiment, Study, identify
from tsid_fmu.report.ssp import model_ssp, validate_ssp, write_ssp
from tsid_fmu.study import load_study

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def _fast(study: Study, experiment: Experiment, **method) -> Study:
    """The study on one short experiment: one Taguchi iteration, no refinement."""
    fields = {f.name: getattr(study, f.name) for f in dataclasses.fields(study)}
    fields.update(
        experiments=[experiment],
        method=dataclasses.replace(
            study.method, max_iterations=1, refine="none", replicates=1, **method
        ),
        phases=[],
        contribution=dataclasses.replace(study.contribution, enabled=False),
    )
    return Study(**fields)


def _ssp_run(path: Path, frame: pd.DataFrame, inputs: list[str]) -> np.ndarray:
    """Simulate an SSP with FMPy's importer, the inputs held per sample of ``frame``."""
    ssd = read_ssd(str(path))  # validates the SSD and reads the bound .ssv
    (component,) = ssd.system.elements
    (binding,) = component.parameterBindings
    (values,) = binding.parameterValues
    # the binding applies to the component; FMPy's simulate_ssp takes one parameter set
    # whose names start with the component's path
    for p in values.parameters:
        p.name = f"{component.name}.{p.name}"
    t = frame["time"].to_numpy()
    dt = float(t[1] - t[0])

    def held(column: str):
        u = frame[column].to_numpy()
        return lambda time: float(u[min(np.searchsorted(t, time + dt / 2) - 1, t.size - 1)])

    res = simulate_ssp(
        str(path),
        start_time=float(t[0]),
        stop_time=float(t[-1]),
        step_size=dt,
        parameter_set=values,
        input={name: held(name) for name in inputs},
    )
    # FMPy adds up the step: the last sample may or may not get a row
    assert len(res) >= t.size - 1
    np.testing.assert_allclose(res["time"][: t.size - 1], t[:-1], rtol=0, atol=1e-9)
    return res["F_o"][: t.size - 1]


def _identified(result) -> dict[str, float]:
    return {**result.params, **result.study.start_values}


@pytest.mark.slow
def test_siso_model_ssp_simulates_like_tsid(tmp_path):
    study = load_study(EXAMPLES / "lsea_siso" / "study.toml")
    data = pd.read_csv(EXAMPLES / "lsea_siso" / "measured.csv").iloc[:1001]
    data = data.assign(F_o=data["F_of"] - data["F_or"])
    exp = Experiment(data=data, inputs={"F_m": "F_m"}, outputs={"F_o": "F_o", "x_m": "x_m"})
    res = identify(_fast(study, exp), tmp_path / "out", plots=False)
    ssp = tmp_path / "out" / "model.ssp"
    assert validate_ssp(ssp) == []
    with zipfile.ZipFile(ssp) as z:
        assert z.namelist() == [
            "SystemStructure.ssd",
            "resources/LSEA_SISO.fmu",
            "resources/LSEA_SISO.ssv",
        ]
        assert z.read("resources/LSEA_SISO.fmu") == (ROOT / "fmus" / "LSEA_SISO.fmu").read_bytes()
    values = _identified(res)
    assert set(values) == {"F_cm", "F_vm", "M_m", "K_s", "B_s", "V_z"}
    theirs = _ssp_run(ssp, data, ["F_m"])
    ours = tsid_fmu.simulate(
        study.fmu, data, inputs={"F_m": "F_m"}, outputs=["F_o"], parameters=values
    )["F_o"].to_numpy()[:-1]
    scale = np.max(np.abs(ours))
    assert np.max(np.abs(theirs - ours)) <= 1e-9 * scale
    # the values matter: the FMU's own defaults give another output
    default = tsid_fmu.simulate(study.fmu, data, inputs={"F_m": "F_m"}, outputs=["F_o"])
    assert np.max(np.abs(default["F_o"].to_numpy()[:-1] - ours)) > 1e-3 * scale


@pytest.mark.slow
def test_miso_model_ssp_simulates_like_tsid(tmp_path):
    study = load_study(EXAMPLES / "lsea_miso" / "study.toml")
    raw = pd.read_csv(EXAMPLES / "lsea_miso" / "combined.csv").iloc[:801]
    t = raw["time"].to_numpy()
    v_o = np.gradient(raw["x_o"].to_numpy(), t)
    data = raw.assign(F_o=raw["F_of"] - raw["F_or"], v_o=v_o, a_o=np.gradient(v_o, t))
    inputs = ["F_m", "x_o", "v_o", "a_o"]
    exp = Experiment(data=data, inputs={n: n for n in inputs}, outputs={"F_o": "F_o"})
    res = identify(_fast(study, exp), tmp_path / "out", plots=False)
    ssp = tmp_path / "out" / "model.ssp"
    assert validate_ssp(ssp) == []
    values = _identified(res)
    theirs = _ssp_run(ssp, data, inputs)
    ours = tsid_fmu.simulate(
        study.fmu, data, inputs={n: n for n in inputs}, outputs=["F_o"], parameters=values
    )["F_o"].to_numpy()[:-1]
    # F_o = K_s (x - x_o) + C_d (v - v_o) - C_2 v_o - m2 a_o: feed-through of the motion
    d = np.array([0.0, -values["K_s"], -(values["C_d"] + values["C_2"]), -values["m2"]])
    u = data[inputs].to_numpy()[:-1]
    previous = np.vstack([np.zeros((1, len(inputs))), u[:-1]])
    scale = np.max(np.abs(ours))
    assert np.max(np.abs(theirs - (ours - (u - previous) @ d))) <= 1e-9 * scale
    assert np.max(np.abs(theirs - ours)) > 1e-6 * scale  # the feed-through is really there


def test_ssp_is_reproducible_typed_and_validated(tmp_path):
    fmu = ROOT / "fmus" / "fmi3" / "LSEA_MISO.fmu"
    values = {"K_s": 4000.0, "m1": 0.5}
    a = write_ssp(tmp_path / "a.ssp", fmu, values, name="x")
    assert a.read_bytes() == model_ssp(fmu, values, name="x")
    assert validate_ssp(a) == []
    with zipfile.ZipFile(a) as z:
        ssd = z.read("SystemStructure.ssd").decode()
        ssv = z.read("resources/LSEA_MISO.ssv").decode()
    for port in ("F_m", "x_o", "v_o", "a_o"):
        assert f'name="{port}" kind="input"' in ssd
    assert 'name="F_o" kind="output"' in ssd and 'unit="m/s2"' in ssd
    assert '<ssv:Real value="4000.0"' in ssv
    # a broken document is reported, naming the file and line
    bad = tmp_path / "bad.ssp"
    with zipfile.ZipFile(a) as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename.endswith(".ssd"):
                data = data.replace(b'kind="input"', b'kind="sideways"', 1)
            dst.writestr(item, data)
    problems = validate_ssp(bad)
    assert problems and problems[0].startswith("SystemStructure.ssd:")


def test_unknown_value_is_refused(tmp_path):
    with pytest.raises(tsid_fmu.errors.FMUError, match="no variable 'K_x'"):
        model_ssp(ROOT / "fmus" / "LSEA_SISO.fmu", {"K_x": 1.0})
