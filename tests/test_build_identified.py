"""``tsid build --from-result DIR``: the study's FMU rebuilt with the identified values.

Needs pymoca, casadi and a C compiler, like the other build tests. The result folders
are made by :func:`tsid_fmu.report.ssp.write_ssp` (what ``identify`` writes as
``model.ssp``), so no identification runs here.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("pymoca")
pytest.importorskip("casadi")
if shutil.which("gcc") is None and shutil.which("cc") is None:
    pytest.skip("no C compiler", allow_module_level=True)

from fmpy import read_model_description
from fmpy.validation import validate_fmu
from fmu_factory import build_c_fmu, copy_without

import tsid_fmu
from tsid_fmu.build import build_fmu, build_from_result
from tsid_fmu.cli import main
from tsid_fmu.errors import BuildError
from tsid_fmu.report.ssp import write_ssp

ROOT = Path(__file__).resolve().parents[1]
SISO = {"F_cm": 80.0, "F_vm": 45.0, "M_m": 4.0, "K_s": 8000.0, "B_s": 3.0, "V_z": 0.001}
MISO = {"m1": 0.5, "K_s": 4500.0, "C_d": 4.0, "C_1": 18.0, "m2": 0.25, "C_2": 1.5}


def _starts(path: Path) -> dict[str, float]:
    md = read_model_description(str(path))
    return {v.name: float(v.start) for v in md.modelVariables if v.causality == "parameter"}


@pytest.mark.slow
@pytest.mark.parametrize(
    ("fmu", "values", "inputs"),
    [
        (ROOT / "fmus" / "LSEA_SISO.fmu", SISO, ["F_m"]),
        (ROOT / "fmus" / "fmi3" / "LSEA_MISO.fmu", MISO, ["F_m", "x_o", "v_o", "a_o"]),
    ],
)
def test_rebuilt_fmu_has_the_values_a_new_guid_and_simulates_alike(tmp_path, fmu, values, inputs):
    result = tmp_path / "result"
    write_ssp(result / "model.ssp", fmu, values)
    rebuilt = build_from_result(result)
    ident = fmu.stem
    assert rebuilt == result / f"{ident}_identified.fmu"
    assert validate_fmu(str(rebuilt)) == []
    old, new = read_model_description(str(fmu)), read_model_description(str(rebuilt))
    assert new.fmiVersion == old.fmiVersion and new.modelName == old.modelName
    assert new.guid != old.guid
    assert [v.name for v in new.modelVariables] == [v.name for v in old.modelVariables]
    starts = _starts(rebuilt)
    assert {k: starts[k] for k in values} == values
    assert starts["fixedStepSize"] == _starts(fmu)["fixedStepSize"]
    # the rebuilt FMU with its own start values = the original with the values set
    t = np.arange(1001) * 1e-3
    data = pd.DataFrame({"time": t, **{n: 0.0 for n in inputs}})
    data["F_m"] = 150.0 * np.sign(np.sin(2 * np.pi * 2 * t))
    if "x_o" in inputs:
        data["x_o"], data["v_o"] = 1e-3 * np.sin(5 * t), 5e-3 * np.cos(5 * t)
    kw = {"inputs": {n: n for n in inputs}, "outputs": ["F_o"]}
    ours = tsid_fmu.simulate(rebuilt, data, **kw)
    theirs = tsid_fmu.simulate(fmu, data, parameters=values, **kw)
    np.testing.assert_array_equal(ours["F_o"].to_numpy(), theirs["F_o"].to_numpy())
    # reproducible: the same result folder gives the same bytes
    again = build_from_result(result, tmp_path / "again")
    assert again.read_bytes() == rebuilt.read_bytes()


def test_cli_from_result_and_its_errors(tmp_path, capsys):
    result = tmp_path / "r"
    write_ssp(result / "model.ssp", ROOT / "fmus" / "LSEA_SISO.fmu", {"K_s": 7000.0})
    assert main(["build", "--from-result", str(result), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out.strip()
    assert out == str(tmp_path / "o" / "LSEA_SISO_identified.fmu")
    assert _starts(Path(out))["K_s"] == 7000.0
    assert main(["build", "--from-result", str(tmp_path / "missing")]) == 1
    assert "model.ssp: not found" in capsys.readouterr().err


def test_only_fmus_built_by_tsid_from_modelica_are_rebuilt(tmp_path):
    other = build_c_fmu(tmp_path, "Lag", interfaces=("cs",))
    write_ssp(tmp_path / "r" / "model.ssp", other, {"tau": 0.3})
    with pytest.raises(BuildError, match="not by tsid-fmu; only FMUs built from Modelica"):
        build_from_result(tmp_path / "r")
    bare = copy_without(ROOT / "fmus" / "LSEA_SISO.fmu", tmp_path / "LSEA_SISO.fmu", "resources/")
    write_ssp(tmp_path / "s" / "model.ssp", bare, {"K_s": 7000.0})
    with pytest.raises(BuildError, match=r"resources/LSEA_SISO\.mo is missing"):
        build_from_result(tmp_path / "s")


def test_unknown_start_value_is_refused(tmp_path):
    with pytest.raises(BuildError, match="has no parameter or state named 'K_x'"):
        build_fmu(
            ROOT / "models" / "TSID" / "LSEA_SISO.mo",
            "TSID.LSEA_SISO",
            tmp_path / "x.fmu",
            start_values={"K_x": 1.0},
        )
