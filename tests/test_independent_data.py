"""The independently simulated data of the examples and the benchmark problems.

The generators must not use any FMU; here they are checked for determinism, the logged
columns of a real rig, stick-slip in the SISO data, and agreement with the FMUs at the
truth (which is the check that the two solutions of the same equations agree); but the
rigs of the DC motor and the resonance have, on purpose, effects their models leave out,
and their data must stay a stated floor away from their FMUs, also after the best fit.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmpy import read_model_description

from tsid_fmu.fmu import FMUSession

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from problems import base, dc_motor, local_minima, miso, siso  # noqa: E402

SISO_GEN = base.load_module(
    ROOT / "examples" / "lsea_siso" / "make_data.py", "tsid_examples_lsea_siso_make_data"
)
MISO_GEN = base.load_module(
    ROOT / "examples" / "lsea_miso" / "make_data.py", "tsid_examples_lsea_miso_make_data"
)


@pytest.fixture(scope="module")
def siso_frame() -> pd.DataFrame:
    return SISO_GEN.make_data(2024)


@pytest.fixture(scope="module")
def miso_frames() -> dict[str, pd.DataFrame]:
    return MISO_GEN.make_data(7)


def test_siso_generator_is_deterministic_per_seed(siso_frame):
    pd.testing.assert_frame_equal(SISO_GEN.make_data(2024), siso_frame)
    other = SISO_GEN.make_data(2025)
    assert not np.allclose(other["F_of"], siso_frame["F_of"])
    # the command and the encoder carry no random noise
    np.testing.assert_array_equal(other["F_m"], siso_frame["F_m"])
    np.testing.assert_array_equal(other["x_m"], siso_frame["x_m"])


def test_siso_columns_and_sensors(siso_frame):
    assert list(siso_frame.columns) == ["time", "F_m", "F_of", "F_or", "x_m"]
    t = siso_frame["time"].to_numpy()
    np.testing.assert_array_equal(t, np.round(np.arange(10001) * 1e-3, 9))
    steps = siso_frame["x_m"].to_numpy() / SISO_GEN.ENCODER_STEP
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)  # 1 um encoder
    # each compression-only cell reads noise around zero while the other carries the load
    front, rear = siso_frame["F_of"].to_numpy(), siso_frame["F_or"].to_numpy()
    idle = front > 50
    assert abs(np.std(rear[idle]) - SISO_GEN.NOISE["F_or"]) < 0.3


def test_committed_example_data_are_the_generators():
    committed = pd.read_csv(ROOT / "examples" / "lsea_siso" / "measured.csv")
    fresh = SISO_GEN.make_data(2024)
    assert list(committed.columns) == list(fresh.columns)
    np.testing.assert_allclose(committed.to_numpy(), fresh.to_numpy(), rtol=1e-8, atol=1e-12)


def test_siso_data_show_stick_slip():
    t = SISO_GEN.sample_times()
    _, v_m, _ = SISO_GEN.simulate(t, SISO_GEN.motor_force(t), SISO_GEN.TRUTH)
    band = np.abs(v_m) <= SISO_GEN.V_Z
    assert 0.2 < band.mean() < 0.95
    stick_starts = np.flatnonzero(np.diff(band.astype(int)) == 1)
    assert len(stick_starts) >= 10  # stuck again after each of many slip phases
    assert np.abs(v_m).max() > 100 * SISO_GEN.V_Z


@pytest.mark.slow
def test_siso_independent_solution_agrees_with_the_fmu():
    problem = siso.siso(encoder=True)
    data = problem.experiments[0].data
    t, f_m = data["time"].to_numpy(), data["F_m"].to_numpy()
    x_m, _, f_o = SISO_GEN.simulate(t, f_m, problem.truth)
    names = [*problem.truth, "V_z", "fixedStepSize"]
    with FMUSession(problem.fmu, ["F_m"], ["F_o", "x_m"], parameters=names) as fmu:
        y = fmu.simulate(t, f_m, {**problem.truth, **problem.start_values})
        rms_f, _ = base.rms_over_sigma(y[:, 0], f_o, problem.noise["F_o"])
        assert rms_f < 0.2
        # at the FMU's default internal step (1e-4 s) too: the Co-Simulation integrator
        # locates the short stick-band passages inside one internal step (was 3.7 um)
        rms_x, _ = base.rms_over_sigma(y[:, 1], x_m, 1e-6)
        assert rms_x < 0.003  # um
        fine = {**problem.truth, **problem.start_values, "fixedStepSize": 1e-6}
        y = fmu.simulate(t, f_m, fine)
    rms_x, _ = base.rms_over_sigma(y[:, 1], x_m, problem.noise["x_m"])
    assert rms_x < 0.2


@pytest.mark.parametrize("fmu", ["LSEA_SISO.fmu", "fmi3/LSEA_SISO.fmu"])
def test_siso_cs_at_default_step_matches_independent_solution(fmu):
    """Co-Simulation at fixedStepSize = 1e-4 s against the piecewise-exact solution.

    The velocity crosses the stick band |v_m| <= V_z in less than one internal step where
    it reverses under a large spring force; the FMU must locate both switches of such a
    passage. The bounds are 0.1 sigma of the 1 um encoder and 0.05 sigma of F_o.
    """
    t = SISO_GEN.sample_times()
    f_m = SISO_GEN.motor_force(t)
    x_m, _, f_o = SISO_GEN.simulate(t, f_m, SISO_GEN.TRUTH)
    path = ROOT / "fmus" / fmu
    md = read_model_description(str(path))
    assert [float(v.start) for v in md.modelVariables if v.name == "fixedStepSize"] == [1e-4]
    params = {**SISO_GEN.TRUTH, "V_z": SISO_GEN.V_Z}
    with FMUSession(path, ["F_m"], ["F_o", "x_m"], parameters=list(params)) as session:
        y = session.simulate(t, f_m, params)
    sigma_f = math.hypot(SISO_GEN.NOISE["F_of"], SISO_GEN.NOISE["F_or"])
    rms_x, _ = base.rms_over_sigma(y[:, 1], x_m, SISO_GEN.ENCODER_STEP / 12**0.5)
    rms_f, _ = base.rms_over_sigma(y[:, 0], f_o, sigma_f)
    assert rms_x < 0.1, rms_x  # measured: 0.0012
    assert rms_f < 0.05, rms_f  # measured: 3e-7


@pytest.mark.slow
def test_miso_generator_is_deterministic_and_logs_position_only(miso_frames):
    assert list(miso_frames) == ["force_only", "motion_only", "combined"]
    again = MISO_GEN.make_data(7)
    for name, frame in miso_frames.items():
        assert list(frame.columns) == ["time", "F_m", "x_o", "F_of", "F_or"]
        pd.testing.assert_frame_equal(again[name], frame)
    for name in miso_frames:
        committed = pd.read_csv(ROOT / "examples" / "lsea_miso" / f"{name}.csv")
        assert "v_o" not in committed.columns and "a_o" not in committed.columns
        np.testing.assert_allclose(
            committed.to_numpy(), miso_frames[name].to_numpy(), rtol=1e-8, atol=1e-12
        )
    # locked stage, motor off
    assert not miso_frames["force_only"]["x_o"].any()
    assert not miso_frames["motion_only"]["F_m"].any()


def test_miso_stage_starts_from_rest_and_is_smooth():
    t = MISO_GEN.sample_times()
    x_o, v_o, a_o = MISO_GEN.stage_motion(t)
    assert x_o[0] == v_o[0] == a_o[0] == 0.0
    dt = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(x_o, dt)[1:-1], v_o[1:-1], atol=1e-4)
    np.testing.assert_allclose(np.gradient(v_o, dt)[1:-1], a_o[1:-1], atol=1e-3)


@pytest.mark.slow
def test_miso_force_only_agrees_with_the_fmu(miso_frames):
    t = MISO_GEN.sample_times()
    f_m, stage = MISO_GEN.experiment_inputs("force_only", t)
    assert stage is None
    f_o = MISO_GEN.simulate(t, f_m, None, MISO_GEN.TRUTH)
    zero = np.zeros_like(t)
    problem_sigma = math.hypot(MISO_GEN.NOISE["F_of"], MISO_GEN.NOISE["F_or"])
    with FMUSession(
        ROOT / "fmus" / "LSEA_MISO.fmu",
        ["F_m", "x_o", "v_o", "a_o"],
        ["F_o"],
        parameters=list(MISO_GEN.TRUTH),
    ) as fmu:
        y = fmu.simulate(t, np.column_stack([f_m, zero, zero, zero]), MISO_GEN.TRUTH)
    rms, _ = base.rms_over_sigma(y[:, 0], f_o, problem_sigma)
    assert rms < 0.2


@pytest.mark.slow
def test_problem_structures():
    p = siso.siso(encoder=False)
    assert "x_m" not in p.experiments[0].data.columns and p.noise.keys() == {"F_o"}
    assert p.parameters["K_s"]["levels"] == [1000.0, 4000.0, 6000.0, 8000.0, 10000.0]
    m = miso.miso()
    assert [e.name for e in m.experiments] == ["force_only", "motion_only", "combined"]
    exp = m.experiments[1]
    assert exp.derived["v_o"] == "der(x_o)" and exp.derived["a_o"] == "der(x_o, 2)"
    for name, spec in m.parameters.items():
        lv = spec["levels"]
        assert len(lv) == 5 and lv[0] < m.truth[name] < lv[-1]
        assert lv[2] != pytest.approx(m.truth[name], rel=0.05)  # not centred on the truth


def test_dc_motor_and_local_minima_generators():
    a, b = dc_motor.make_data(3), dc_motor.make_data(3)
    pd.testing.assert_frame_equal(a, b)
    assert list(a.columns) == ["time", "V", "w", "i"]
    for name, value in dc_motor.TRUTH.items():
        lo, hi, _ = dc_motor.RANGES[name]
        assert hi / lo == pytest.approx(10.0)
        pos = base.log_position(value, lo, hi)
        assert 0.25 <= pos <= 0.4 or 0.6 <= pos <= 0.75
    c = local_minima.make_data(3)
    pd.testing.assert_frame_equal(c, local_minima.make_data(3))
    assert list(c.columns) == ["time", "u", "y"]


def _pythonfmu_ok() -> bool:
    sys.path.insert(0, str(ROOT / "tests"))
    from fmu_factory import pythonfmu_available

    return pythonfmu_available()


#: Floors of the mismatch the rig data must keep (issue 27: they matched their FMUs to
#: 1e-6 and 1e-4 sigma, so these problems compared optimisers, not accuracy under model
#: mismatch). Measured: DC motor 1.11 / 0.85 sigma at the truth and 0.44 / 0.40 after the
#: best fit (w / i); resonance 1.35 and 0.49 sigma.
DC_AT_TRUTH = {"w": 0.8, "i": 0.6}
DC_AFTER_FIT = {"w": 0.3, "i": 0.3}
RESONANCE_AT_TRUTH = 1.0
RESONANCE_AFTER_FIT = 0.35


@pytest.mark.skipif(not _pythonfmu_ok(), reason="pythonfmu cannot build here")
def test_dc_motor_fmu_is_the_model_and_misses_the_rig(tmp_path, monkeypatch):
    monkeypatch.setattr(base, "CACHE", tmp_path)
    problem = dc_motor.dc_motor(seed=1)
    t = base.sample_times(dc_motor.DURATION)
    v = dc_motor.voltage(t)
    model = dc_motor.simulate(t, v, problem.truth)
    rig = dc_motor.simulate_rig(t, v, problem.truth)
    with FMUSession(problem.fmu, ["V"], ["w", "i"], parameters=list(problem.truth)) as fmu:
        y = fmu.simulate(t, v, problem.truth)
    for k, name in enumerate(("w", "i")):
        # the FMU solves its equations right; the rig is another plant
        assert base.rms_over_sigma(y[:, k], model[:, k], problem.noise[name])[0] < 1e-6
        miss = base.rms_over_sigma(y[:, k], rig[:, k], problem.noise[name])[0]
        assert miss > DC_AT_TRUTH[name], (name, miss)


@pytest.mark.slow
def test_dc_motor_rig_data_stay_above_the_noise_after_the_best_fit():
    t = base.sample_times(dc_motor.DURATION)
    found, left = dc_motor.best_fit(t, dc_motor.voltage(t))
    for name, floor in DC_AFTER_FIT.items():
        assert left[name] > floor, (name, left[name])
    # small enough that the parameters stay sensible
    assert all(abs(found[n] / v - 1) < 0.15 for n, v in dc_motor.TRUTH.items()), found
    assert all(r < 0.8 for r in left.values())
    noisy = dc_motor.make_data(1)
    clean = dc_motor.simulate_rig(t, dc_motor.voltage(t), dc_motor.TRUTH)
    assert np.std(noisy["w"] - clean[:, 0]) == pytest.approx(dc_motor.NOISE["w"], rel=0.05)


@pytest.mark.skipif(importlib.util.find_spec("pymoca") is None, reason="needs [build]")
def test_resonance_fmu_is_the_model_and_misses_the_rig(tmp_path, monkeypatch):
    monkeypatch.setattr(base, "CACHE", tmp_path)
    problem = local_minima.local_minima(seed=1)
    data = problem.experiments[0].data
    t, u = data["time"].to_numpy(), data["u"].to_numpy()
    model = local_minima.simulate(t, u, problem.truth)
    rig = local_minima.simulate_rig(t, u, problem.truth)
    with FMUSession(problem.fmu, ["u"], ["y"], parameters=list(problem.truth)) as fmu:
        y = fmu.simulate(t, u, problem.truth)
    assert base.rms_over_sigma(y[:, 0], model, problem.noise["y"])[0] < 1e-4
    miss = base.rms_over_sigma(y[:, 0], rig, problem.noise["y"])[0]
    assert miss > RESONANCE_AT_TRUTH, miss


@pytest.mark.slow
def test_resonance_rig_data_stay_above_the_noise_after_the_best_fit():
    t = base.sample_times()
    found, left = local_minima.best_fit(t, local_minima.input_signal(t))
    assert RESONANCE_AFTER_FIT < left < 0.8, left
    assert all(abs(found[n] / v - 1) < 0.05 for n, v in local_minima.TRUTH.items()), found
