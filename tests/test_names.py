"""Every name the FMI standard allows round-trips through the TOML tsid writes (issue 43).

OpenModelica names parameters ``mass.m``, ``ampl[0]``, ``der(x)``; Modelica's quoted
identifiers hold spaces, quotes and ``#``; FMI's flat convention allows any string. As
bare TOML keys the first read back as nested tables and the rest are not TOML, so a hand
study on a tool's FMU died at the first ``next_levels.toml`` read back, blaming a file
tsid wrote. Hypothesis generates names of both conventions and writes them through
``next_levels.toml`` (both its forms) and the keys ``tsid init`` writes.
"""

from __future__ import annotations

import string
import tomllib
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi.frame import Factor, Frame
from tsid_fmu.study.tomltext import toml_key, toml_string
from tsid_fmu.trail.levels import read_next_levels, write_next_levels

_IDENT = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,6}", fullmatch=True)
# Modelica's Q-IDENT: any printable character but ' and \ unless escaped
_QIDENT = st.text(
    st.characters(blacklist_categories=("Cs", "Cc"), blacklist_characters="'\\"), max_size=6
).map(lambda s: f"'{s}'")
_PART = st.one_of(_IDENT, _QIDENT)
_SUBSCRIPT = st.lists(st.integers(0, 12), min_size=1, max_size=2).map(
    lambda ix: "[" + ",".join(map(str, ix)) + "]"
)
_STRUCTURED = st.builds(
    lambda parts, sub, der: f"der({'.'.join(parts)}{sub})" if der else ".".join(parts) + sub,
    st.lists(_PART, min_size=1, max_size=3),
    st.one_of(st.just(""), _SUBSCRIPT),
    st.booleans(),
)
_FLAT = st.text(min_size=1, max_size=12)  # the flat convention: any string at all
NAMES = st.one_of(_STRUCTURED, _FLAT, st.sampled_from(["mass.m", "ampl[0]", "a b", "x#1"]))


def _space(names: list[str]) -> Space:
    levels = {n: [1.0 + i, 2.0 + i, 4.0 + i] for i, n in enumerate(names)}
    return Space(levels, {n: (0.5, 100.0) for n in names}, LevelingOptions())


def _record(names: list[str]) -> SimpleNamespace:
    decisions = [SimpleNamespace(name=n, case="keep", reason=f"why {n}\nnext line") for n in names]
    return SimpleNamespace(index=1, stage="taguchi", decision=SimpleNamespace(parameters=decisions))


@settings(max_examples=300, deadline=None)
@given(st.lists(NAMES, min_size=1, max_size=3, unique=True))
def test_axis_aligned_next_levels_round_trip_any_name(tmp_path_factory, names):
    space = _space(names)
    levels = {n: [1.5 + i, 2.0 + i, 3.0 + i] for i, n in enumerate(names)}
    frame = Frame.from_levels(space, levels)
    path = tmp_path_factory.mktemp("levels") / "next_levels.toml"
    path.write_text(write_next_levels(path, _record(names), space, frame, "note\n#"), "utf-8")
    assert read_next_levels(path, space).level_values(space) == frame.level_values(space)


@settings(max_examples=300, deadline=None)
@given(st.lists(NAMES, min_size=2, max_size=3, unique=True))
def test_rotated_next_levels_round_trip_any_name(tmp_path_factory, names):
    space = _space(names)
    dim = len(names)
    q, _ = np.linalg.qr(np.arange(1.0, dim * dim + 1).reshape(dim, dim) + np.eye(dim))
    factors = [Factor(f"A{k + 1}", q[:, k], np.array([-0.1, 0.0, 0.1])) for k in range(dim)]
    frame = Frame(np.zeros(dim), factors, anchor={n: 2.0 + i for i, n in enumerate(names)})
    path = tmp_path_factory.mktemp("rotated") / "next_levels.toml"
    path.write_text(write_next_levels(path, _record(names), space, frame, "n"), "utf-8")
    read = read_next_levels(path, space)
    assert read.anchor == frame.anchor
    assert read.to_dict()["factors"] == frame.to_dict()["factors"]


@settings(max_examples=500, deadline=None)
@given(NAMES, st.text())
def test_keys_and_strings_as_tsid_init_writes_them_read_back(name, value):
    doc = tomllib.loads(f"[t]\n{toml_key(name)} = {{ unit = {toml_string(value)} }}\n")
    assert doc == {"t": {name: {"unit": value}}}


def test_the_names_of_the_issue_are_quoted_and_plain_names_are_not():
    assert toml_key("K_s") == "K_s"
    for name in ("mass.m", "ampl[0]", "der(x)", "a b", "x#1", "'q'", "", "ä"):
        assert toml_key(name).startswith('"'), name
    assert set(toml_key(string.printable)) - set(string.printable) == set()
