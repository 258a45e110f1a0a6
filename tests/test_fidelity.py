"""Solver fidelity (issue 16): an FMU's own integrator, not the physics, deciding the answer.

The van der Pol FMU of ``vdp_factory`` integrates its Co-Simulation with forward Euler
at 10 ms, as the Modelica Association's Reference-FMUs do, and has an exact Model
Exchange interface. The data come from SciPy at ``rtol = 1e-12`` with mu = 1.7 and 1 %
noise. With Co-Simulation the identification misses mu by 4 %, hundreds of standard
errors; the check must say so and name the fix, and ``interface = "auto"`` must avoid it.
"""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_pythonfmu, pythonfmu_available
from vdp_factory import build_vdp_fmu, vdp_solution

from tsid_fmu import Experiment, Method, Parameter, Study, identify
from tsid_fmu.cli import main
from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.spec import PreparedExperiment
from tsid_fmu.study.prepare import prepare
from tsid_fmu.uncertainty.fidelity import (
    CS_REFERENCE_TOLERANCE,
    CS_TOLERANCE,
    THRESHOLD,
    check_fidelity,
    study_noise,
)
from tsid_fmu.uncertainty.solvers import Solver, SolverRuns, compare, output_noise

MU = 1.7
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def vdp(tmp_path_factory):
    d = tmp_path_factory.mktemp("vdp")
    t = np.linspace(0.0, 20.0, 2001)  # 10 ms samples, the FMU's Euler step
    y = vdp_solution(t, MU)
    sigma = 0.01 * np.sqrt(np.mean(y**2, axis=0))
    y = y + np.random.default_rng(1).standard_normal(y.shape) * sigma
    data = d / "vdp.csv"
    pd.DataFrame({"time": t, "x0": y[:, 0], "x1": y[:, 1]}).to_csv(data, index=False)
    return {
        "both": build_vdp_fmu(d, "VdpBoth"),
        "cs": build_vdp_fmu(d, "VdpCS", interfaces=("cs",)),
        "data": data,
    }


def vdp_study(vdp, fmu="both", **kw):
    return Study(
        fmu=vdp[fmu],
        parameters=[Parameter("mu", [1.0, 1.5, 2.0, 2.5, 3.0], min=0.1, max=10.0)],
        experiments=[Experiment(vdp["data"], outputs={"x0": "x0", "x1": "x1"}, name="vdp")],
        cost="sse",
        weighting="noise",
        replicates=1,
        **kw,
    )


@pytest.mark.slow
def test_cs_study_warns_of_solver_error_and_names_the_fix(vdp, tmp_path):
    events = []
    res = identify(
        vdp_study(vdp, interface="cs"),
        tmp_path / "out",
        plots=False,
        progress=lambda event, info: events.append((event, info)),
    )
    # the silent failure of the issue: 4 % off, the truth far outside the interval
    assert res.params["mu"] == pytest.approx(1.6288, rel=2e-3)
    low, high = res.intervals["mu"]
    assert not low <= MU <= high
    # ... is no longer silent: the first warning is the solver's, with figures and fix
    first = res.warnings[0]
    assert first.startswith("solver fidelity (answer): Co-Simulation")
    assert "differs from Model Exchange at tolerance 1e-12 by" in first
    assert 'fix in [method]: interface = "me"' in first
    assert "it alone moves mu by" in first
    record = res.fidelity
    assert record["requested"] == "cs" and record["interface"] == "cs"
    assert record["start"]["matters"] and record["answer"]["matters"]
    assert record["answer"]["used"]["ratio"] > 10  # RMS 24 x the noise on x1
    assert record["answer"]["bias"]["mu"] > 100  # standard errors
    me = [a for a in record["answer"]["alternatives"] if a["interface"] == "me"]
    assert me and me[0]["ratio"] < 1e-3
    # the fit-quality verdict names the mismatch too
    assert any("model or solver mismatch" in w and "vdp / x1" in w for w in res.warnings)
    # progress output, result.json and the report say the same
    said = [info["message"] for event, info in events if event == "fidelity"]
    assert [m.split(")")[0] for m in said] == [
        "solver fidelity (start point",
        "solver fidelity (answer",
    ]
    saved = json.loads((tmp_path / "out" / "result.json").read_text())
    assert saved["warnings"][0] == first
    assert saved["extra"]["fidelity"]["answer"]["message"] == first
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Solver fidelity" in report and first in report
    assert "**These intervals assume that the model explains the data" in report


