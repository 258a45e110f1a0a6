"""Three more quirks of issue 62, item 8: an assertion, a parameter that does nothing, a time step.

The lag of :mod:`fmu_factory`, Co-Simulation only, built with ``quirks=``:

- ``ASSERT_RANGE``: a step fails on an assertion where ``tau`` > 1.2 ("outside scope
  of model", as Dymola's models assert on a temperature); the study's levels reach 2.
- ``NO_EFFECT``: a parameter ``spare`` that acts on nothing.
- ``NUMERICAL_SETTING``: the FMU integrates explicit Euler on an internal grid of step
  ``timestep`` (a parameter in s, 1e-3), as Hopsan's FMUs expose their time step. Its
  error moves ``tau`` by 2.7 standard errors on these data. The solver-fidelity check's
  reference used to run the FMU at a smaller communication step and a tighter tolerance
  only, which that grid ignores, and said "matches ... to 0 x the noise".

Each study ends at the optimum or says why it cannot be trusted, and ``tsid init`` frees
neither ``spare`` nor ``timestep``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, lag_response

from tsid_fmu import Experiment, Parameter, Study, identify
from tsid_fmu.fmu.variables import VariableInfo
from tsid_fmu.scaffold import init_study
from tsid_fmu.scaffold_rules import time_step_setting
from tsid_fmu.study.prepare import prepare
from tsid_fmu.uncertainty.fidelity import check_fidelity

TRUTH = {"tau": 0.37, "x0": 0.8}


@pytest.fixture(scope="module")
def quirky(tmp_path_factory):
    d = tmp_path_factory.mktemp("quirks")
    fmus = {
        q: build_c_fmu(d, q.title().replace("_", ""), interfaces=("cs",), quirks=[q])
        for q in ("ASSERT_RANGE", "NO_EFFECT", "NUMERICAL_SETTING")
    }
    t = np.arange(0, 5.0 + 1e-9, 0.01)
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5) + 0.3 * np.sin(3 * t)
    y = lag_response(t, u, TRUTH["tau"], TRUTH["x0"])  # exact, not the FMU's Euler
    y = y + np.random.default_rng(0).normal(0, 0.01 * np.std(y), y.shape)
    data = d / "lag.csv"
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(data, index=False)
    return fmus, data


def _study(fmu, data, *extra: Parameter, **options) -> Study:
    return Study(
        fmu=fmu,
        parameters=[
            Parameter("tau", [0.05, 0.5, 2.0], min=0.0, unit="s"),
            Parameter("x0", [-1.0, 0.0, 2.0]),
            *extra,
        ],
        experiments=[Experiment(data=data, inputs={"u": "u"}, outputs={"y": "y"})],
        **{"max_iterations": 12, "replicates": 1, **options},
    )


def _info(name: str, unit: str | None = "s", description: str = "") -> VariableInfo:
    return VariableInfo(name, 0, "Real", "parameter", "fixed", "exact", "0.001", unit, description)


def test_the_fmus_own_time_steps_are_told_from_times_of_the_plant():
    for name in ("timestep", "fixedStepSize", "solver.dt", "h", "step"):
        assert time_step_setting(_info(name)), name
    assert time_step_setting(_info("tint", description="internal step of the integrator"))
    # a step source's time, a sampled controller's period, a step without the unit s
    for name in ("stepTime", "step.startTime", "Ts", "samplePeriod", "T"):
        assert not time_step_setting(_info(name)), name
    assert not time_step_setting(_info("timestep", unit=None))
    assert not time_step_setting(dataclasses.replace(_info("timestep"), causality="local"))


def test_the_reference_runs_the_fmus_own_time_step_smaller(quirky):
    fmus, data = quirky
    spec = prepare(_study(fmus["NUMERICAL_SETTING"], data))
    check = check_fidelity(spec, TRUTH)
    assert check.reference.settings == (("timestep", 0.00025),)
    assert check.used.ratio > 0.1, check.message  # was "matches ... to 0 x the noise"
    fast = {"tau": 0.2, "x0": 0.8}  # Euler's error grows as h / tau: well past 0.2 x the noise
    check = check_fidelity(spec, fast)
    assert check.matters, check.message
    assert "fix: the FMU's own time step smaller, start_values = { timestep = 0.00025 }" in (
        check.message
    )
    fixed = dataclasses.replace(spec, start_values={"timestep": 0.00025})
    again = check_fidelity(fixed, fast)
    assert again.reference.settings == (("timestep", 6.25e-05),)
    assert not again.matters and again.used.ratio < 0.1, again.message
    # a time step the study identifies is the study's, not the reference's
    free = prepare(_study(fmus["NUMERICAL_SETTING"], data, Parameter("timestep", [1e-3, 2e-3])))
    assert check_fidelity(free, {**TRUTH, "timestep": 1e-3}).reference.settings == ()


def test_a_study_on_the_fmus_own_coarse_step_warns_with_the_fix_and_ends_in_it(quirky, tmp_path):
    fmus, data = quirky
    result = identify(_study(fmus["NUMERICAL_SETTING"], data), plots=False, workers=1, timeout=0)
    warned = [w for w in result.warnings if w.startswith("solver fidelity (answer)")]
    assert warned and "start_values = { timestep = 0.00025 }" in warned[0], result.warnings
    assert "moves tau by" in warned[0]
    fixed = identify(
        _study(fmus["NUMERICAL_SETTING"], data, start_values={"timestep": 0.00025}),
        plots=False,
        workers=1,
        timeout=0,
    )
    assert fixed.status == 0, fixed.message
    assert not any(w.startswith("solver fidelity") for w in fixed.warnings), fixed.warnings
    low, high = fixed.intervals["tau"]
    assert low <= TRUTH["tau"] <= high


def test_init_frees_neither_the_time_step_nor_a_parameter_without_effect(quirky, tmp_path):
    fmus, data = quirky
    text = init_study(fmus["NUMERICAL_SETTING"], data, tmp_path / "step.toml", workers=1)
    assert "\n# timestep = {" in text and "numerical, not physical" in text
    text = init_study(fmus["NO_EFFECT"], data, tmp_path / "spare.toml", workers=1)
    assert "\n# spare = {" in text and "no effect the data can see" in text


def test_a_study_whose_levels_fail_an_assertion_ends_at_the_optimum(quirky):
    fmus, data = quirky
    result = identify(_study(fmus["ASSERT_RANGE"], data), plots=False, workers=1, timeout=0)
    assert result.status == 0, result.message
    assert result.params["tau"] == pytest.approx(TRUTH["tau"], rel=0.01)
    assert result.params["x0"] == pytest.approx(TRUTH["x0"], rel=0.02)
    failed = [r for s in result.stages for rec in s.records for r in rec.errors if r]
    assert failed and all("outside scope of model" in r for r in failed)


def test_a_parameter_without_effect_is_reported_so_and_the_others_are_found(quirky):
    fmus, data = quirky
    spare = Parameter("spare", [0.5, 1.0, 2.0])
    result = identify(_study(fmus["NO_EFFECT"], data, spare), plots=False, workers=1, timeout=0)
    assert result.status == 0, result.message
    assert result.params["tau"] == pytest.approx(TRUTH["tau"], rel=0.01)
    assert "spare" in result.weak and None in result.intervals["spare"], result.weak
