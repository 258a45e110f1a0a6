from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tsid_fmu.data import MeasuredData, load_data
from tsid_fmu.errors import DataError


def write(tmp_path: Path, text: str, name: str = "data.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD = "time,F_of,F_or,x\n0.0,1,0,0.1\n0.01,0,2,0.2\n0.02,3,0,0.3\n0.03,0,4,0.4\n"


def test_load_csv_and_accessors(tmp_path):
    data = load_data(write(tmp_path, GOOD))
    assert data.sample_time == pytest.approx(0.01)
    assert data.time.dtype == np.float64
    np.testing.assert_allclose(data.column("x"), [0.1, 0.2, 0.3, 0.4])
    assert data.columns(["F_of", "x"]).shape == (4, 2)
    assert data.columns([]).shape == (4, 0)
    assert list(data.to_pandas().index) == pytest.approx([0, 0.01, 0.02, 0.03])
    assert len(data) == 4


def test_derived_channels(tmp_path):
    data = load_data(
        write(tmp_path, GOOD), derived={"F_o": "F_of - F_or", "mag": "abs(F_o) * 2 + sin(0 * x)"}
    )
    np.testing.assert_allclose(data.column("F_o"), [1, -2, 3, -4])
    np.testing.assert_allclose(data.column("mag"), [2, 4, 6, 8])


def test_derived_unknown_name(tmp_path):
    with pytest.raises(DataError, match=r"'F_o' = 'F_of - F_ox'.*unknown name 'F_ox'.*F_or"):
        load_data(write(tmp_path, GOOD), derived={"F_o": "F_of - F_ox"})


@pytest.mark.parametrize("expr", ['__import__("os").system("true")', "x.__class__", "open(x)"])
def test_derived_no_arbitrary_python(tmp_path, expr):
    with pytest.raises(DataError):
        load_data(write(tmp_path, GOOD), derived={"bad": expr})


def test_columns_selection(tmp_path):
    data = load_data(write(tmp_path, GOOD), columns=["x"])
    assert data.names == ["time", "x"]
    with pytest.raises(DataError, match="'nope' not found"):
        load_data(write(tmp_path, GOOD), columns=["nope"])


def test_missing_file(tmp_path):
    with pytest.raises(DataError, match=r"not found.*missing\.csv"):
        load_data(tmp_path / "missing.csv")


def test_empty_file(tmp_path):
    with pytest.raises(DataError, match="empty"):
        load_data(write(tmp_path, ""))
    with pytest.raises(DataError, match=r"empty|at least 2"):
        load_data(write(tmp_path, "time,x\n", "header_only.csv"))


def test_time_column_missing(tmp_path):
    with pytest.raises(DataError, match=r"data.csv: time column 't' not found; columns are time"):
        load_data(write(tmp_path, GOOD), time_column="t")


def test_non_numeric(tmp_path):
    text = "time,x\n0,1\n0.1,2\n0.2,1.2.3\n0.3,4\n"
    # issue 13: the message names the column and row but never quotes the cell
    with pytest.raises(
        DataError,
        match=r"data.csv: column 'x' has a non-numeric value in row 3$",
    ):
        load_data(write(tmp_path, text))


def test_nan_and_inf(tmp_path):
    with pytest.raises(DataError, match=r"column 'x' is missing \(NaN\) in row 2"):
        load_data(write(tmp_path, "time,x\n0,1\n0.1,\n0.2,3\n"))
    with pytest.raises(DataError, match=r"column 'x' is inf in row 3"):
        load_data(write(tmp_path, "time,x\n0,1\n0.1,2\n0.2,inf\n"))


def test_time_duplicate_and_decreasing(tmp_path):
    with pytest.raises(DataError, match=r"row 3 repeats"):
        load_data(write(tmp_path, "time,x\n0,1\n0.1,2\n0.1,3\n0.2,4\n"))
    with pytest.raises(DataError, match=r"row 3 goes back"):
        load_data(write(tmp_path, "time,x\n0,1\n0.1,2\n0.05,3\n0.2,4\n"))


def test_non_uniform(tmp_path):
    with pytest.raises(DataError, match=r"non-uniform sampling .* at row 4"):
        load_data(write(tmp_path, "time,x\n0,1\n0.1,2\n0.2,3\n0.35,4\n0.45,5\n"))
    # small jitter is fine
    load_data(write(tmp_path, "time,x\n0,1\n0.1,2\n0.2005,3\n0.3,4\n", "jitter.csv"))


def test_expected_sample_time(tmp_path):
    load_data(write(tmp_path, GOOD), sample_time=0.01)
    with pytest.raises(DataError, match=r"sample time is 0.01 s but the study expects 0.001 s"):
        load_data(write(tmp_path, GOOD), sample_time=0.001)


def test_tsv_and_read_options(tmp_path):
    data = load_data(write(tmp_path, "time\tx\n0\t1\n0.5\t2\n1\t3\n", "d.tsv"))
    assert data.sample_time == 0.5
    data = load_data(
        write(tmp_path, "time;x\n0;1,5\n1;2,5\n", "eu.csv"),
        read_options={"sep": ";", "decimal": ","},
    )
    np.testing.assert_allclose(data.column("x"), [1.5, 2.5])


def test_mat_file(tmp_path):
    from scipy.io import savemat

    savemat(tmp_path / "d.mat", {"time": np.arange(4) * 0.1, "u": np.ones(4)})
    data = load_data(tmp_path / "d.mat")
    np.testing.assert_allclose(data.column("u"), 1.0)


def test_column_missing_lists_columns(tmp_path):
    data = load_data(write(tmp_path, GOOD))
    with pytest.raises(
        DataError,
        match=r"data.csv: no column 'F_o'; columns are time, F_of.*"
        r"Did you mean",
    ):
        data.column("F_o")


def test_from_frame():
    df = pd.DataFrame({"t": np.arange(5) * 0.2, "u": np.arange(5.0)})
    data = MeasuredData.from_frame(df, time_column="t", derived={"v": "2 * u"})
    assert data.path == "<frame>"
    np.testing.assert_allclose(data.column("v"), 2 * np.arange(5.0))
    with pytest.raises(DataError, match="<frame>: time column 'time' not found"):
        MeasuredData.from_frame(df)
    with pytest.raises(DataError, match="expected a pandas DataFrame"):
        MeasuredData.from_frame({"t": [1, 2]})  # type: ignore[arg-type]