@pytest.mark.slow
def test_auto_switches_to_model_exchange_and_finds_mu(vdp, tmp_path):
    out = tmp_path / "out"
    res = identify(vdp_study(vdp), out, plots=False)  # interface "auto" by default
    record = res.fidelity
    assert record["requested"] == "auto" and record["interface"] == "me"
    assert 'interface = "auto" uses Model Exchange instead' in record["start"]["message"]
    assert record["answer"]["used"]["interface"] == "me"
    assert not record["answer"]["matters"]
    assert abs(res.params["mu"] / MU - 1) < 0.005
    low, high = res.intervals["mu"]
    assert low <= MU <= high
    assert not any("solver" in w for w in res.warnings), res.warnings
    # tsid simulate --result replays the interface the study chose: a good fit
    plot = tmp_path / "fit.png"
    study_file = vdp_study(vdp).to_toml(tmp_path / "study.toml")
    code = main(["simulate", str(study_file), "--result", str(out), "--plot", str(plot)])
    assert code == 0 and plot.is_file()


def test_fidelity_false_skips_both_checks_and_says_so(vdp, tmp_path):
    events = []
    study = vdp_study(vdp, fidelity=False)  # interface "auto": Co-Simulation, unchecked
    res = identify(study, plots=False, progress=lambda event, info: events.append(event))
    assert "fidelity" not in events
    assert res.fidelity == {"checked": False, "reason": "[method] fidelity = false"}
    assert not any("solver fidelity" in w for w in res.warnings)
    assert res.params["mu"] == pytest.approx(1.6288, rel=2e-3)  # the Euler-biased answer
    again = Study.from_toml(study.to_toml(tmp_path / "study.toml"))
    assert again.method.fidelity is False
    with pytest.raises(StudyError, match="fidelity must be true or false"):
        vdp_study(vdp, fidelity="no")


def test_method_interface_replaces_the_study_key(vdp):
    spec = prepare(vdp_study(vdp, interface="me"))
    assert (spec.interface, spec.step_size, spec.tolerance) == ("me", None, 1e-10)
    spec = prepare(vdp_study(vdp, method=Method(interface="me", step=0.005)))
    assert (spec.interface, spec.step_size) == ("me", 0.005)


def test_loose_model_exchange_tolerance_is_flagged_with_its_fix(vdp, tmp_path):
    """The own ME integrator ends a step at every sample, so on 10 ms samples even a
    loose tolerance is accurate; on 0.5 s samples it takes long steps, and a tolerance of
    0.1 leaves an error above the threshold."""
    t = np.linspace(0.0, 20.0, 41)
    y = vdp_solution(t, MU)
    y = y + np.random.default_rng(1).standard_normal(y.shape) * 0.01 * np.sqrt(
        np.mean(y**2, axis=0)
    )
    coarse = tmp_path / "coarse.csv"
    pd.DataFrame({"time": t, "x0": y[:, 0], "x1": y[:, 1]}).to_csv(coarse, index=False)
    data = {**vdp, "data": coarse}
    spec = prepare(vdp_study(data, interface="me", tolerance=0.1))
    check = check_fidelity(spec, {"mu": MU})
    assert check.matters and check.interface == "me"
    assert "Model Exchange at tolerance 0.1 differs from" in check.message
    assert check.reference == Solver("me", tolerance=1e-12)
    assert "fix in [method]: tolerance = 1e-12" in check.message
    # within the threshold at the study's default tolerance
    check = check_fidelity(prepare(vdp_study(data, interface="me")), {"mu": MU})
    assert not check.matters and check.used.ratio < 1e-3
    assert check.message.endswith(f"(threshold {THRESHOLD:g})")


