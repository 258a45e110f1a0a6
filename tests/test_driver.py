from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from fmu_factory import (
    build_c_fmu,
    build_pythonfmu,
    build_stub_library,
    copy_without,
    lag_response,
    pythonfmu_available,
)

from tsid_fmu.errors import FMUError, SimulationError
from tsid_fmu.fmu import FMUSession, fmu_info

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmus")
    return {
        "fmi2": build_c_fmu(d, "Lag2"),
        "fmi2_me": build_c_fmu(d, "Lag2ME", interfaces=("me",)),
        "fmi3": build_c_fmu(d, "Lag3", fmi_version="3.0"),
        "dir": d,
    }


@pytest.fixture
def grid():
    t = np.arange(501) * 1e-3
    u = np.sin(7 * t) + (t > 0.2)
    return t, u


@pytest.mark.parametrize("kind", ["fmi2", "fmi3"])
def test_cs_matches_analytic_zoh(fmus, grid, kind):
    t, u = grid
    with FMUSession(fmus[kind], ["u"], ["y"], parameters=["tau", "x0"]) as s:
        y = s.simulate(t, u[:, None], {"tau": 0.05, "x0": 0.3})
        assert y.shape == (t.size, 1)
        np.testing.assert_allclose(y[:, 0], lag_response(t, u, 0.05, x0=0.3), atol=1e-12)
        assert s.interface == "cs"


def test_reset_gives_identical_runs_and_parameters_take_effect(fmus, grid):
    t, u = grid
    with FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["tau", "gain", "offset_on"]) as s:
        a = s.simulate(t, u, {"tau": 0.1})
        b = s.simulate(t, u, {"tau": 0.2})
        c = s.simulate(t, u, {"tau": 0.1})
        np.testing.assert_array_equal(a, c)
        assert not np.allclose(a, b)
        d = s.simulate(t, u, {"tau": 0.1, "gain": 2, "offset_on": True})
        np.testing.assert_allclose(d, 2 * a + 1)
        assert s.nfev == 4
        assert s.default_parameters() == {"tau": 1.0, "gain": 1.0, "offset_on": 0.0}
        # parameters from a previous run do not leak into the next (reset)
        np.testing.assert_array_equal(s.simulate(t, u, {"tau": 0.1}), a)


def test_start_values_applied_every_run(fmus, grid):
    t, u = grid
    with FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["tau"], start_values={"x0": 1.0}) as s:
        for _ in range(2):
            y = s.simulate(t, u, {"tau": 0.1})
            assert y[0, 0] == 1.0


def test_step_size_substeps(fmus):
    t = np.arange(11) * 0.1
    u = np.ones(11)
    with FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["tau"], step_size=0.01) as s:
        y = s.simulate(t, u, {"tau": 0.5})
    np.testing.assert_allclose(y[:, 0], 1 - np.exp(-t / 0.5), atol=1e-12)


def test_model_exchange(fmus, grid):
    t, u = grid
    with FMUSession(fmus["fmi2_me"], ["u"], ["y"], parameters=["tau"]) as s:
        assert s.interface == "me"
        y = s.simulate(t, u, {"tau": 0.05})
        np.testing.assert_allclose(y[:, 0], lag_response(t, u, 0.05), atol=2e-3)
        y2 = s.simulate(t, u, {"tau": 0.05})
        np.testing.assert_allclose(y, y2)
    with pytest.raises(FMUError, match=r"interface 'cs' requested.*only supports Model Exchange"):
        FMUSession(fmus["fmi2_me"], ["u"], ["y"], interface="cs")


def test_unknown_names_suggest(fmus):
    with pytest.raises(FMUError, match=r"Lag2.fmu: unknown parameter 'taU'.*Did you mean 'tau'"):
        FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["taU"])
    with pytest.raises(FMUError, match=r"unknown input 'uu'.*'u'"):
        FMUSession(fmus["fmi2"], ["uu"], ["y"])
    with pytest.raises(FMUError, match=r"unknown output 'yy'"):
        FMUSession(fmus["fmi2"], ["u"], ["yy"])
    with (
        FMUSession(fmus["fmi2"], ["u"], ["y"]) as s,
        pytest.raises(FMUError, match="unknown parameter 'tauu'"),
    ):
        s.simulate(np.arange(3.0), np.zeros(3), {"tauu": 1.0})


