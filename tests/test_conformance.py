"""The FMU conformance probe (issue 62): a broken reset, a non-deterministic FMU.

20-sim 4.6's ``fmi2Reset`` keeps the FMU's clock and its ``fmi2SetupExperiment``
restores the default parameters: after the first run no step integrates, and a study on
one reset instance "converged" at the start values with exit status 0. The quirk FMUs
here are the lag of :mod:`fmu_factory` built with ``quirks=``: ``STALE_CLOCK`` (that
FMU, FMI 2.0 and 3.0) and ``NONDETERMINISTIC`` (its output grows with every run). A
study on the first must end at the optimum (every run on a fresh instance), one on the
second with exit status 1 and a one-line reason -- never exit 0 with a wrong answer.
``LOOSE_TOLERANCE`` integrates on an internal grid set by the tolerance passed to it, not
by the communication step (a variable-step CS solver whose default tolerance is loose):
a study without ``cs_tolerance`` must adopt a tight one and end at the optimum.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, lag_data, lag_response

from tsid_fmu import Experiment, Parameter, Study, identify
from tsid_fmu.evaluate import conformance
from tsid_fmu.fmu import FMUSession
from tsid_fmu.status import MESSAGES, Verdict, study_status
from tsid_fmu.study.prepare import prepare
from tsid_fmu.uncertainty.fidelity import (
    CS_REFERENCE_TOLERANCE,
    CS_TOLERANCE,
    check_fidelity,
    fidelity_warnings,
)

T = np.arange(0, 2.0 + 1e-9, 0.01)
U = np.where(T < 1.0, 1.0, -0.5)


def _study(tmp_path, fmu, **options) -> Study:
    _, data = lag_data(tmp_path, 0.37, 0.8)
    return Study(
        fmu=fmu,
        parameters=[
            Parameter("tau", [0.05, 0.5, 2.0], min=0.0, unit="s"),
            Parameter("x0", [-1.0, 0.0, 2.0]),
        ],
        experiments=[Experiment(data=data, inputs={"u": "u"}, outputs={"y": "y_meas"})],
        **{"max_iterations": 6, "replicates": 1, **options},
    )


@pytest.fixture(scope="module")
def quirky(tmp_path_factory):
    d = tmp_path_factory.mktemp("quirks")
    return {
        ("STALE_CLOCK", "2.0"): build_c_fmu(
            d, "Stale2", interfaces=("cs",), quirks=["STALE_CLOCK"]
        ),
        ("STALE_CLOCK", "3.0"): build_c_fmu(d, "Stale3", fmi_version="3.0", quirks=["STALE_CLOCK"]),
        ("NONDETERMINISTIC", "2.0"): build_c_fmu(
            d, "Random2", interfaces=("cs",), quirks=["NONDETERMINISTIC"]
        ),
        ("NONDETERMINISTIC", "3.0"): build_c_fmu(
            d, "Random3", fmi_version="3.0", quirks=["NONDETERMINISTIC"]
        ),
        ("LOOSE_TOLERANCE", "2.0"): build_c_fmu(
            d, "Loose2", interfaces=("cs",), quirks=["LOOSE_TOLERANCE"]
        ),
        ("LOOSE_TOLERANCE", "3.0"): build_c_fmu(
            d, "Loose3", fmi_version="3.0", quirks=["LOOSE_TOLERANCE"]
        ),
        ("", "2.0"): build_c_fmu(d, "Plain2", interfaces=("cs",)),
    }


def _runs(fmu, fresh: bool) -> list[np.ndarray]:
    with FMUSession(fmu, ["u"], ["y"], parameters=["tau", "x0"], fresh=fresh) as s:
        runs = [s.simulate(T, U, {"tau": 0.3, "x0": 0.5})[:, 0] for _ in range(3)]
        assert s.instantiations == (3 if fresh else 1)
    return runs


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_a_stale_clock_integrates_once_on_a_reset_instance_and_always_on_fresh_ones(
    quirky, version
):
    fmu = quirky[("STALE_CLOCK", version)]
    exact = lag_response(T, U, 0.3, 0.5)
    first, second, _ = _runs(fmu, fresh=False)
    np.testing.assert_allclose(first, exact, rtol=1e-12)
    assert np.all(second == 0.5)  # the quirk: at the initial state for ever
    for y in _runs(fmu, fresh=True):
        np.testing.assert_allclose(y, exact, rtol=1e-12)


def _probe(tmp_path, fmu) -> dict:
    study = _study(tmp_path, fmu)
    return conformance.probe(prepare(study), {"tau": 0.5, "x0": 0.0})


def test_a_conforming_fmu_costs_the_probe_two_simulations(quirky, tmp_path):
    record = _probe(tmp_path, quirky[("", "2.0")])
    assert record["probed"] and record["reset"] and record["deterministic"]
    assert not record["fresh"] and record["simulations"] == 2
    assert conformance.warnings(record) == [] and conformance.problem(record) is None


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_the_probe_finds_the_broken_reset_and_chooses_fresh_instances(quirky, tmp_path, version):
    record = _probe(tmp_path, quirky[("STALE_CLOCK", version)])
    assert record["probed"] and not record["reset"] and record["deterministic"]
    assert record["fresh"] and record["simulations"] == 4
    assert "reset is broken" in conformance.warnings(record)[0]
    assert conformance.problem(record) is None


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_the_probe_finds_a_nondeterministic_fmu(quirky, tmp_path, version):
    record = _probe(tmp_path, quirky[("NONDETERMINISTIC", version)])
    assert record["probed"] and record["deterministic"] is False and not record["fresh"]
    assert "not deterministic" in conformance.warnings(record)[0]
    assert conformance.problem(record)


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_a_study_on_the_stale_clock_fmu_ends_at_the_optimum(quirky, tmp_path, version):
    study = _study(tmp_path, quirky[("STALE_CLOCK", version)])
    result = identify(study, tmp_path / "out", plots=False, workers=1, timeout=0)
    record = result.conformance
    assert record["fresh"] and not record["reset"]
    assert result.status == 0, result.message
    assert result.params["tau"] == pytest.approx(0.37, rel=0.02)
    assert result.params["x0"] == pytest.approx(0.8, rel=0.05)
    assert any("reset is broken" in w for w in result.warnings)
    assert result.summary()["conformance"]["fresh"] is True
    assert '"conformance"' in (tmp_path / "out" / "result.json").read_text()


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_a_study_on_a_nondeterministic_fmu_does_not_exit_0(quirky, tmp_path, version):
    study = _study(tmp_path, quirky[("NONDETERMINISTIC", version)], max_iterations=2)
    result = identify(study, plots=False, workers=1, timeout=0)
    assert result.status == 1 and not result.success
    assert result.message.startswith("stopped: the FMU does not reproduce its runs")
    assert "\n" not in result.message
    assert any("not deterministic" in w for w in result.warnings)


def test_the_fmu_verdict_has_its_own_code():
    status, code, message, told = study_status([], "its runs differ from each other")
    assert (status, code) == (1, Verdict.FMU) and Verdict.FMU in MESSAGES
    assert "its runs differ" in message and told[-1].startswith("FMU: ")


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_cs_tolerance_reaches_the_fmu(quirky, version):
    fmu = quirky[("NONDETERMINISTIC", version)]
    seen = []
    with FMUSession(fmu, ["u"], ["y"], cs_tolerance=1e-7) as s:
        wrapped = s._fmu.setupExperiment if version == "2.0" else s._fmu.enterInitializationMode

        def spy(**kwargs):
            seen.append(kwargs.get("tolerance"))
            return wrapped(**kwargs)

        name = "setupExperiment" if version == "2.0" else "enterInitializationMode"
        setattr(s._fmu, name, spy)
        s.simulate(T, U, {})
    with FMUSession(fmu, ["u"], ["y"]) as s:  # default: none defined
        assert s._inst.tolerance is None
    assert seen == [1e-7]


def test_tsid_info_says_whether_the_fmu_was_probed(quirky, capsys):
    from tsid_fmu.cli import main

    assert main(["info", str(quirky[("STALE_CLOCK", "2.0")]), "--probe"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("Conformance"))
    assert "not probed: the FMU has inputs" in line


def test_tsid_info_probes_an_fmu_without_inputs(tmp_path, capsys):
    from vdp_factory import build_vdp_fmu

    from tsid_fmu.cli import main

    fmu = build_vdp_fmu(tmp_path, "VdP", interfaces=("cs",))
    assert main(["info", str(fmu), "--probe"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("Conformance"))
    assert "a reset instance reproduces a fresh one" in line, line


@pytest.mark.parametrize("solver", ["rk45", "cvode"])
def test_fresh_instances_for_model_exchange_too(tmp_path, solver):
    fmu = build_c_fmu(tmp_path, "LagME", interfaces=("me",))
    runs = []
    with FMUSession(fmu, ["u"], ["y"], parameters=["tau"], me_solver=solver, fresh=True) as s:
        for _ in range(3):
            runs.append(s.simulate(T, U, {"tau": 0.3})[:, 0])
        assert s.instantiations == 3
    assert np.array_equal(runs[0], runs[1]) and np.array_equal(runs[0], runs[2])
    np.testing.assert_allclose(runs[0], lag_response(T, U, 0.3), atol=1e-3)  # CVode: 1e-5


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_a_loose_default_tolerance_biases_tau_and_a_tight_one_does_not(quirky, version):
    fmu = quirky[("LOOSE_TOLERANCE", version)]
    exact = lag_response(T, U, 0.37, 0.8)
    errors = {}
    for tol in (None, CS_TOLERANCE):
        for step in (None, 0.0025):  # a smaller communication step changes nothing
            with FMUSession(
                fmu, ["u"], ["y"], parameters=["tau", "x0"], step_size=step, cs_tolerance=tol
            ) as s:
                y = s.simulate(T, U, {"tau": 0.37, "x0": 0.8})[:, 0]
            errors[tol, step] = float(np.max(np.abs(y - exact)))
    assert errors[None, None] == errors[None, 0.0025] > 0.1
    assert errors[CS_TOLERANCE, None] < 1e-4 and errors[CS_TOLERANCE, 0.0025] < 1e-4


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_a_study_on_a_loose_tolerance_fmu_adopts_a_tight_one_and_ends_at_the_optimum(
    quirky, tmp_path, version
):
    study = _study(tmp_path, quirky[("LOOSE_TOLERANCE", version)])
    result = identify(study, tmp_path / "out", plots=False, workers=1, timeout=0)
    record = result.fidelity
    assert record["cs_tolerance"] == CS_TOLERANCE, record["reason"]
    assert "its default tolerance, not the physics, limits the answer" in record["reason"]
    assert record["start"]["matters"] and record["start"]["converges"] is True
    assert not record["answer"]["matters"], record["answer"]["message"]  # at 1e-8
    assert result.status == 0, result.message
    assert result.params["tau"] == pytest.approx(0.37, rel=0.01)
    assert result.params["x0"] == pytest.approx(0.8, rel=0.02)
    assert not any("solver fidelity" in w for w in result.warnings), result.warnings
    saved = (tmp_path / "out" / "result.json").read_text()
    assert '"cs_tolerance": 1e-08' in saved
    report = (tmp_path / "out" / "report.md").read_text()
    assert "- The FMU's own solver at tolerance 1e-08" in report


def test_a_study_that_sets_its_own_cs_tolerance_keeps_it_and_is_told_the_fix(quirky, tmp_path):
    fmu = quirky[("LOOSE_TOLERANCE", "2.0")]
    spec = prepare(_study(tmp_path, fmu, cs_tolerance=1e-3))
    check = check_fidelity(spec, {"tau": 0.37, "x0": 0.8})
    assert check.used.solver.tolerance == 1e-3  # the study's own reaches the check
    assert check.reference.tolerance == CS_REFERENCE_TOLERANCE
    assert check.matters and not check.adopted and check.cs_tolerance == 1e-3
    assert "cs_tolerance = 1e-08" in check.message and "fix:" in check.message
    assert fidelity_warnings(check, None) == [check.message]
    tight = check_fidelity(dataclasses.replace(spec, cs_tolerance=1e-9), {"tau": 0.37, "x0": 0.8})
    assert not tight.matters and tight.reference.tolerance == pytest.approx(1e-11)  # 100 x


def test_tsid_simulate_uses_the_adopted_tolerance(quirky, tmp_path, capsys):
    from tsid_fmu.cli import main

    study = _study(tmp_path, quirky[("LOOSE_TOLERANCE", "2.0")])
    identify(study, tmp_path / "out", plots=False, workers=1, timeout=0)
    toml = study.to_toml(tmp_path / "study.toml")
    args = ["simulate", str(toml), "--result", str(tmp_path / "out" / "result.json")]
    assert main([*args, "--csv", str(tmp_path / "sim.csv"), "--plot", str(tmp_path / "s.png")]) == 0
    sim = pd.read_csv(tmp_path / "sim.csv")
    data = pd.read_csv(tmp_path / "lag.csv")
    rms = float(np.sqrt(np.mean((sim["y"] - data["y_meas"]) ** 2)))
    assert rms < 2 * 0.01 * np.std(data["y_meas"])  # at the noise, not 7 % off
