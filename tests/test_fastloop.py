"""The compiled step loop: same outputs as the Python loop and FMPy, same errors, fallback."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from crash_factory import build_crash_fmu
from fmu_factory import build_c_fmu, lag_response

from tsid_fmu.errors import SimulationError
from tsid_fmu.evaluate.cost import Cost
from tsid_fmu.fmu import FMUSession
from tsid_fmu.fmu import compiled as fastloop

REPO = Path(__file__).resolve().parents[1]
needs_numba = pytest.mark.skipif(not fastloop.numba_available(), reason="Numba not installed")


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fastloop")
    return {
        "fmi2": build_c_fmu(d, "FLag2", interfaces=("cs",)),
        "fmi3": build_c_fmu(d, "FLag3", fmi_version="3.0"),
        "feed": build_crash_fmu(d, "Feed"),
    }


@pytest.fixture
def grid():
    t = np.arange(2001) * 1e-3
    u = np.sin(7 * t) + (t > 0.4)
    return t, u


@pytest.fixture
def python_loop(monkeypatch):
    monkeypatch.setenv(fastloop.LOOP_ENV, "python")
    yield
    monkeypatch.delenv(fastloop.LOOP_ENV)


def _run(path, t, u, params, names=("tau", "x0", "t_fail")):
    with FMUSession(path, ["u"], ["y"], parameters=list(names)) as s:
        return s.simulate(t, u, params)


@needs_numba
def test_backend_is_numba_and_loops_are_compiled():
    assert fastloop.warm_up() == "numba"
    assert fastloop.cs_loop(2).__name__ == "cs_loop_fmi2_numba"
    assert fastloop.cs_loop(3).__name__ == "cs_loop_fmi3_numba"


def test_env_variable_forces_python_loop(python_loop):
    from tsid_fmu.fmu.steploop import _cs_loop_fmi2, _cs_loop_fmi3

    assert fastloop.backend() == "python"
    assert fastloop.cs_loop(2) is _cs_loop_fmi2
    assert fastloop.cs_loop(3) is _cs_loop_fmi3


@needs_numba
@pytest.mark.parametrize("kind", ["fmi2", "fmi3"])
def test_compiled_loop_is_bit_identical_to_python_loop(fmus, grid, kind, monkeypatch):
    t, u = grid
    params = {"tau": 0.05, "x0": 0.3}
    fast = _run(fmus[kind], t, u, params)
    monkeypatch.setenv(fastloop.LOOP_ENV, "python")
    slow = _run(fmus[kind], t, u, params)
    np.testing.assert_array_equal(fast, slow)
    np.testing.assert_allclose(fast[:, 0], lag_response(t, u, 0.05, x0=0.3), atol=1e-12)


@needs_numba
def test_compiled_loop_handles_no_inputs_and_several_outputs(fmus, grid):
    t, _ = grid
    with FMUSession(fmus["fmi2"], [], ["y", "x"], parameters=["x0", "tau"]) as s:
        y = s.simulate(t, None, {"x0": 1.0, "tau": 0.1})
    np.testing.assert_allclose(y[:, 0], np.exp(-t / 0.1), rtol=1e-12)
    np.testing.assert_array_equal(y[:, 0], y[:, 1])


@pytest.mark.parametrize("backend", ["numba", "python"])
@pytest.mark.parametrize("kind", ["fmi2", "fmi3"])
def test_failing_step_names_call_step_and_time(fmus, grid, kind, backend, monkeypatch):
    if backend == "numba" and not fastloop.numba_available():
        pytest.skip("Numba not installed")
    if backend == "python":
        monkeypatch.setenv(fastloop.LOOP_ENV, "python")
    t, u = grid
    with FMUSession(fmus[kind], ["u"], ["y"], parameters=["tau", "t_fail"]) as s:
        with pytest.raises(SimulationError) as info:
            s.simulate(t, u, {"tau": 0.1, "t_fail": 0.5})
        v = 2 if kind == "fmi2" else 3
        text = str(info.value)
        assert f"fmi{v}DoStep returned Error at step 500, t=0.5" in text
        assert "time limit t_fail=0.5 exceeded" in text
        # the session stays usable
        np.testing.assert_allclose(
            s.simulate(t, u, {"tau": 0.1})[:, 0], lag_response(t, u, 0.1), atol=1e-12
        )


@pytest.mark.slow
def test_fallback_without_numba_gives_identical_output(fmus, grid, tmp_path):
    """Numba absent (import blocked): the Python loop runs, with the same result."""
    t, u = grid
    expected = _run(fmus["fmi2"], t, u, {"tau": 0.07})
    np.save(tmp_path / "t.npy", t)
    np.save(tmp_path / "u.npy", u)
    script = textwrap.dedent(
        f"""
        import sys
        sys.modules["numba"] = None  # import numba -> ImportError
        import numpy as np
        from tsid_fmu.fmu import compiled as fastloop
        from tsid_fmu.fmu import FMUSession
        assert not fastloop.numba_available()
        assert fastloop.backend() == "python", fastloop.backend()
        assert fastloop.warm_up() == "python"
        t = np.load({str(tmp_path / "t.npy")!r}); u = np.load({str(tmp_path / "u.npy")!r})
        with FMUSession({str(fmus["fmi2"])!r}, ["u"], ["y"], parameters=["tau"]) as s:
            np.save({str(tmp_path / "y.npy")!r}, s.simulate(t, u, {{"tau": 0.07}}))
        """
    )
    env = {k: v for k, v in os.environ.items() if k != fastloop.LOOP_ENV}
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=REPO
    )
    assert proc.returncode == 0, proc.stderr
    np.testing.assert_array_equal(np.load(tmp_path / "y.npy"), expected)


def test_fast_loop_matches_fmpy_simulate_fmu_costs(fmus, grid):
    """FMPy's own master gives the same outputs and costs (to 1e-9 relative)."""
    import fmpy

    t, u = grid
    for path, params in ((fmus["fmi2"], {"tau": 0.05}), (fmus["feed"], {"gain": 2.5})):
        names = list(params)
        with FMUSession(path, ["u"], ["y"], parameters=names) as s:
            ours = s.simulate(t, u, params)[:, 0]
        signal = np.zeros(t.size, dtype=[("time", np.float64), ("u", np.float64)])
        signal["time"], signal["u"] = t, u
        if path == fmus["feed"]:
            # FMPy's master reads the outputs of t[k+1] before it sets the inputs of
            # t[k+1]: one step of lag on a direct feed-through, which the session does
            # not have (it sets the inputs of t[k+1] first, as FMI co-simulation
            # implies). So FMPy gets each input one sample early, with an event at t[0]
            # (and a sample before it) so that its initialization still sets u[0].
            signal = np.zeros(t.size + 2, dtype=signal.dtype)
            signal["time"] = np.concatenate([t[:1] - 1, t[:1], t])
            signal["u"] = np.concatenate([u[:1], u[:1], u[1:], u[-1:]])
        ref = fmpy.simulate_fmu(
            str(path),
            start_values=params,
            input=signal,
            output=["y"],
            step_size=1e-3,
            output_interval=1e-3,
            stop_time=t[-1],
        )
        theirs = np.interp(t, ref["time"], ref["y"])
        measured = np.cos(3 * t)[:, None]
        cost = Cost("iae")
        a = cost.per_output(t, measured, ours[:, None])
        b = cost.per_output(t, measured, theirs[:, None])
        np.testing.assert_allclose(a, b, rtol=1e-9)