def test_wrong_causality_and_type(fmus):
    with pytest.raises(FMUError, match=r"input 'tau' has causality 'parameter', not 'input'"):
        FMUSession(fmus["fmi2"], ["tau"], ["y"])
    with pytest.raises(FMUError, match=r"parameter 'x' has causality 'local'"):
        FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["x"])
    with pytest.raises(FMUError, match=r"parameter 'c_const' is a constant"):
        FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["c_const"])
    with pytest.raises(FMUError, match=r"output 'gain' is of type Integer.*Real"):
        FMUSession(fmus["fmi2"], ["u"], ["gain"])


def test_not_a_zip_and_missing_files(tmp_path, fmus):
    bad = tmp_path / "bad.fmu"
    bad.write_text("hello")
    with pytest.raises(FMUError, match=r"bad.fmu: not an FMU \(an FMU is a ZIP archive\)"):
        FMUSession(bad, ["u"], ["y"])
    with pytest.raises(FMUError, match="FMU file not found"):
        FMUSession(tmp_path / "nope.fmu", ["u"], ["y"])
    no_md = copy_without(fmus["fmi2"], tmp_path / "nomd.fmu", "modelDescription.xml")
    with pytest.raises(FMUError, match=r"modelDescription\.xml is missing"):
        FMUSession(no_md, ["u"], ["y"])


def test_missing_platform_binary(tmp_path, fmus):
    import fmpy

    stripped = copy_without(fmus["fmi2"], tmp_path / "nobin.fmu", f"binaries/{fmpy.platform}")
    with pytest.raises(
        FMUError,
        match=rf"nobin.fmu: no binary for this platform: expected "
        rf"binaries/{fmpy.platform}/Lag2.so; platforms present: "
        r"none.*sources",
    ):
        FMUSession(stripped, ["u"], ["y"])


def test_unloadable_library_names_dependency(tmp_path):
    stub = build_stub_library(tmp_path / "dep", "tsidmissingdep")
    fmu = build_c_fmu(tmp_path, "NeedsDep", link_library=stub)
    shutil.rmtree(stub.parent)
    with pytest.raises(
        FMUError,
        match=r"NeedsDep.fmu: cannot load binaries/.*NeedsDep.so: it "
        r"needs libtsidmissingdep.so, which cannot be found",
    ):
        FMUSession(fmu, ["u"], ["y"])


@pytest.mark.parametrize("kind", ["fmi2", "fmi3"])
def test_fmi_error_mid_run_then_reusable(fmus, grid, kind):
    t, u = grid
    with FMUSession(fmus[kind], ["u"], ["y"], parameters=["tau", "t_fail"]) as s:
        with pytest.raises(
            SimulationError,
            match=r"DoStep returned Error at step 2[0-9]{2}, "
            r"t=0\.2.*time limit t_fail=0\.25",
        ):
            s.simulate(t, u, {"tau": 0.1, "t_fail": 0.25})
        good = s.simulate(t, u, {"tau": 0.1})
        np.testing.assert_allclose(good[:, 0], lag_response(t, u, 0.1), atol=1e-12)
        with pytest.raises(SimulationError, match=r"ExitInitializationMode.*tau must be positive"):
            s.simulate(t, u, {"tau": -1.0})
        np.testing.assert_array_equal(s.simulate(t, u, {"tau": 0.1}), good)


def test_reinstantiate_when_reset_fails(fmus, grid, monkeypatch):
    t, u = grid
    with FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["tau"]) as s:
        a = s.simulate(t, u, {"tau": 0.1})

        def broken_reset():
            raise RuntimeError("fmi2Reset failed")

        monkeypatch.setattr(s._fmu, "reset", broken_reset)
        first = s._component
        np.testing.assert_array_equal(s.simulate(t, u, {"tau": 0.1}), a)
        assert s._component is not None and s._component != 0
        assert first is not None


