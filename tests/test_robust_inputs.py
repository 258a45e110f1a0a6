"""Hostile data and study files: only the project's own errors come out, as one line.

Hand-written cases go through :func:`tsid_fmu.cli.main` (exit status 2, one line
``tsid: error: ...`` on stderr, no traceback) or through the loaders; property-based
tests feed random study documents, random bytes and random CSV text to
:func:`~tsid_fmu.study.load_study` and :func:`~tsid_fmu.data.load_data` and accept
nothing but :class:`~tsid_fmu.errors.TsidError` subclasses.
"""

from __future__ import annotations

import datetime
import json
import math
import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fmu_factory import lag_case
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tsid_fmu import identify
from tsid_fmu.cli import main
from tsid_fmu.data import load_data
from tsid_fmu.doe import select_array
from tsid_fmu.errors import ArrayError, DataError, StudyError, TsidError
from tsid_fmu.study import load_study

DT = 0.01
PARAMS = "[parameters]\ntau = { levels = [0.1, 0.3, 0.6], min = 0 }\n"


@pytest.fixture(scope="module")
def lag(tmp_path_factory) -> Path:
    return lag_case(tmp_path_factory.mktemp("lag"), DT)


def _paper(method: str) -> str:
    """The SISO paper's method these tests were written for, where ``method`` sets none."""
    pinned = {"cost": '"iae"', "weighting": '"none"', "replicates": "2"}
    return "".join(f"{k} = {v}\n" for k, v in pinned.items() if f"{k} =" not in method)


def study_text(fmu: Path, data: str | None = None, *, study: str = "", data_extra: str = "",
               method: str = "", params: str = PARAMS) -> str:  # fmt: skip
    data = data or (fmu.parent / "good.csv").as_posix()
    return (
        f'[study]\nfmu = "{fmu.as_posix()}"\n{study}'
        f'[data]\nfile = "{data}"\ninputs = {{ u = "u" }}\noutputs = {{ y = "y" }}\n{data_extra}'
        f"[method]\nmax_iterations = 1\n{_paper(method)}{method}" + params
    )


