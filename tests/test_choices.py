"""Discrete factors in a study: ``choices`` for FMU Integer, Boolean and Enumeration
variables, checked against the model description, written and read back; and the FMU
session giving a run whose structure changed a fresh instance."""

from __future__ import annotations

import dataclasses
import string
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, lag_response
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tsid_fmu import ArrayError, Choice, Experiment, Parameter, Study, StudyError
from tsid_fmu.fmu import FMUSession

DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Switches" guid="{0}"
    variableNamingConvention="flat">
  <CoSimulation modelIdentifier="Switches"/>
  <TypeDefinitions>
    <SimpleType name="FrictionLaw">
      <Enumeration>
        <Item name="coulomb" value="1"/>
        <Item name="viscous" value="2"/>
        <Item name="stribeck" value="3"/>
      </Enumeration>
    </SimpleType>
  </TypeDefinitions>
  <ModelVariables>
    <ScalarVariable name="friction" valueReference="0" causality="parameter"
        variability="fixed" initial="exact"><Enumeration declaredType="FrictionLaw" start="2"/>
    </ScalarVariable>
    <ScalarVariable name="damping_on" valueReference="1" causality="parameter"
        variability="fixed" initial="exact"><Boolean start="false"/></ScalarVariable>
    <ScalarVariable name="masses" valueReference="2" causality="parameter"
        variability="fixed" initial="exact"><Integer start="1"/></ScalarVariable>
    <ScalarVariable name="K" valueReference="3" causality="parameter"
        variability="fixed" initial="exact"><Real start="1"/></ScalarVariable>
    <ScalarVariable name="mode" valueReference="4" causality="local"
        variability="discrete" initial="exact"><Integer start="0"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="5" causality="output"
        variability="continuous"><Real/></ScalarVariable>
    <ScalarVariable name="D" valueReference="6" causality="parameter"
        variability="fixed" initial="exact"><Real start="1"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="6"/></Outputs></ModelStructure>