def test_non_finite_output(fmus, grid):
    t, u = grid
    with FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["t_nan"]) as s:
        with pytest.raises(SimulationError, match=r"output 'y' is nan at t=0\.301"):
            s.simulate(t, u, {"t_nan": 0.3})
        assert np.isfinite(s.simulate(t, u, {})).all()


def test_bad_arrays(fmus):
    with FMUSession(fmus["fmi2"], ["u"], ["y"]) as s:
        with pytest.raises(SimulationError, match="strictly increasing"):
            s.simulate(np.array([0.0, 0.0, 1.0]), np.zeros(3), {})
        with pytest.raises(SimulationError, match=r"inputs must have shape \(3, 1\)"):
            s.simulate(np.arange(3.0), np.zeros((3, 2)), {})
        with pytest.raises(SimulationError, match="inputs missing"):
            s.simulate(np.arange(3.0), None, {})


def test_read_only_arrays_checked_once_writeable_ones_every_time(fmus, monkeypatch):
    """Frozen time/input arrays skip the re-check; anything that can change does not."""
    t = np.arange(5.0)
    u = np.ones((5, 1))
    calls = []
    with FMUSession(fmus["fmi2"], ["u"], ["y"]) as s:
        real = s._validate_arrays
        monkeypatch.setattr(s, "_validate_arrays", lambda *a: calls.append(1) or real(*a))
        t_ro, u_ro = t.copy(), u.copy()
        t_ro.flags.writeable = u_ro.flags.writeable = False
        first = s.simulate(t_ro, u_ro, {})
        np.testing.assert_array_equal(s.simulate(t_ro, u_ro, {}), first)
        assert len(calls) == 1
        # writeable arrays are checked at every call, so a NaN written in between is found
        s.simulate(t, u, {})
        u[2, 0] = np.nan
        with pytest.raises(SimulationError, match=r"input 'u' is not finite at t=2"):
            s.simulate(t, u, {})
        # a read-only view of a writeable array can still change: not remembered either
        base = np.ones((5, 1))
        view = base.view()
        view.flags.writeable = False
        s.simulate(t_ro, view, {})
        base[3, 0] = np.inf
        with pytest.raises(SimulationError, match=r"input 'u' is not finite at t=3"):
            s.simulate(t_ro, view, {})


def test_extraction_folder_is_lent_per_session_and_kept_for_the_next(fmus, grid, tmp_path):
    """A closed session gives its folder back; the next session of the file reuses it."""
    t, u = grid
    s = FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["tau", "t_fail"])
    tmp = s.tempdir
    assert tmp is not None and tmp.is_dir()
    with pytest.raises(SimulationError), s:
        s.simulate(t, u, {"t_fail": 0.1})
    assert s.closed and s.tempdir is None
    assert tmp.is_dir()  # kept for the next session, removed at the process's exit
    s.close()  # idempotent
    with pytest.raises(SimulationError, match="closed"):
        s.simulate(t, u, {})

    # failure inside the constructor: the folder is given back, none is added
    with pytest.raises(FMUError):
        FMUSession(fmus["fmi2"], ["u"], ["nope"])
    with FMUSession(fmus["fmi2"], ["u"], ["y"]) as again:
        assert again.tempdir == tmp  # the same folder, so the same library file
        with FMUSession(fmus["fmi2"], ["u"], ["y"]) as both:  # open at the same time
            assert both.tempdir not in (None, tmp)
            np.testing.assert_array_equal(again.simulate(t, u, {}), both.simulate(t, u, {}))


def test_logger_receives_messages(fmus, grid):
    t, u = grid
    lines: list[str] = []
    with FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["t_fail"], logger=lines.append) as s:
        with pytest.raises(SimulationError):
            s.simulate(t, u, {"t_fail": 0.1})
    assert any("time limit" in line for line in lines)


