"""Issue 25, properties over hostile inputs (Hypothesis, a few seconds each).

* any study document with numbers at the limits of a float or an integer (``1e308``,
  ``5e-324``, ``-0.0``, ``2**63``, 400-digit integers) in any key: ``tsid identify``
  exits 2 with one line, and :func:`~tsid_fmu.study.load_study` gives a study or a
  :class:`~tsid_fmu.errors.StudyError`, nothing else;
* any CSV header (names drawn so that they repeat, with or without a UTF-8 byte order
  mark, any usual delimiter): the data load with exactly those names, or a repeated
  name is refused naming both positions;
* any cell at the limits of a float: the data load finite, or a
  :class:`~tsid_fmu.errors.DataError`.
"""

from __future__ import annotations

import json
import math
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tsid_fmu.cli import main
from tsid_fmu.data import load_data
from tsid_fmu.errors import DataError, TsidError
from tsid_fmu.study import load_study

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

LIMITS = st.sampled_from(
    [1e308, -1e308, 1.7976931348623157e308, 5e-324, -5e-324, 2.2250738585072014e-308, -0.0,
     0.0, 2**63 - 1, -(2**63), 2**63, -(2**63) - 1, 2**64, 10**400, -(10**400),
     float("inf"), float("-inf"), float("nan")]
)  # fmt: skip


def _toml(v: Any) -> str:
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml(x)}" for k, x in v.items()) + "}"
    return json.dumps(v) if isinstance(v, str) else str(v)


def _template() -> dict[str, dict[str, Any]]:
    return {
        "study": {"fmu": "plant.fmu", "step_size": 0.01, "start_values": {"x0": 0.0}},
        "data": {"file": "d.csv", "inputs": {"u": "u"}, "outputs": {"y": "y"},
                 "weights": {"y": 1.0}, "sample_time": 0.01, "noise": {"y": 0.1}},
        "method": {"replicates": 2, "seed": 1, "max_iterations": 3, "input_noise": 0.0},
        "leveling": {"tolerance": 0.01, "shrink": 0.5, "n_levels": 3, "log_ratio": 10.0},
        "parameters": {"tau": {"levels": [0.1, 0.2, 0.3], "min": 0.0, "max": 10.0}},
    }  # fmt: skip


def _number_paths(doc: Any, prefix: tuple = ()) -> Iterator[tuple]:
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _number_paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _number_paths(v, (*prefix, i))
    elif isinstance(doc, int | float) and not isinstance(doc, bool):
        yield prefix


@st.composite
def studies_at_the_limits(draw) -> str:
    doc = _template()
    paths = list(_number_paths(doc))
    for path in draw(st.lists(st.sampled_from(paths), min_size=1, max_size=4, unique=True)):
        parent: Any = doc
        for key in path[:-1]:
            parent = parent[key]
        parent[path[-1]] = draw(LIMITS)
    return "\n".join(
        f"[{table}]\n" + "".join(f"{json.dumps(k)} = {_toml(v)}\n" for k, v in body.items())
        for table, body in doc.items()
    )


@pytest.fixture(scope="module")
def folder() -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="tsid-limits-") as d:
        (Path(d) / "plant.fmu").write_bytes(b"PK\x05\x06" + bytes(18))  # an empty ZIP
        (Path(d) / "d.csv").write_text("time,u,y\n0,1,0\n0.01,1,0.1\n0.02,1,0.2\n")
        yield Path(d)


@settings(FAST, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=studies_at_the_limits())
def test_any_number_at_the_limits_loads_or_is_one_line_exit_2(folder, text, capsys):
    path = folder / "study.toml"
    path.write_text(text)
    try:
        load_study(path)
    except TsidError:
        pass
    rc = main(["identify", str(path), "--out", str(folder / "out"), "-q", "--no-plots"])
    err = capsys.readouterr().err  # read (and so cleared) at each example
    assert rc == 2, err  # the FMU is an empty archive: bad input, whatever the numbers
    assert err.startswith("tsid: error: ") and err.count("\n") == 1, err
    assert len(err) < 2000, err  # a 400-digit integer is not echoed whole


NAMES = st.sampled_from(["time", "u", "y", "F_m", "F_of", "x_1", "Time (s)", "u [V]"])


@FAST
@given(
    names=st.lists(NAMES, min_size=1, max_size=5),
    bom=st.booleans(),
    sep=st.sampled_from([",", ";", "\t"]),
    spaces=st.booleans(),
)
def test_any_header_loads_its_names_or_names_the_repeated_one(folder, names, bom, sep, spaces):
    names = ["time", *names]
    gap = " " if spaces and sep != "\t" else ""
    rows = [sep.join(f"{gap}{n}" for n in names)]
    rows += [sep.join([f"{i * 0.1:g}"] + ["1.5"] * (len(names) - 1)) for i in range(3)]
    path = folder / "h.csv"
    path.write_bytes(("\ufeff" if bom else "").encode() + ("\n".join(rows) + "\n").encode())
    repeated = [i for i, n in enumerate(names) if n in names[:i]]
    if not repeated:
        assert load_data(path).names == names
        return
    first = repeated[0]
    with pytest.raises(DataError) as info:
        load_data(path)
    message = str(info.value)
    match = re.search(r"columns (\d+) and (\d+) are both named", message)
    assert match, message
    assert int(match.group(2)) == first + 1
    assert names[int(match.group(1)) - 1] == names[first]


CELLS = st.sampled_from(
    ["1e308", "-1e308", "1.7976931348623157e308", "1.8e308", "5e-324", "-5e-324", "-0.0",
     "0", "9" * 400, "-" + "9" * 400, "1e-400", "0x10", "1_000", "nan", "inf", "", "+1"]
)  # fmt: skip


@FAST
@given(cells=st.lists(CELLS, min_size=4, max_size=4), bom=st.booleans())
def test_any_cell_at_the_limits_loads_finite_or_is_a_data_error(folder, cells, bom):
    rows = ["time,u"] + [f"{i * 0.1:g},{c}" for i, c in enumerate(cells)]
    path = folder / "c.csv"
    path.write_bytes(("\ufeff" if bom else "").encode() + ("\n".join(rows) + "\n").encode())
    try:
        data = load_data(path)
    except DataError as exc:
        assert "9999999999" not in str(exc)  # a cell is located, never quoted
        return
    assert data.names == ["time", "u"]
    assert np.all(np.isfinite(data.frame.to_numpy()))
