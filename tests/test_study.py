"""Study files: a valid file loads; every kind of mistake is a StudyError naming file and key."""

import math
import textwrap
from pathlib import Path

import pytest

from tsid_fmu.errors import StudyError
from tsid_fmu.study import Experiment, Parameter, Study, load_study

GOOD = """
[study]
name = "demo"
fmu = "plant.fmu"
start_values = { V_z = 0.001 }

[data]
file = "measured.csv"
derived = { F_o = "F_of - F_or" }
inputs = { F_m = "F_m" }
outputs = { F_o = "F_o" }

[method]
array = "L25"
cost = "iae"
replicates = 2
seed = 3

[leveling]
tolerance = 0.01
selective = true

[parameters]
F_cm = { levels = [10, 50, 80, 100, 110], min = 0, unit = "N" }
K_s = { levels = [1000, 4000, 6000, 8000, 10000], min = 1 }
"""


def write(tmp_path, text, name="study.toml"):
    (tmp_path / "plant.fmu").write_bytes(b"PK")
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_good_study_loads(tmp_path):
    s = load_study(write(tmp_path, GOOD))
    assert s.name == "demo"
    assert s.fmu == (tmp_path / "plant.fmu").resolve()
    assert s.parameter_names == ["F_cm", "K_s"]
    assert s.parameters[0].levels == [10, 50, 80, 100, 110]
    assert s.parameters[0].min == 0 and s.parameters[1].max == math.inf
    assert s.array == "L25" and s.cost == "iae" and s.replicates == 2 and s.seed == 3
    assert s.leveling.tolerance == 0.01 and s.leveling.selective
    assert s.start_values == {"V_z": 0.001}
    exp = s.experiments[0]
    assert exp.data == tmp_path / "measured.csv"
    assert exp.derived == {"F_o": "F_of - F_or"}
    assert exp.inputs == {"F_m": "F_m"} and exp.outputs == {"F_o": "F_o"}


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("[method]", "[methd]", r"unknown key 'methd' in the top level; did you mean 'method'"),
        ("replicates = 2", 'replicates = "two"', r"\[method\] replicates must be an integer"),
        ("seed = 3", "seed = 3\nsed = 1", r"unknown key 'sed' in \[method\]; did you mean 'seed'"),
        ('cost = "iae"', 'cost = "mae"', r"unknown cost 'mae'"),
        ("min = 0, unit", "min = 20, unit", r"F_cm.*levels \[10.0\] lie outside the bounds"),
        ("[10, 50, 80, 100, 110]", "[10, 10, 80]", r"F_cm.*levels must be distinct"),
        ("[10, 50, 80, 100, 110]", "[10]", r"F_cm.*at least 2 levels"),
        ('fmu = "plant.fmu"', 'fmu = "nope.fmu"', r"\[study\] fmu: no such file .*nope.fmu"),
        ("tolerance = 0.01", "tolerance = -1", r"\[leveling\] tolerance must be > 0"),
        ("tolerance = 0.01", "tolerence = 0.01", r"did you mean 'tolerance'"),
        ('outputs = { F_o = "F_o" }', "", r"\[data\] needs outputs"),
        (
            "[parameters]",
            "[parameters]\nV_z = { levels = [1, 2] }",
            r"V_z both identified and fixed",
        ),
    ],
)
def test_mistakes_name_file_and_key(tmp_path, old, new, message):
    text = GOOD.replace(old, new, 1)
    assert text != GOOD or old == new
    path = write(tmp_path, text)
    with pytest.raises(StudyError, match=message) as info:
        load_study(path)
    assert str(path) in str(info.value)


def test_not_toml_and_missing_file(tmp_path):
    with pytest.raises(StudyError, match="study file not found"):
        load_study(tmp_path / "none.toml")
    path = write(tmp_path, "[study\nfmu=")
    with pytest.raises(StudyError, match="not valid TOML"):
        load_study(path)


def test_python_api_builds_the_same_study(tmp_path):
    (tmp_path / "plant.fmu").write_bytes(b"PK")
    s = Study(
        fmu=tmp_path / "plant.fmu",
        parameters=[Parameter("k", [1, 2, 3], min=0)],
        experiments=[Experiment(data=tmp_path / "d.csv", inputs={"u": "u"}, outputs={"y": "y"})],
        cost="SSE",
    )
    assert s.cost == "sse" and s.first_levels() == {"k": [1.0, 2.0, 3.0]}
    with pytest.raises(StudyError, match="listed twice"):
        Study(
            fmu=tmp_path / "plant.fmu",
            parameters=[Parameter("k", [1, 2]), Parameter("k", [1, 2])],
            experiments=[Experiment(data="d.csv", outputs={"y": "y"})],
        )


def test_study_with_dataframe_data_round_trips_through_toml(tmp_path):
    """Data given as a DataFrame is written as CSV beside the study file and read back."""
    import pandas as pd

    (tmp_path / "plant.fmu").write_bytes(b"PK")
    frame = pd.DataFrame({"time": [0.0, 0.1, 0.2], "u": [1.0, 2.0, 3.0], "y": [0.5, 0.25, 0.0]})
    s = Study(
        fmu=tmp_path / "plant.fmu",
        parameters=[Parameter("k", [1, 2, 3], min=0)],
        experiments=[Experiment(data=frame, inputs={"u": "u"}, outputs={"y": "y"}, name="step")],
    )
    back = Study.from_toml(s.to_toml(tmp_path / "study.toml"))
    assert Path(back.experiments[0].data) == tmp_path / "study_step.csv"
    pd.testing.assert_frame_equal(pd.read_csv(back.experiments[0].data), frame)
    assert back.experiments[0].inputs == {"u": "u"} and back.experiments[0].outputs == {"y": "y"}
    assert back.first_levels() == s.first_levels()