def test_variables_and_info(fmus):
    with FMUSession(fmus["fmi2"], ["u"], ["y"]) as s:
        assert s.variables["tau"].unit == "s"
        assert s.model_description.modelName == "Lag2"
        assert "FMI 2.0" in repr(s)
    text = fmu_info(fmus["fmi2"])
    for part in (
        "FMI version      2.0",
        "Co-Simulation, Model Exchange",
        "linux64",
        "tau",
        "time constant",
        "start=1.0",
        "Inputs (1)",
        "Outputs (1)",
    ):
        assert part in text
    assert "3.0" in fmu_info(fmus["fmi3"])


@pytest.mark.skipif(not pythonfmu_available(), reason="pythonfmu cannot build here")
def test_pythonfmu_lag(tmp_path):
    try:
        fmu = build_pythonfmu(tmp_path)
    except RuntimeError as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))
    t = np.arange(101) * 0.01
    u = np.ones(101)
    with FMUSession(fmu, ["u"], ["y"], parameters=["tau"]) as s:
        y = s.simulate(t, u, {"tau": 0.5})
        y2 = s.simulate(t, u, {"tau": 0.5})
    euler = 1 - (1 - 0.01 / 0.5) ** np.arange(101)
    np.testing.assert_allclose(y[:, 0], euler, atol=1e-9)
    np.testing.assert_array_equal(y, y2)


@pytest.mark.parametrize("name", ["LSEA_SISO", "LSEA_MISO"])
def test_project_fmus_if_present(name):
    from fmpy.model_description import read_model_description

    fmu = REPO / "fmus" / f"{name}.fmu"
    if not fmu.exists():
        pytest.skip(f"{fmu} not built")
    assert "FMI version" in fmu_info(fmu)
    md = read_model_description(str(fmu), validate=False)
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    t = np.arange(1001) * 1e-3
    u = np.zeros((t.size, len(inputs)))
    u[:, 0] = 50 * np.sin(2 * np.pi * t)
    with FMUSession(fmu, inputs, outputs) as s:
        a = s.simulate(t, u, {})
        b = s.simulate(t, u, {})
    assert np.isfinite(a).all()
    np.testing.assert_array_equal(a, b)


def test_log_messages_reach_their_own_session_and_outlive_closed_ones(fmus, grid):
    """Two sessions at once each get their own FMU messages; once a session is closed and
    collected, an FMU that logs (here through plain FMPy) must not call into freed memory.
    FMPy's native log proxy keeps one global target, which used to be the newest session's
    callback: a dangling pointer and a segfault after that session was gone."""
    import gc

    from fmpy import extract
    from fmpy.fmi2 import FMU2Slave
    from fmpy.model_description import read_model_description

    t, u = grid
    failing = {"tau": 0.1, "t_fail": 0.25}
    with (
        FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["tau", "t_fail"]) as a,
        FMUSession(fmus["fmi2"], ["u"], ["y"], parameters=["tau", "t_fail"]) as b,
    ):
        with pytest.raises(SimulationError, match=r"time limit t_fail=0\.25"):
            a.simulate(t, u, failing)
        with pytest.raises(SimulationError, match=r"time limit t_fail=0\.15"):
            b.simulate(t, u, {"tau": 0.1, "t_fail": 0.15})
        assert not any("0.15" in m for m in a._log.messages)
        assert not any("0.25" in m for m in b._log.messages)
    del a, b
    gc.collect()
    md = read_model_description(str(fmus["fmi2"]))
    fmu = FMU2Slave(
        guid=md.guid,
        unzipDirectory=extract(str(fmus["fmi2"])),
        modelIdentifier=md.coSimulation.modelIdentifier,
    )
    fmu.instantiate()
    fmu.setReal([2, 4], [0.1, 0.01])
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    with pytest.raises(Exception, match="fmi2DoStep"):  # FMPy raises its own exception type
        for k in range(100):
            fmu.doStep(k * 1e-3, 1e-3)  # logs "time limit t_fail exceeded"
    fmu.freeInstance()