def run_cli(tmp_path: Path, text: str, capsys) -> str:
    """Run ``tsid identify`` on a study text; assert exit 2 and one error line."""
    path = tmp_path / "study.toml"
    path.write_text(text)
    rc = main(["identify", str(path), "--out", str(tmp_path / "out"), "-q", "--no-plots"])
    captured = capsys.readouterr()
    assert rc == 2, captured
    err = captured.err
    assert err.startswith("tsid: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


# ---------------------------------------------------------------------------- data files

BAD_DATA = [
    ("nan.csv", "time,u,y\n0,1,0\n0.01,,0.1\n0.02,1,0.2\n",
     r"nan\.csv: column 'u' is missing \(NaN\) in row 2"),
    ("inf.csv", "time,u,y\n0,1,0\n0.01,1,1e999\n0.02,1,0.2\n", r"column 'y' is inf in row 2"),
    ("dup.csv", "time,u,y\n0,1,0\n0.01,1,0\n0.01,1,0\n0.03,1,0\n",
     r"row 3 repeats the previous time"),
    ("back.csv", "time,u,y\n0,1,0\n0.02,1,0\n0.01,1,0\n", r"row 3 goes back"),
    ("text.csv", "time,u,y\n0,1,0\n0.01,one,0\n0.02,1,0\n",
     r"column 'u' has a non-numeric value in row 2$"),  # issue 13: the cell is not quoted
    ("ttext.csv", "time,u,y\n0,1,0\nsoon,1,0\n0.02,1,0\n",
     r"column 'time' has a non-numeric value in row 2$"),
    ("empty.csv", "", r"empty\.csv: the file is empty"),
    ("blank.csv", "\n\n\n", r"blank\.csv: (the file is empty|no data|cannot read)"),
    ("header.csv", "time,u,y\n", r"header\.csv: (no data|at least 2 samples)"),
    ("one.csv", "time,u,y\n0,1,0\n", r"one\.csv: at least 2 samples are needed, got 1"),
    ("rate.csv", "time,u,y\n0,1,0\n0.02,1,0\n0.04,1,0\n",
     r"rate\.csv: sample time is 0\.02 s but the study expects 0\.01 s"),
    ("jitter.csv", "time,u,y\n0,1,0\n0.01,1,0\n0.025,1,0\n0.03,1,0\n", r"non-uniform sampling"),
    ("notime.csv", "t,u,y\n0,1,0\n0.01,1,0\n", r"notime\.csv: time column 'time' not found"),
    ("nou.csv", "time,v,y\n0,1,0\n0.01,1,0\n0.02,1,0\n", r"nou\.csv: no column 'u'"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "content", "message"), BAD_DATA)
def test_bad_data_through_the_cli(lag, tmp_path, capsys, name, content, message):
    (tmp_path / name).write_text(content)
    extra = f"sample_time = {DT}\n"
    err = run_cli(tmp_path, study_text(lag, name, data_extra=extra), capsys)
    assert re.search(message, err), err


@pytest.mark.parametrize(
    ("name", "content"),
    [
        ("binary.csv", bytes(range(256)) * 4),
        ("latin1.csv", "time,u\n0,\xe9\n0.1,2\n".encode("latin-1")),
        ("ragged.csv", b"time,u\n0,1,2,3\n0.1,2\n0.2\n"),
        ("quote.csv", b'time,u\n0,"1\n0.1,2\n'),
        ("nul.csv", b"time,u\n0,1\x00\n0.1,2\n"),
        ("onlycol.csv", b"time\n0\n0.1\n0.2\n"),
        ("bom.csv", b"\xef\xbb\xbftime,u\n0,1\n0.1,2\n"),
    ],
)
def test_odd_files_are_data_errors_or_load(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    try:
        data = load_data(path)
    except DataError as exc:
        assert name in str(exc)
    else:
        assert np.all(np.diff(data.time) > 0) and np.all(np.isfinite(data.frame.to_numpy()))


def test_data_folder_instead_of_file(tmp_path):
    with pytest.raises(DataError, match="not a file"):
        load_data(tmp_path)


# ---------------------------------------------------------------------------- study files


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ({"study": "fmu_file = 1\n"}, r"unknown key 'fmu_file' in \[study\]"),
        ({"method": "replicats = 2\n"},
         r"unknown key 'replicats' in \[method\]; did you mean 'replicates'"),
        ({"method": 'replicates = "2"\n'}, r"\[method\] replicates must be an integer, got '2'"),
        ({"method": "seed = 1.5\n"}, r"\[method\] seed must be an integer"),
        ({"method": "cost = 3\n"}, r"\[method\] cost must be a string"),
        ({"data_extra": "inputs = 3\n"}, r"Cannot overwrite a value|inputs must be a table"),
        ({"study": 'interface = "fmi"\n'}, r"interface must be 'auto', 'cs' or 'me'"),
        ({"params": "[parameters]\ntau = { levels = [0.1, 0.3], min = 0.2 }\n"},
         r"'tau': levels \[0\.1\] lie outside the bounds \[0\.2, inf\]"),
        ({"params": "[parameters]\ntau = { levels = [0.1, 0.3], max = 0.2 }\n"},
         r"'tau': levels \[0\.3\] lie outside the bounds"),
        ({"params": "[parameters]\ntau = { levels = 0.3 }\n"}, r"levels must be a list"),
        ({"params": "[parameters]\ntau = { levels = [0.1, 0.3], step = 1 }\n"},
         r"unknown key 'step' in \[parameters\] tau"),
        ({"params": "[parameters]\ntau = { levels = [0.1, nan] }\n"}, r"levels must be finite"),
    ],
)  # fmt: skip
def test_study_mistakes_through_the_cli(lag, tmp_path, capsys, edit, message):
    err = run_cli(tmp_path, study_text(lag, **edit), capsys)
    assert re.search(message, err), err
    assert "study.toml" in err


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ("[parameters]\ntaux = { levels = [0.1, 0.3] }\n",
         r"Lag\.fmu: unknown parameter 'taux'.*Did you mean 'tau'"),
        ("[parameters]\ny = { levels = [0.1, 0.3] }\n",
         r"Lag\.fmu: parameter 'y' has causality 'output', not 'parameter'"),
        ("[parameters]\nc_const = { levels = [0.1, 0.3] }\n", r"'c_const' is a constant"),
    ],
)  # fmt: skip
def test_parameter_not_in_the_fmu_fails_at_study_start(lag, tmp_path, capsys, params, message):
    err = run_cli(tmp_path, study_text(lag, params=params), capsys)
    assert re.search(message, err), err
    # refused before the first iteration: nothing but the copied study file was written
    assert not list((tmp_path / "out").glob("iteration_*"))