def test_cs_only_fmu_is_compared_with_a_four_times_smaller_step(vdp):
    spec = prepare(vdp_study(vdp, fmu="cs"))
    check = check_fidelity(spec, {"mu": MU})
    assert check.reference.interface == "cs"
    assert check.reference.step == pytest.approx(0.0025, rel=1e-9)
    # the study's step, the reference (4 x smaller and a tight tolerance), a step 4 x
    # smaller still: Euler converges; then each setting alone, the step and the tolerance
    assert check.matters and check.interface == "cs" and check.simulations == 5
    assert check.converges is True and check.reference.tolerance == CS_REFERENCE_TOLERANCE
    step, tight = check.alternatives[1:]
    assert step.solver == Solver("cs", step=check.reference.step) and step.ratio < 1e-9
    assert tight.solver.tolerance == CS_TOLERANCE and tight.ratio == check.used.ratio
    assert check.cs_tolerance is None and not check.adopted  # its Euler has no tolerance
    assert "differs from Co-Simulation at step 0.0025 s" in check.message
    assert "fix: a smaller communication step, step = 0.0025 or less" in check.message
    # a step 4 x smaller than the study's own; Euler's error falls with the step
    fine = check_fidelity(dataclasses.replace(spec, step_size=0.001), {"mu": MU})
    assert fine.reference.step == pytest.approx(0.00025, rel=1e-9)
    assert 8 < check.used.ratio / fine.used.ratio < 12
    assert "step = 0.00025 or less" in fine.message


def test_a_failing_start_point_leaves_the_check_undone(vdp):
    spec = prepare(vdp_study(vdp))
    check = check_fidelity(spec, {"mu": 1e6})  # Euler diverges to inf
    assert not check.checked and not check.matters and check.interface == "cs"
    assert check.message.startswith("solver fidelity (start point): not checked")


def test_study_keys_interface_step_tolerance(vdp, tmp_path):
    study = vdp_study(vdp, method=Method(interface="me", step=0.005, tolerance=1e-9))
    back = Study.from_toml(study.to_toml(tmp_path / "s.toml"))
    assert (back.method.interface, back.method.step, back.method.tolerance) == ("me", 0.005, 1e-9)
    assert 'interface = "me"' in (tmp_path / "s.toml").read_text()
    with pytest.raises(StudyError, match=r"\[study\] interface = 'cs' and \[method\] interface"):
        vdp_study(vdp, interface="cs", method=Method(interface="me"))
    with pytest.raises(StudyError, match=r"\[study\] step_size = 0.01 and \[method\] step"):
        vdp_study(vdp, step_size=0.01, step=0.02)
    with pytest.raises(StudyError, match="interface must be 'auto', 'cs' or 'me', got 'fast'"):
        Method(interface="fast")
    with pytest.raises(StudyError, match="tolerance must be between 0 and 1"):
        vdp_study(vdp, tolerance=2.0)
    with pytest.raises(StudyError, match="step must be at least 1e-9 s"):
        vdp_study(vdp, step=0.0)


def _first_seconds(spec, seconds):
    def cut(e):
        n = round(seconds / (e.time[1] - e.time[0])) + 1
        return PreparedExperiment(
            e.name, e.time[:n], e.input_names, e.output_names,
            None if e.inputs is None else e.inputs[:n], e.measured[:n], e.weights, e.scale,
            start_values=e.start_values, hold=e.hold,
        )  # fmt: skip

    return dataclasses.replace(spec, experiments=tuple(cut(e) for e in spec.experiments))


SISO_TRUTH = {"F_cm": 88.5, "F_vm": 51.5, "M_m": 4.3, "K_s": 8600.0, "B_s": 2.5}
MISO_TRUTH = {"m1": 0.45, "m2": 0.2, "K_s": 5000.0, "C_d": 5.0, "C_1": 20.0, "C_2": 2.0}


