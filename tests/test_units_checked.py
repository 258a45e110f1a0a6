"""A parameter's unit is checked against the FMU's declared one (issue 64).

``unit = "kN/mm"`` on the SISO plant's K_s (declared in N/m) passed as a label while
the levels went to the FMU as N/m: a value off by 1e6, silently.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from tsid_fmu import Study, identify
from tsid_fmu.errors import StudyError
from tsid_fmu.study.unitcheck import check_units, parse_unit
from tsid_fmu.study.units import fmu_units

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "examples" / "lsea_siso" / "study.toml"


def _with_unit(name: str, unit: str) -> Study:
    study = Study.from_toml(STUDY)
    params = [dataclasses.replace(p, unit=unit) if p.name == name else p for p in study.parameters]
    return dataclasses.replace(study, parameters=params)


def test_a_unit_at_another_scale_is_refused_before_any_simulation(tmp_path):
    with pytest.raises(StudyError) as err:
        identify(_with_unit("K_s", "kN/mm"), tmp_path / "out", plots=False)
    said = str(err.value)
    assert "K_s" in said and "'kN/mm'" in said and "'N/m'" in said and "1e+06" in said
    assert not (tmp_path / "out").exists()  # refused before the folder or a simulation


def test_another_dimension_is_refused_and_another_notation_is_not():
    declared = fmu_units(REPO / "fmus" / "LSEA_SISO.fmu")
    params = Study.from_toml(STUDY).parameters
    with pytest.raises(StudyError, match=r"'kg' is not a unit of K_s, which LSEA_SISO.fmu"):
        check_units([dataclasses.replace(params[3], unit="kg")], declared, "LSEA_SISO.fmu")
    same = [dataclasses.replace(params[1], unit=u) for u in ("N*s/m", "N s m-1", "N.s.m-1")]
    check_units(same, declared, "LSEA_SISO.fmu")  # F_vm in N.s/m, written otherwise
    check_units([dataclasses.replace(params[1], unit="lbf.s/ft")], declared, "x")  # a label
    assert parse_unit("kN/mm") == (1e6, parse_unit("N/m")[1])
    assert parse_unit("kg.m2")[1] == parse_unit("N.m.s2")[1]
    assert parse_unit("rpm") is None and parse_unit("") is None