def test_unknown_input_and_start_value_names(lag, tmp_path, capsys):
    text = study_text(lag).replace('inputs = { u = "u" }', 'inputs = { uu = "u" }')
    assert "unknown input 'uu'" in run_cli(tmp_path, text, capsys)
    text = study_text(lag, study="start_values = { x00 = 1.0 }\n")
    assert "unknown start value 'x00'" in run_cli(tmp_path, text, capsys)


FIVE = "[parameters]\n" + "".join(
    f"{n} = {{ levels = [{', '.join(str(v) for v in vals)}] }}\n"
    for n, vals in {
        "tau": [0.1, 0.2, 0.3, 0.4, 0.5],
        "x0": [-2, -1, 0, 1, 2],
        "t_fail": [10, 11, 12, 13, 14],
        "t_nan": [10, 11, 12, 13, 14],
        "gain": [1, 2, 3, 4, 5],
    }.items()
)


def test_array_too_small_for_the_factors(lag, tmp_path, capsys):
    with pytest.raises(ArrayError, match=r"L4"):
        select_array([5] * 5, name="L4")
    path = tmp_path / "five.toml"
    path.write_text(study_text(lag, method='array = "L4"\n', params=FIVE))
    with pytest.raises(ArrayError, match=r"L4.*5 levels"):
        identify(load_study(path), tmp_path / "api", plots=False)
    err = run_cli(tmp_path, study_text(lag, method='array = "L4"\n', params=FIVE), capsys)
    assert "L4" in err
    err = run_cli(tmp_path, study_text(lag, method='array = "L7"\n'), capsys)
    assert "unknown orthogonal array 'L7'" in err


CHECKED_AT_LOAD = [
    ("seed = -1", "[method] seed", "numpy raises ValueError in runner.prepare_experiment"),
    ("replicates = 100000000000", "[method] replicates", "Evaluator builds 1e11 inputs: hangs"),
    ("input_noise = 0.01\n[leveling]\nn_levels = 9", "[leveling] n_levels",
     "no array has 9-level columns: ArrayError only in iteration 2"),
]  # fmt: skip


@pytest.mark.parametrize(("line", "key", "why"), CHECKED_AT_LOAD, ids=["seed", "reps", "n_levels"])
def test_method_values_checked_at_load(lag, tmp_path, line, key, why):
    path = tmp_path / "s.toml"
    path.write_text(study_text(lag, method=line + "\n"))
    with pytest.raises(StudyError, match=key.replace("[", r"\[").replace("]", r"\]")):
        load_study(path)


NON_FINITE = [
    ({"study": "start_values = { x0 = nan }\n"}, "start_values"),
    ({"study": "step_size = -1.0\n"}, "step_size"),
    ({"study": "step_size = nan\n"}, "step_size"),
    ({"data_extra": "weights = { y = -1.0 }\n"}, "weights"),
    ({"data_extra": "weights = { y = nan }\n"}, "weights"),
    ({"data_extra": "sample_time = -0.01\n"}, "sample_time"),
    ({"params": "[parameters]\ntau = { levels = [1e308, -1e308, 0] }\n"}, "tau"),
]  # fmt: skip


@pytest.mark.parametrize(("edit", "key"), NON_FINITE, ids=[k for _, k in NON_FINITE])
def test_non_finite_or_negative_numbers_refused_at_load(lag, tmp_path, edit, key):
    path = tmp_path / "s.toml"
    path.write_text(study_text(lag, **edit))
    with pytest.raises(StudyError, match=key):
        load_study(path)


# ---------------------------------------------------------------------------- fuzzing

_SCALARS = (
    st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**63 - 1)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=12)
    | st.dates()
)
_VALUES = st.recursive(
    _SCALARS,
    lambda inner: (
        st.lists(inner, max_size=4)
        | st.dictionaries(st.text(min_size=1, max_size=8), inner, max_size=4)
    ),
    max_leaves=10,
)
_KEYS = st.sampled_from(
    ["study", "data", "experiments", "method", "leveling", "parameters", "fmu", "file",
     "levels", "min", "max", "unit", "inputs", "outputs", "weights", "derived", "time",
     "array", "cost", "replicates", "seed", "max_iterations", "selection", "n_levels",
     "tolerance", "shrink", "scale", "start_values", "step_size", "interface", "name",
     "sample_time", "tau", "x0"]
) | st.text(min_size=1, max_size=8)  # fmt: skip


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string, except for lone surrogates
    if isinstance(v, datetime.date):
        return v.isoformat()
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"