</fmiModelDescription>
"""


def _switches(folder: Path) -> Path:
    """An FMU archive with only its model description (enough to check a study)."""
    fmu = folder / "Switches.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", DESCRIPTION.format("{1234}"))
    return fmu


def _study(folder: Path, *choices: Choice) -> Study:
    data = folder / "d.csv"
    data.write_text("time,y\n0,0\n1,1\n")
    return Study(
        fmu=_switches(folder),
        parameters=[Parameter("D", [1.0, 2.0, 3.0]), *choices],
        experiments=[Experiment(data, outputs={"y": "y"})],
    )


def test_choices_resolve_to_the_values_the_fmu_takes(tmp_path):
    s = _study(
        tmp_path,
        Choice("friction", ["coulomb", "stribeck"]),
        Choice("damping_on", [True, False]),
        Choice("masses", [1, 2, 3]),
    )
    assert [c.name for c in s.choices] == ["friction", "damping_on", "masses"]
    assert s.parameter_names == ["D"]
    assert [c.values for c in s.choices] == [[1.0, 3.0], [1.0, 0.0], [1.0, 2.0, 3.0]]
    assert s.choices[0].labels == ["coulomb", "stribeck"]


@pytest.mark.parametrize(
    ("choice", "message"),
    [
        (Choice("frction", ["coulomb", "viscous"]), "'frction': the FMU has no variable.*'fri"),
        (Choice("friction", ["coulomb", "stribek"]), "'friction': 'stribek' is not an item of its "
         "Enumeration type FrictionLaw \\(items: coulomb, viscous, stribeck\\)"),
        (Choice("friction", [1, 7]), "'friction': 7 is not a value of its Enumeration"),
        (Choice("K", [1, 2]), "'K' is a Real variable: give it levels"),
        (Choice("damping_on", [0, 2]), "'damping_on': a Boolean takes true or false, got 2"),
        (Choice("masses", [True, False]), "'masses': an Integer variable takes integers"),
        (Choice("mode", [0, 1]), "'mode' has causality 'local'"),
    ],
)  # fmt: skip
def test_a_wrong_choice_is_refused_naming_the_parameter(tmp_path, choice, message):
    with pytest.raises(StudyError, match=message):
        _study(tmp_path, choice)


@pytest.mark.parametrize(
    ("choices", "message"),
    [
        ([1], "'x': needs at least 2 choices"),
        ([1, 1], "'x': choices must be distinct"),
        ([1, "a"], "'x': choices must be all integers"),
        ([1.5, 2], "'x': choices must be all integers"),
    ],
)
def test_a_choice_needs_two_distinct_values_of_one_kind(choices, message):
    with pytest.raises(StudyError, match=message):
        Choice("x", choices)


def test_the_study_file_gives_choices_and_refuses_them_with_levels(tmp_path):
    _switches(tmp_path)
    (tmp_path / "d.csv").write_text("time,y\n0,0\n1,1\n")
    head = '[study]\nfmu = "Switches.fmu"\n[data]\nfile = "d.csv"\noutputs = { y = "y" }\n'
    path = tmp_path / "s.toml"
    path.write_text(
        head + "[parameters]\nK = { levels = [1, 2, 3] }\n"
        'friction = { choices = ["coulomb", "stribeck"] }\n'
        "damping_on = { choices = [true, false] }\n"
    )
    s = Study.from_toml(path)
    assert [c.choices for c in s.choices] == [["coulomb", "stribeck"], [True, False]]
    path.write_text(head + "[parameters]\nK = { levels = [1, 2, 3] }\n"
                    "masses = { choices = [1, 2], levels = [1, 2] }\n")  # fmt: skip
    with pytest.raises(StudyError, match="masses gives choices and levels"):
        Study.from_toml(path)


def test_five_level_parameters_beside_two_choices_have_no_array_and_the_error_says_why(tmp_path):
    with pytest.raises(ArrayError, match="give the Real parameters 3 levels"):
        Study(
            fmu=_switches(tmp_path),
            parameters=[Parameter("K", [1, 2, 3, 4, 5]), Choice("masses", [1, 2]),
                        Choice("damping_on", [True, False])],
            experiments=[Experiment(tmp_path / "d.csv", outputs={"y": "y"})],
        )  # fmt: skip


NAME = st.text(string.ascii_letters, min_size=1, max_size=5)
CHOICES = st.sampled_from(
    [
        Choice("friction", ["coulomb", "viscous", "stribeck"]),
        Choice("friction", ["stribeck", "coulomb"]),
        Choice("friction", [1, 3]),
        Choice("damping_on", [True, False]),
        Choice("damping_on", [False, True]),
        Choice("masses", [3, 1]),
        Choice("masses", [1, 2, 3]),
    ]
)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(CHOICES, min_size=1, max_size=3, unique_by=lambda c: c.name))
def test_a_study_with_choices_reads_back_equal_from_its_toml(choices):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp).resolve()
        s = _study(folder, *[Choice(c.name, list(c.choices)) for c in choices])
        back = Study.from_toml(s.to_toml(folder / "out" / "study.toml"))
        assert back == s
        assert [c.values for c in back.choices] == [c.values for c in s.choices]


def test_a_changed_discrete_fixed_value_gets_a_fresh_instance(tmp_path):
    fmu = build_c_fmu(tmp_path, "Lag", interfaces=("cs",))
    t = np.arange(0, 1.0 + 1e-9, 0.01)
    u = np.where(t < 0.5, 1.0, 0.0)
    with FMUSession(fmu, ["u"], ["y"], parameters=["tau", "gain", "offset_on"]) as s:
        runs = [
            {"tau": 0.3, "gain": 1, "offset_on": 0},
            {"tau": 0.3, "gain": 1, "offset_on": 0},  # same structure: reset
            {"tau": 0.5, "gain": 1, "offset_on": 0},  # a Real fixed value: reset
            {"tau": 0.5, "gain": 1, "offset_on": 1},  # the switch: a fresh instance
            {"tau": 0.5, "gain": 2, "offset_on": 1},  # the Integer: a fresh instance
        ]
        made = []
        for p in runs:
            y = s.simulate(t, u[:, None], p)[:, 0]
            expected = lag_response(t, u, p["tau"], 0.0, p["gain"], float(p["offset_on"]))
            assert np.allclose(y, expected, atol=1e-12)
            made.append(s.instantiations)
    assert made == [1, 1, 1, 2, 3]


def test_a_study_of_choices_sets_the_chosen_values_through_start_values(tmp_path):
    fmu = build_c_fmu(tmp_path, "Lag", interfaces=("cs",))
    t = np.arange(0, 1.0 + 1e-9, 0.01)
    u = np.where(t < 0.5, 1.0, 0.0)
    with FMUSession(fmu, ["u"], ["y"], start_values={"offset_on": 1.0, "gain": 3.0}) as s:
        y = s.simulate(t, u[:, None], {})[:, 0]
    assert np.allclose(y, lag_response(t, u, 1.0, 0.0, 3, 1.0), atol=1e-12)
    assert pd.Series(y).notna().all()


def test_init_writes_discrete_parameters_commented_out_with_their_choices(tmp_path):
    from tsid_fmu.scaffold import init_study

    fmu = build_c_fmu(tmp_path, "Lag", interfaces=("cs",))
    t = np.arange(0, 1.0 + 1e-9, 0.01)
    u = np.where(t < 0.5, 1.0, 0.0)
    frame = pd.DataFrame({"time": t, "u": u, "y": lag_response(t, u, 0.3)})
    frame.to_csv(tmp_path / "d.csv", index=False)
    text = init_study(fmu, tmp_path / "d.csv", tmp_path / "study.toml")
    assert "# gain = { choices = [1, 2] }  # Integer (start 1)" in text
    assert "# offset_on = { choices = [false, true] }  # Boolean (start false)" in text
    written = (tmp_path / "study.toml").read_text()
    opened = written.replace("# offset_on = {", "offset_on = {").replace('"L25"', '"L50"')
    (tmp_path / "opened.toml").write_text(opened)
    study = Study.from_toml(tmp_path / "opened.toml")  # uncommented, a hint runs as written
    assert {c.name: c.values for c in study.choices} == {"offset_on": [0.0, 1.0]}
    assert 'array = "L50" for one 2-level choice' in text  # as the hint says


def test_init_offers_an_enumeration_its_items():
    from tsid_fmu.fmu.variables import VariableInfo
    from tsid_fmu.scaffold import _choice_line

    v = VariableInfo("friction", 0, "Enumeration", "parameter", "fixed", "exact", "2", "", "")
    line = _choice_line(dataclasses.replace(v, items=("coulomb", "viscous", "stribeck")))
    assert line.startswith('# friction = { choices = ["coulomb", "viscous", "stribeck"] }')
