"""``tsid_fmu.simulate``: a DataFrame in and out, sessions cached, errors of our own."""

from __future__ import annotations

import os

import numpy as np
import pandas as pd
import pytest
from feed_factory import build_feed_fmu
from fmu_factory import build_c_fmu, lag_response

import tsid_fmu
from tsid_fmu.errors import DataError, FMUError, SimulationError
from tsid_fmu.fmu import facade


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("api")
    return {"feed": build_feed_fmu(d, "ApiFeed"), "lag": build_c_fmu(d, "ApiLag")}


@pytest.fixture(autouse=True)
def fresh_cache():
    facade.clear_cache()
    yield
    facade.clear_cache()


@pytest.fixture
def data():
    t = np.arange(101) * 0.01
    return pd.DataFrame({"time": t, "a": np.sin(5 * t), "b": np.cos(2 * t), "other": 1.0})


def test_defaults_all_inputs_from_columns_all_outputs(fmus, data):
    out = tsid_fmu.simulate(fmus["feed"], data)
    assert list(out.columns) == ["time", "ya", "yb", "za", "zb", "nder"]
    assert out.index.equals(data.index)
    np.testing.assert_array_equal(out["time"], data["time"])
    np.testing.assert_array_equal(out["ya"], data["a"])  # feed-through, no lag
    np.testing.assert_array_equal(out["yb"], data["b"])


def test_mapping_outputs_parameters_start_values_and_hold(fmus, data):
    frame = data.rename(columns={"a": "u_meas"})
    out = tsid_fmu.simulate(
        fmus["lag"],
        frame,
        inputs={"u": "u_meas"},
        outputs=["y"],
        parameters={"tau": 0.05},
        start_values={"x0": 0.5},
    )
    expected = lag_response(data["time"].to_numpy(), data["a"].to_numpy(), 0.05, x0=0.5)
    np.testing.assert_allclose(out["y"], expected, atol=1e-12)
    lin = tsid_fmu.simulate(fmus["feed"], data, outputs=["za"], hold={"a": "linear"})
    held = tsid_fmu.simulate(fmus["feed"], data, outputs=["za"])
    assert lin["za"].iloc[-1] != held["za"].iloc[-1]


def test_sessions_are_cached_and_reused(fmus, data):
    tsid_fmu.simulate(fmus["lag"], data.rename(columns={"a": "u"}), inputs={"u": "u"})
    assert len(facade._open) == 1
    ((session, _lock),) = facade._open.values()
    frame = data.rename(columns={"a": "u"})
    for tau in (0.1, 0.2, 0.1):
        tsid_fmu.simulate(fmus["lag"], frame, inputs={"u": "u"}, parameters={"tau": tau})
    assert len(facade._open) == 1 and next(iter(facade._open.values()))[0] is session
    assert session.nfev == 4
    # start values change per call without a new session
    a = tsid_fmu.simulate(fmus["lag"], frame, inputs={"u": "u"}, start_values={"x0": 1.0})
    b = tsid_fmu.simulate(fmus["lag"], frame, inputs={"u": "u"})
    assert a["y"].iloc[0] == 1.0 and b["y"].iloc[0] == 0.0
    assert next(iter(facade._open.values()))[0] is session
    # other variables: another session
    tsid_fmu.simulate(fmus["lag"], frame, inputs={"u": "u"}, outputs=["x"])
    assert len(facade._open) == 2


def test_changed_fmu_file_gets_a_new_session(fmus, data, tmp_path):
    copy = tmp_path / "copy.fmu"
    copy.write_bytes(fmus["feed"].read_bytes())
    tsid_fmu.simulate(copy, data)
    ((old, _),) = facade._open.values()
    stat = copy.stat()
    os.utime(copy, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
    tsid_fmu.simulate(copy, data)
    assert old.closed and len(facade._open) == 1


def test_least_recently_used_sessions_are_closed(fmus, data, monkeypatch):
    monkeypatch.setattr(facade, "MAX_OPEN", 2)
    sessions = []
    for outputs in (["ya"], ["yb"], ["za"]):
        tsid_fmu.simulate(fmus["feed"], data, outputs=outputs)
        sessions.append(next(reversed(facade._open.values()))[0])
    assert sessions[0].closed and not sessions[1].closed and not sessions[2].closed
    facade.clear_cache()
    assert all(s.closed for s in sessions) and not facade._open


def test_data_errors_name_the_column_and_row(fmus, data):
    with pytest.raises(
        DataError, match=r"no column 'x' for the FMU input 'a' \(columns: time, a, b, other\)"
    ):
        tsid_fmu.simulate(fmus["feed"], data, inputs={"a": "x", "b": "b"})
    with pytest.raises(DataError, match=r"no column 'a' for the FMU input 'a'"):
        tsid_fmu.simulate(fmus["feed"], data.drop(columns="a"))
    bad = data.astype({"b": object})
    bad.loc[7, "b"] = "n/a"
    with pytest.raises(DataError, match=r"column 'b' has non-numeric value 'n/a' in row 8"):
        tsid_fmu.simulate(fmus["feed"], bad)
    nan = data.copy()
    nan.loc[3, "a"] = np.nan
    with pytest.raises(DataError, match=r"column 'a' is missing \(NaN\) in row 4"):
        tsid_fmu.simulate(fmus["feed"], nan)
    with pytest.raises(DataError, match=r"no 'time' column.*Did you mean 'Time'"):
        tsid_fmu.simulate(fmus["feed"], data.rename(columns={"time": "Time"}))
    back = data.copy()
    back.loc[5, "time"] = 0.0
    with pytest.raises(DataError, match=r"'time' is not strictly increasing: row 6"):
        tsid_fmu.simulate(fmus["feed"], back)
    with pytest.raises(DataError, match=r"must be a pandas DataFrame.*not dict"):
        tsid_fmu.simulate(fmus["feed"], {"time": [0, 1]})


def test_fmu_errors_name_the_variable(fmus, data, tmp_path):
    with pytest.raises(FMUError, match=r"unknown output 'yaa'.*Did you mean 'ya'"):
        tsid_fmu.simulate(fmus["feed"], data, outputs=["yaa"])
    with pytest.raises(FMUError, match=r"unknown input 'c'"):
        tsid_fmu.simulate(fmus["feed"], data, inputs={"c": "a"})
    with pytest.raises(FMUError, match=r"unknown parameter 'tauu'.*Did you mean 'tau'"):
        tsid_fmu.simulate(
            fmus["lag"], data, inputs={"u": "a"}, outputs=["y"], parameters={"tauu": 1.0}
        )
    with pytest.raises(FMUError, match="FMU file not found"):
        tsid_fmu.simulate(tmp_path / "none.fmu", data)
    with pytest.raises(SimulationError, match=r"fmi2DoStep returned Error.*t_fail"):
        tsid_fmu.simulate(
            fmus["lag"], data, inputs={"u": "a"}, outputs=["y"], parameters={"t_fail": 0.5}
        )
    # the cached session is still usable after a failed run
    ok = tsid_fmu.simulate(fmus["lag"], data, inputs={"u": "a"}, outputs=["y"])
    assert np.isfinite(ok["y"]).all()