def _template() -> dict[str, Any]:
    return {
        "study": {"fmu": "plant.fmu", "name": "fuzz"},
        "data": {"file": "d.csv", "inputs": {"u": "u"}, "outputs": {"y": "y"}},
        "method": {"array": "L9", "replicates": 2, "seed": 1},
        "leveling": {"tolerance": 0.01},
        "parameters": {"tau": {"levels": [0.1, 0.2, 0.3], "min": 0.0}},
    }


def _paths(doc: dict[str, Any], prefix: tuple = ()) -> list[tuple]:
    out = []
    for k, v in doc.items():
        out.append((*prefix, k))
        if isinstance(v, dict):
            out.extend(_paths(v, (*prefix, k)))
    return out


@st.composite
def mutated_studies(draw) -> dict[str, Any]:
    doc = _template()
    for _ in range(draw(st.integers(1, 4))):
        paths = _paths(doc)
        path = draw(st.sampled_from(paths))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        if action == "replace":
            parent[path[-1]] = draw(_VALUES)
        elif action == "delete":
            del parent[path[-1]]
        else:
            target = parent[path[-1]] if isinstance(parent[path[-1]], dict) else parent
            target[draw(_KEYS)] = draw(_VALUES)
        if not doc:
            break
    return doc


@pytest.fixture(scope="module")
def fuzz_dir():
    with tempfile.TemporaryDirectory(prefix="tsid-fuzz-") as d:
        (Path(d) / "plant.fmu").write_bytes(b"PK")
        yield Path(d)


_FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _only_own_errors(call, *args, **kwargs) -> None:
    try:
        call(*args, **kwargs)
    except TsidError:
        pass


@pytest.mark.slow
@_FUZZ
@given(doc=mutated_studies())
def test_fuzz_study_documents(fuzz_dir, doc):
    path = fuzz_dir / "study.toml"
    path.write_text("\n".join(f"{json.dumps(k)} = {_toml_value(v)}" for k, v in doc.items()))
    _only_own_errors(load_study, path)


@_FUZZ
@given(content=st.binary(max_size=300) | st.text(max_size=300).map(str.encode))
def test_fuzz_study_bytes(fuzz_dir, content):
    path = fuzz_dir / "bytes.toml"
    path.write_bytes(content)
    _only_own_errors(load_study, path)


_CSV_CHARS = "0123456789.,;-+eEnaifNAIFxt \t\n\r\"'#"


@_FUZZ
@example(content="\n+", suffix=".dat", sample_time=None)  # found by this test
@given(
    content=st.text(alphabet=_CSV_CHARS, max_size=200)
    | st.binary(max_size=200).map(lambda b: b.decode("latin-1")),
    suffix=st.sampled_from([".csv", ".tsv", ".txt", ".dat", ""]),
    sample_time=st.none() | st.floats(allow_nan=True, allow_infinity=True),
)
def test_fuzz_csv_content(fuzz_dir, content, suffix, sample_time):
    path = fuzz_dir / f"data{suffix}"
    path.write_text(content, encoding="latin-1")
    try:
        data = load_data(path, sample_time=sample_time)
    except TsidError:
        return
    # whatever loads is usable: strictly increasing, finite, uniformly sampled
    assert np.all(np.diff(data.time) > 0)
    assert np.all(np.isfinite(data.frame.to_numpy()))
    assert data.sample_time > 0


@st.composite
def numeric_tables(draw) -> str:
    n = draw(st.integers(0, 8))
    cells = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(["", "x", "1e999"])
    times = draw(st.lists(st.floats(-1e3, 1e3) | cells, min_size=n, max_size=n))
    us = draw(st.lists(cells, min_size=n, max_size=n))
    rows = ["time,u"] + [f"{a},{b}" for a, b in zip(times, us, strict=True)]
    return "\n".join(rows) + "\n"


@pytest.mark.slow
@_FUZZ
@given(table=numeric_tables())
def test_fuzz_numeric_tables(fuzz_dir, table):
    path = fuzz_dir / "table.csv"
    path.write_text(table)
    _only_own_errors(load_data, path)
