"""``tsid init`` writes studies that work (issue 24, item 6).

Numerical settings (steps, tolerances, thresholds) are written commented out, the
levels respect the bounds the FMU declares, and an FMU input or output that the data
hold only in parts gets a ``--derived`` proposal. Every study written here is read back
with :meth:`tsid_fmu.Study.from_toml`.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pandas as pd

from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.variables import variable_info

REPO = Path(__file__).resolve().parents[1]
SISO = REPO / "examples" / "lsea_siso"
MISO = REPO / "examples" / "lsea_miso"

_BALL = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Ball" guid="{1}">
  <CoSimulation modelIdentifier="Ball"/>
  <TypeDefinitions><SimpleType name="Share"><Real min="0" max="1"/></SimpleType></TypeDefinitions>
  <ModelVariables>
    <ScalarVariable name="h" valueReference="0" causality="output" variability="continuous">
      <Real unit="m"/></ScalarVariable>
    <ScalarVariable name="e" valueReference="1" causality="parameter" variability="fixed"
      initial="exact" description="Coefficient of restitution"><Real start="0.7" min="0.5"
      max="1"/></ScalarVariable>
    <ScalarVariable name="loss" valueReference="2" causality="parameter" variability="fixed"
      initial="exact"><Real declaredType="Share" start="0.3"/></ScalarVariable>
    <ScalarVariable name="g" valueReference="3" causality="parameter" variability="fixed"
      initial="exact"><Real unit="m/s2" start="-9.81" max="-9"/></ScalarVariable>
    <ScalarVariable name="v_min" valueReference="4" causality="parameter" variability="fixed"
      initial="exact" description="Velocity below which the ball is considered at rest">
      <Real unit="m/s" start="0.01" min="0"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1"/></Outputs></ModelStructure>
</fmiModelDescription>
"""


def _ball(tmp_path: Path) -> tuple[Path, Path]:
    """A bouncing ball's model description (no binaries: init reads the description only)."""
    fmu = tmp_path / "Ball.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", _BALL)
    t = np.arange(0.0, 2.0, 0.01)
    data = tmp_path / "ball.csv"
    pd.DataFrame({"time": t, "h": np.abs(np.sin(3 * t))}).to_csv(data, index=False)
    return fmu, data


def test_variable_info_carries_the_declared_bounds(tmp_path):
    fmu, _ = _ball(tmp_path)
    infos = {v.name: variable_info(v) for v in read_fmu_description(fmu).modelVariables}
    assert (infos["e"].min, infos["e"].max) == (0.5, 1.0)
    assert (infos["loss"].min, infos["loss"].max) == (0.0, 1.0)  # from its declared type
    assert (infos["g"].min, infos["g"].max) == (None, -9.0)
    assert (infos["h"].min, infos["h"].max) == (None, None)
