"""FMI 3 array variables: shown as arrays, never silently compared by their first element.

PythonFMU3's ``FMU3Model`` has an output ``vector`` of 5 elements; ``info`` showed a
scalar, ``init`` mapped one column to it and ``identify`` compared element 0, with a
noise estimate 66 times the truth and no warning (issue 43).
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tsid_fmu.errors import FMUError
from tsid_fmu.fmu import FMUSession
from tsid_fmu.fmu.info import fmu_info
from tsid_fmu.scaffold import init_study

_XML = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="Arrays" instantiationToken="{1}">
  <CoSimulation modelIdentifier="Arrays"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Float64 name="u" valueReference="1" causality="input" start="0"/>
    <Float64 name="k" valueReference="2" causality="parameter" variability="fixed" start="1"/>
    <Float64 name="y" valueReference="3" causality="output"/>
    <Float64 name="vector" valueReference="4" causality="output"><Dimension start="5"/></Float64>
  </ModelVariables>
  <ModelStructure><Output valueReference="3"/><Output valueReference="4"/></ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture
def arrays(tmp_path) -> tuple[Path, Path]:
    fmu = tmp_path / "Arrays.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", _XML)
    t = np.arange(0, 1.0, 0.01)
    data = tmp_path / "d.csv"
    pd.DataFrame({"time": t, "u": t, "y": t, "vector": t}).to_csv(data, index=False)
    return fmu, data


def test_info_shows_the_dimensions(arrays):
    line = next(x for x in fmu_info(arrays[0]).splitlines() if x.strip().startswith("vector"))
    assert "Float64[5]" in line


def test_init_maps_no_column_to_an_array_output(arrays, tmp_path):
    text = init_study(*arrays, tmp_path / "study.toml")
    outputs = next(x for x in text.splitlines() if x.startswith("outputs = "))
    assert "y" in outputs and "vector" not in outputs


def test_a_session_refuses_an_array_output_by_name(arrays):
    with pytest.raises(FMUError, match=r"output 'vector' is an array variable \(5 elements\)"):
        FMUSession(arrays[0], ["u"], ["vector"], parameters=["k"])
