"""The Model Exchange integrator (tsid_fmu.fmu.meloop / mesolver) against exact solutions.

A Model-Exchange-only first-order lag (tests/fmu_factory.py) against its analytic
solution for held and linear inputs; the project's plants in Model Exchange against
the independent references in models/reference/ (the SISO plant sticks and slips, so
state events must be located); errors name the FMI call and the time; the compiled
and the interpreted loop give identical results; CVode stays available.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from fmpy.util import read_csv
from fmu_factory import build_c_fmu, lag_response
from test_reference import ACCEPT, FMUS, REF, assert_stick_slip, nrms

from tsid_fmu.errors import FMUError, SimulationError
from tsid_fmu.fmu import FMUSession
from tsid_fmu.fmu import compiled as fastloop

TAU = 0.05


@pytest.fixture(scope="module")
def lag_me(tmp_path_factory):
    return build_c_fmu(tmp_path_factory.mktemp("me"), "LagME", interfaces=("me",))


@pytest.fixture(scope="module")
def held():
    t = np.arange(2001) * 1e-3
    rng = np.random.default_rng(1)
    u = np.sign(np.sin(2 * np.pi * 2 * t)) + 0.2 * rng.standard_normal(t.size)
    return t, u


def _lag(path, t, u, params, **kw):
    with FMUSession(path, ["u"], ["y"], parameters=list(params), **kw) as s:
        return s.simulate(t, u, params)[:, 0], s


def test_me_only_fmu_uses_the_integrator_and_matches_the_exact_solution(lag_me, held):
    t, u = held
    y, s = _lag(lag_me, t, u, {"tau": TAU})
    assert s.interface == "me" and s.me_solver == "rk45"
    exact = lag_response(t, u, TAU)
    # the bound is 0.01 %; the integrator is far inside it
    assert np.max(np.abs(y - exact)) / np.max(np.abs(exact)) < 1e-8
    stats = s.me_stats
    assert stats["steps"] == t.size - 1 and stats["rejected"] == 0
    assert stats["derivatives"] == 6 * stats["steps"]


def test_linear_input_is_integrated_as_a_ramp(lag_me):
    # u = a + b t between samples: x(t) = a + b (t - tau) + (x0 - a + b tau) exp(-t/tau)
    t = np.linspace(0.0, 0.5, 51)
    a, b = 0.3, 4.0
    y, _ = _lag(lag_me, t, a + b * t, {"tau": TAU}, hold={"u": "linear"})
    exact = a + b * (t - TAU) + (0.0 - a + b * TAU) * np.exp(-t / TAU)
    np.testing.assert_allclose(y, exact, rtol=1e-8, atol=1e-10)
    held, _ = _lag(lag_me, t, a + b * t, {"tau": TAU})
    assert np.max(np.abs(held - exact)) > 1e-3  # a held input would be visibly off


def test_integrator_is_much_faster_than_cvode_and_more_accurate(lag_me, held):
    t, u = held
    exact = lag_response(t, u, TAU)
    with FMUSession(lag_me, ["u"], ["y"], parameters=["tau"]) as s:
        s.simulate(t, u, {"tau": TAU})  # compile or load the loop
        t0 = time.perf_counter()
        ours = s.simulate(t, u, {"tau": TAU})[:, 0]
        fast = time.perf_counter() - t0
    with FMUSession(lag_me, ["u"], ["y"], parameters=["tau"], me_solver="cvode") as s:
        t0 = time.perf_counter()
        cvode = s.simulate(t, u, {"tau": TAU})[:, 0]
        slow = time.perf_counter() - t0
        assert s.me_stats is None
    err = np.max(np.abs(cvode - exact)) / np.max(np.abs(exact))
    assert np.max(np.abs(ours - exact)) < err / 100
    if fastloop.backend() == "numba":
        assert slow / fast > 10, (slow, fast)  # benchmarks/bench_me.py: ~300x


def test_compiled_and_python_loop_are_bit_identical(lag_me, held, monkeypatch):
    t, u = held
    y_fast, _ = _lag(lag_me, t, u, {"tau": TAU})
    monkeypatch.setenv(fastloop.LOOP_ENV, "python")
    y_py, _ = _lag(lag_me, t[:300], u[:300], {"tau": TAU})
    np.testing.assert_array_equal(y_py, y_fast[:300])


def test_repeated_runs_reset_the_instance(lag_me, held):
    t, u = held
    with FMUSession(lag_me, ["u"], ["y"], parameters=["tau", "x0"]) as s:
        a = s.simulate(t, u, {"tau": TAU, "x0": 0.0})
        b = s.simulate(t, u, {"tau": 2 * TAU, "x0": 1.0})
        c = s.simulate(t, u, {"tau": TAU, "x0": 0.0})
    np.testing.assert_array_equal(a, c)
    np.testing.assert_allclose(b[:, 0], lag_response(t, u, 2 * TAU, x0=1.0), rtol=1e-8)


@pytest.mark.parametrize("backend", ["numba", "python"])
def test_failing_call_names_function_interval_and_time(lag_me, held, backend, monkeypatch):
    if backend == "python":
        monkeypatch.setenv(fastloop.LOOP_ENV, "python")
    t, u = held
    with FMUSession(lag_me, ["u"], ["y"], parameters=["tau", "t_fail"]) as s:
        with pytest.raises(SimulationError) as err:
            s.simulate(t[:500], u[:500], {"tau": TAU, "t_fail": 0.25})
        msg = str(err.value)
        assert "fmi2CompletedIntegratorStep returned Error" in msg
        assert "t=0.25" in msg and "time limit t_fail exceeded" in msg
        # the session stays usable
        y = s.simulate(t, u, {"tau": TAU, "t_fail": 1e300})
    np.testing.assert_allclose(y[:, 0], lag_response(t, u, TAU), rtol=1e-8)


def test_nan_output_is_reported(lag_me, held):
    t, u = held
    with pytest.raises(SimulationError, match=r"output 'y' is nan at t=0\.101"):
        _lag(lag_me, t, u, {"tau": TAU, "t_nan": 0.1})


def test_bad_solver_and_tolerance_are_refused(lag_me):
    with pytest.raises(FMUError, match="me_solver must be 'rk45' or 'cvode'"):
        FMUSession(lag_me, ["u"], ["y"], me_solver="euler")
    with pytest.raises(FMUError, match="tolerance must be a relative tolerance"):
        FMUSession(lag_me, ["u"], ["y"], tolerance=2.0)


def test_tolerance_and_step_size_are_used(lag_me, held):
    t, u = held
    exact = lag_response(t, u, TAU)
    loose, s = _lag(lag_me, t, u, {"tau": TAU}, tolerance=1e-3, step_size=0.5e-3)
    assert s.me_stats["steps"] == 2 * (t.size - 1)  # max step: two per sample
    assert np.max(np.abs(loose - exact)) < 1e-6


# ------------------------------------------------------- the plants, with state events


def _reference(model):
    folder = REF / model
    return read_csv(folder / f"{model}_in.csv"), read_csv(folder / f"{model}_ref.csv")


@pytest.mark.parametrize("version", [2, 3])
def test_siso_me_meets_every_stick_slip_switch(version):
    inp, ref = _reference("LSEA_SISO")
    t = ref["time"]
    idx = np.searchsorted(inp["time"], t, side="right") - 1  # the square wave, held
    u = inp["F_m"][idx]
    path = FMUS[version] / "LSEA_SISO.fmu"
    with FMUSession(path, ["F_m"], ["F_o", "x_m", "v_m", "F_mt"], interface="me") as s:
        y = s.simulate(t, u, {})
        stats = s.me_stats
    for j, name in enumerate(["F_o", "x_m", "v_m"]):
        assert nrms(y[:, j], ref[name]) < 1e-6, name  # the bound is 1 %
    assert_stick_slip(y[:, 2], y[:, 3])
    # every slip -> stick switch inside a step is located; the force steps are input events
    assert stats["state_events"] >= 40 and stats["input_events"] == 20


@pytest.mark.parametrize("version", [2, 3])
def test_miso_me_with_linear_inputs_matches_reference(version):
    inputs = ["F_m", "x_o", "v_o", "a_o"]
    inp, ref = _reference("LSEA_MISO")
    t = ref["time"]
    u = np.column_stack([np.interp(t, inp["time"], inp[n]) for n in inputs])
    path = FMUS[version] / "LSEA_MISO.fmu"
    hold = dict.fromkeys(inputs, "linear")
    with FMUSession(path, inputs, ["F_o"], interface="me", hold=hold) as s:
        y = s.simulate(t, u, {})[:, 0]
    assert nrms(y, ref["F_o"]) < 1e-6 < ACCEPT
