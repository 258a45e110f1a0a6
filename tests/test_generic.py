"""Nothing in the engine knows the project's plants: it identifies other FMUs too."""

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_pythonfmu, pythonfmu_available

from tsid_fmu import identify
from tsid_fmu.build import build_fmu
from tsid_fmu.fmu import FMUSession
from tsid_fmu.study import Experiment, Parameter, Study

# both tests identify a study end to end
pytestmark = pytest.mark.slow

SECOND_ORDER = """
model SecondOrder "Plain second-order system, written only in a test"
  parameter Real zeta = 0.5 "Damping ratio";
  parameter Real omega(unit = "rad/s") = 5 "Natural frequency";
  input Real u(start = 0) "Input";
  output Real y "Output";
  Real x(start = 0, fixed = true);
  Real v(start = 0, fixed = true);
equation
  der(x) = v;
  der(v) = omega * omega * (u - x) - 2 * zeta * omega * v;
  y = x;
end SecondOrder;
"""


def _data(fmu, truth, path, t, u, noise=0.01):
    with FMUSession(fmu, ["u"], ["y"], parameters=list(truth)) as s:
        y = s.simulate(t, u[:, None], truth)[:, 0]
    y = y + np.random.default_rng(3).normal(0, noise * np.abs(y).max(), y.shape)
    pd.DataFrame({"time": t, "u": u, "y_meas": y}).to_csv(path, index=False)


def test_damping_ratio_and_natural_frequency_of_a_second_order_fmu(tmp_path):
    mo = tmp_path / "SecondOrder.mo"
    mo.write_text(SECOND_ORDER)
    fmu = build_fmu(mo, "SecondOrder", tmp_path / "SecondOrder.fmu")
    t = np.round(np.arange(0, 8.0 + 1e-9, 0.005), 9)
    u = np.where((t % 4.0) < 2.0, 1.0, -1.0) + 0.5 * np.sin(1.3 * t)
    truth = {"zeta": 0.23, "omega": 7.4}
    _data(fmu, truth, tmp_path / "so.csv", t, u)
    study = Study(
        fmu=fmu,
        parameters=[
            Parameter("zeta", [0.05, 0.4, 1.0], min=0.0),
            Parameter("omega", [2.0, 6.0, 12.0], min=0.1),
        ],
        experiments=[
            Experiment(data=tmp_path / "so.csv", inputs={"u": "u"}, outputs={"y": "y_meas"})
        ],
        seed=4,
    )
    res = identify(study, tmp_path / "out", plots=False)
    assert res.params["zeta"] == pytest.approx(truth["zeta"], rel=0.02)
    assert res.params["omega"] == pytest.approx(truth["omega"], rel=0.01)


@pytest.mark.skipif(not pythonfmu_available(), reason="pythonfmu cannot build FMUs here")
def test_an_fmu_exported_by_another_tool(tmp_path):
    """A Co-Simulation FMU made with the pythonfmu package (its own C wrapper, Python slave)."""
    fmu = build_pythonfmu(tmp_path)
    t = np.round(np.arange(0, 3.0 + 1e-9, 0.01), 9)
    u = np.where((t % 1.5) < 0.75, 1.0, 0.0)
    _data(fmu, {"tau": 0.35}, tmp_path / "py.csv", t, u)
    study = Study(
        fmu=fmu,
        parameters=[Parameter("tau", [0.1, 0.5, 1.0], min=0.01)],
        experiments=[
            Experiment(data=tmp_path / "py.csv", inputs={"u": "u"}, outputs={"y": "y_meas"})
        ],
        replicates=1,
        input_noise=0.0,
        max_iterations=10,
    )
    res = identify(study, tmp_path / "out", plots=False, workers=1)
    assert res.params["tau"] == pytest.approx(0.35, rel=0.02)
