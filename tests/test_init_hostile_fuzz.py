"""Property tests: whatever names and descriptions ``tsid init`` copies, the study parses.

Names, descriptions and units of an FMU's variables and the data's column names are
drawn from all of Unicode that XML 1.0 (the model description) and a CSV can hold:
control characters, quotes, ``]``, ``=``, ``#``, newlines. The written study must parse
as TOML with only the tables ``init`` writes (nothing injected), and load or be refused
with a :class:`~tsid_fmu.errors.TsidError`; ``init`` itself may refuse with one.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_init_hostile import data_file, hostile_fmu

from tsid_fmu.errors import TsidError
from tsid_fmu.scaffold import init_study
from tsid_fmu.study import load_study

FAST = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
LINE_BREAKING = re.compile("[\x00-\x08\x0a-\x1f\x7f-\x9f\u2028\u2029]")
"""What may not stand in a line of the study: it would end a comment, or TOML refuses it."""
TABLES = {"study", "data", "method", "parameters"}

_XML_CHAR = st.characters(
    blacklist_categories=("Cs",),
    blacklist_characters=[chr(c) for c in range(0x20) if c not in (0x9, 0xA, 0xD)]
    + ["\ufffe", "\uffff"],
)
_TRICKY = st.sampled_from(
    ["\n", "\r", "\t", "\x85", "\u2028", "\u2029", "\x7f", '"', "'", "]", "[", "=", "#", "\\",
     "\n[design]\ninputs = { u = [-1000, 1000] }", '" = 1\n[x]\n', "}", "{", " "]
)  # fmt: skip
TEXT = st.lists(st.one_of(_XML_CHAR, _TRICKY), max_size=12).map("".join)
"""Free text an FMU's model description can hold."""
_CSV_CHAR = st.characters(blacklist_categories=("Cs",), blacklist_characters=["\x00"])
COLUMN = st.lists(st.one_of(_CSV_CHAR, _TRICKY), min_size=1, max_size=10).map("".join)


def _check(folder: Path, fmu: Path, data: Path) -> None:
    out = folder / "study.toml"
    try:
        text = init_study(fmu, data, out)
    except TsidError:
        return
    doc = tomllib.loads(text)  # never a TOMLDecodeError: the file always parses
    assert set(doc) == TABLES, sorted(doc)
    assert not any(LINE_BREAKING.search(line) for line in text.split("\n"))
    assert set(doc["method"]) == {"array", "cost", "weighting", "replicates"}
    try:
        load_study(out)
    except TsidError:
        pass


@pytest.fixture
def folder(tmp_path) -> Path:
    return tmp_path


@FAST
@given(
    names=st.lists(TEXT, min_size=1, max_size=3),
    descriptions=st.lists(st.one_of(st.none(), TEXT), min_size=3, max_size=3),
    start=st.sampled_from(["1.0", "-2.5", "0", "1e308", "5e-324", "1e-300", "NaN"]),
)
def test_any_parameter_name_and_description_gives_a_study_that_parses(
    folder, names, descriptions, start
):
    params = [(name, start, "", descriptions[i % 3]) for i, name in enumerate(names)] + [
        ("k_ok", "2.0", "", descriptions[0])
    ]
    fmu = hostile_fmu(folder, params)
    _check(folder, fmu, data_file(folder))


@FAST
@given(output=TEXT, inputs=st.lists(TEXT, max_size=2), columns=st.lists(COLUMN, max_size=3))
def test_any_input_output_and_column_name_gives_a_study_that_parses(
    folder, output, inputs, columns
):
    fmu = hostile_fmu(folder, [("k", "1.0", "", None)], output=output or "h", inputs=tuple(inputs))
    names = tuple(dict.fromkeys([output or "h", *columns]))
    names = tuple(n for n in names if n.strip(" ").lower() != "time")
    try:
        data = data_file(folder, names or ("h",))
    except ValueError:
        return
    _check(folder, fmu, data)