@pytest.mark.parametrize(
    ("example", "truth"), [("lsea_siso", SISO_TRUTH), ("lsea_miso", MISO_TRUTH)]
)
def test_bundled_fmus_raise_no_warning(example, truth):
    # their Co-Simulation matches an accurate Model Exchange solution to the noise (the
    # first 2 s of the examples' data, at the true parameters)
    study = Study.from_toml(EXAMPLES / example / "study.toml")
    spec = _first_seconds(prepare(study), 2.0)
    check = check_fidelity(spec, truth, noise=study_noise(study))
    assert check.checked and not check.matters, check.message
    assert check.interface == "cs" and check.used.ratio < 0.01, check.message


def test_linear_inputs_do_not_make_model_exchange_blame_co_simulation():
    # FMPy's CVode held the stage motion (linear inputs) over each solver call and differed
    # from the exact Co-Simulation by more than the threshold; the own Model Exchange
    # integrator sets linear inputs at every stage and agrees as it is. On held inputs for
    # both, or extrapolated (Richardson), they agree as well
    study = Study.from_toml(EXAMPLES / "lsea_miso" / "study.toml")
    spec = _first_seconds(prepare(study, ["motion only"]), 2.0)
    noise = [output_noise(e) for e in spec.experiments]
    cs, ref = Solver("cs"), Solver("me", tolerance=1e-12)
    runs = SolverRuns(spec, MISO_TRUTH)
    raw = np.sqrt(np.mean((runs.run(cs, 0) - runs.run(ref, 0)) ** 2, axis=0)) / noise[0]
    assert raw.max() < 1e-3
    runs = SolverRuns(spec, MISO_TRUTH)
    assert compare(runs, cs, ref, noise, THRESHOLD).ratio < 1e-3
    assert runs.count == 2  # both on held inputs
    runs = SolverRuns(spec, MISO_TRUTH)
    assert compare(runs, cs, ref, noise, 0.0).ratio < 0.01  # threshold 0: Richardson
    assert runs.count == 5  # held cs and me, then cs, me and me on a twice finer grid


@pytest.mark.skipif(not pythonfmu_available(), reason="needs pythonfmu and a shared libpython")
def test_an_fmu_that_acts_once_per_step_keeps_the_step_and_says_why(tmp_path):
    """PythonFMU3's FMU3Model adds ``increment`` at every step (issue 43): the check
    advised a 4 x smaller step, and following it ended at -74 % with a new warning asking
    for a smaller one still. Outputs that do not converge as the step shrinks are the
    FMU's design, not a solver error."""
    fmu = build_pythonfmu(tmp_path, "Counter", counter=True)
    t = np.round(np.arange(0.0, 2.0 + 1e-9, 0.1), 10)
    u = 1.0 + 0.5 * np.sin(t)
    y = np.concatenate([[0.0], np.cumsum(2.0 * u[:-1])])  # y_k+1 = y_k + 2 u_k
    noisy = y + np.random.default_rng(0).normal(0, 0.02, y.shape)
    pd.DataFrame({"time": t, "u": u, "y": noisy}).to_csv(tmp_path / "d.csv", index=False)
    study = Study(
        fmu=fmu,
        parameters=[Parameter("increment", [0.5, 1.0, 4.0], min=0.0)],
        experiments=[Experiment(tmp_path / "d.csv", inputs={"u": "u"}, outputs={"y": "y"})],
        cost="sse",
        weighting="noise",
        replicates=1,
    )
    check = check_fidelity(prepare(study), {"increment": 2.0})
    assert check.converges is False and not check.matters and check.interface == "cs"
    assert check.alternatives[0].ratio > 2 * check.used.ratio  # it grows as the step shrinks
    assert "do not converge as the communication step shrinks" in check.message
    assert "the study keeps its step" in check.message
    assert "and that from Co-Simulation at step 0.00625 s, tolerance 1e-10 by" in check.message
    result = identify(study, progress=False, plots=False)
    assert result.params["increment"] == pytest.approx(2.0, rel=0.01)
    assert any("do not converge as the communication step shrinks" in w for w in result.warnings)
