"""``tsid init`` on hostile names and descriptions (issue 66, findings 4 and 22).

What ``init`` copies from the FMU and the data into the study is free text: a newline in
a description must not start a line of TOML, and a name or level a study cannot hold
must not make a study that ``tsid identify`` refuses. The written study parses, and
loads or is refused with a :class:`~tsid_fmu.errors.TsidError`.
"""

from __future__ import annotations

import tomllib
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pandas as pd
import pytest

from tsid_fmu.errors import StudyError
from tsid_fmu.scaffold import init_study
from tsid_fmu.study import load_study
from tsid_fmu.study.tomltext import comment_text

INJECTION = "gain\n[design]\ninputs = { u = [-1000, 1000] }"


def _xml_text(text: str) -> str:
    """``text`` as an XML attribute, control characters as character references."""
    return quoteattr(text, {"\r": "&#13;", "\t": "&#9;", "\n": "&#10;"})


def hostile_fmu(
    folder: Path,
    parameters: list[tuple[str, str, str, str | None]],
    output: str = "h",
    inputs: tuple[str, ...] = (),
) -> Path:
    """A model description (no binaries: ``init`` reads the description only).

    ``parameters`` are (name, start, extra Real attributes, description).
    """
    rows = [
        f'<ScalarVariable name={_xml_text(output)} valueReference="0" causality="output" '
        'variability="continuous"><Real/></ScalarVariable>'
    ]
    for i, (name, start, extra, description) in enumerate(parameters, 1):
        desc = f" description={_xml_text(description)}" if description is not None else ""
        rows.append(
            f'<ScalarVariable name={_xml_text(name)} valueReference="{i}" causality="parameter" '
            f'variability="fixed" initial="exact"{desc}><Real start="{start}" {extra}/>'
            "</ScalarVariable>"
        )
    for j, name in enumerate(inputs, len(parameters) + 1):
        rows.append(
            f'<ScalarVariable name={_xml_text(name)} valueReference="{j}" causality="input" '
            'variability="continuous"><Real start="0"/></ScalarVariable>'
        )
    xml = (
        '<?xml version="1.0" encoding="UTF-8"?><fmiModelDescription fmiVersion="2.0" '
        'modelName="B" guid="{1}"><CoSimulation modelIdentifier="B"/><ModelVariables>'
        + "".join(rows)
        + '</ModelVariables><ModelStructure><Outputs><Unknown index="1"/></Outputs>'
        "</ModelStructure></fmiModelDescription>"
    )
    fmu = folder / "B.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", xml.encode("utf-8"))
    return fmu


def data_file(folder: Path, columns: tuple[str, ...] = ("h",)) -> Path:
    """A CSV with ``time`` and ``columns``, written by pandas (names quoted as need be)."""
    t = np.arange(0.0, 1.0, 0.01)
    frame = pd.DataFrame({"time": t, **{c: np.sin(t + i) for i, c in enumerate(columns)}})
    path = folder / "d.csv"
    frame.to_csv(path, index=False)
    return path


def _init(folder: Path, fmu: Path, data: Path) -> tuple[str, dict]:
    text = init_study(fmu, data, folder / "study.toml")
    return text, tomllib.loads(text)


def test_a_description_with_newlines_stays_in_its_comment(tmp_path):
    """A description set ``[design] inputs = ...`` in the study (finding 4)."""
    fmu = hostile_fmu(tmp_path, [("k", "1.0", "", INJECTION), ("j", "2", "", None)])
    text, doc = _init(tmp_path, fmu, data_file(tmp_path))
    assert "design" not in doc
    assert set(doc) == {"study", "data", "method", "parameters"}
    assert comment_text(INJECTION) in text
    assert "gain\\n[design]\\ninputs = { u = [-1000, 1000] }" in text
    assert load_study(tmp_path / "study.toml").parameters[0].name == "k"


@pytest.mark.parametrize("bad", ["\r", "\t", "\x7f", "\x85", "\x9b", "\u2028", "\u2029"])
def test_every_control_character_of_a_description_is_escaped(tmp_path, bad):
    fmu = hostile_fmu(tmp_path, [("k", "1.0", "", f"a{bad}[design]\nx = 1")])
    text, doc = _init(tmp_path, fmu, data_file(tmp_path))
    assert "design" not in doc and "x" not in doc
    assert all(line.isprintable() for line in text.splitlines())
    load_study(tmp_path / "study.toml")


def test_input_and_column_names_in_comments_are_escaped(tmp_path):
    """FMU inputs without a column and unused columns are listed in comments."""
    fmu = hostile_fmu(tmp_path, [("k", "1.0", "", None)], inputs=("u\n[design]\nkinds = 1",))
    data = data_file(tmp_path, ("h", "c\n[method]\narray = 'L4'", "\x1b]0;title\x07\x1b[2J"))
    text, doc = _init(tmp_path, fmu, data)
    assert "design" not in doc
    assert doc["method"]["array"] != "L4"
    assert "c\\n[method]\\narray = 'L4'" in text
    assert "\\u001B]0;title\\u0007\\u001B[2J" in text
    assert all(line.isprintable() for line in text.splitlines())
    load_study(tmp_path / "study.toml")


@pytest.mark.parametrize(
    ("case", "parameter", "reason"),
    [
        ("control character", ("a\nb", "1.0", "", None), "printable"),
        ("tab", ("a\tb", "1.0", "", None), "printable"),
        ("empty", ("", "1.0", "", None), "printable"),
        ("duplicate", ("j", "1.0", "", None), "a second variable of this name"),
        ("infinite levels", ("k", "1e308", "", None), "finite levels"),
        ("degenerate levels", ("k", "5e-324", "", None), "distinct finite levels"),
        ("bounds closer than the levels", ("k", "1", 'min="1" max="1.0000000000000002"', None),
         "distinct finite levels"),
    ],
)  # fmt: skip
def test_init_writes_a_study_that_loads_whatever_the_parameter(tmp_path, case, parameter, reason):
    """Such a study failed to parse or load (finding 22): the variable is left out, said why."""
    fmu = hostile_fmu(tmp_path, [("j", "2.0", "", None), parameter])
    text, _ = _init(tmp_path, fmu, data_file(tmp_path))
    study = load_study(tmp_path / "study.toml")
    assert [p.name for p in study.parameters] == ["j"], case
    (line,) = [row for row in text.splitlines() if "not written" in row]
    assert reason in line and line.startswith("# ")


def test_init_refuses_when_nothing_a_study_can_hold_is_left(tmp_path):
    fmu = hostile_fmu(tmp_path, [("", "1.0", "", None), ("k", "1e308", "", None)])
    with pytest.raises(StudyError, match="no real parameter to identify"):
        init_study(fmu, data_file(tmp_path), tmp_path / "study.toml")


def test_the_no_match_error_keeps_a_name_with_a_newline_on_its_line(tmp_path):
    fmu = hostile_fmu(tmp_path, [("k", "1.0", "", None)], output="y")
    data = data_file(tmp_path, ("z\nfake line",))
    with pytest.raises(StudyError) as info:
        init_study(fmu, data, tmp_path / "study.toml")
    assert "\n" not in str(info.value) and "z\\nfake line" in str(info.value)
