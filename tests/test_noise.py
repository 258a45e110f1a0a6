"""The noise estimate of measured data (``noise_level``), against known noise.

The bundled examples' generators state the noise they add (``NOISE`` in each
``make_data.py``): white noise on the load cells, the 1 um rounding of the encoders.
The synthetic signals cover what a rig logs: smooth motion sampled fast, steps and
impacts, quantised sensors, noise-free simulations and very short records.
"""

from __future__ import annotations

import importlib.util
import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.signal import butter, sosfiltfilt

from tsid_fmu.errors import DataError
from tsid_fmu.evaluate.cost import noise_level
from tsid_fmu.evaluate.noise import _TRIM_RMS, KEEP, quantum

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
T = np.arange(0.0, 10.0, 1e-3)  # 10 s at 1 kHz, as the examples' rig logs


def _generator_noise(example: str) -> dict[str, float]:
    sys.path.insert(0, str(EXAMPLES))  # the generators import examples/_datagen.py
    path = EXAMPLES / example / "make_data.py"
    spec = importlib.util.spec_from_file_location(f"tsid_noise_{example}_make_data", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return dict(module.NOISE)


def _smooth() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(11)
    low_passed = sosfiltfilt(butter(4, 5.0, fs=1000.0, output="sos"), rng.normal(0, 1, T.size))
    return {
        "sines": 100 * np.sin(2 * np.pi * T) + 20 * np.sin(2 * np.pi * 7.3 * T + 1),
        "slow ramp": 3.0 * T + 0.2 * T**2,
        "low-passed random": 300 * low_passed,
    }


def test_the_trimming_constant_is_the_gaussian_one():
    from scipy.stats import norm

    c = norm.ppf(0.5 + KEEP / 2)
    assert _TRIM_RMS == pytest.approx(math.sqrt((KEEP - 2 * c * norm.pdf(c)) / KEEP), rel=1e-6)


@pytest.mark.parametrize(
    ("example", "file"),
    [("lsea_siso", "measured"), ("lsea_miso", "motion_only"), ("lsea_miso", "combined"),
     ("lsea_miso", "force_only")],
)  # fmt: skip
def test_the_examples_noise_is_found_within_a_few_percent(example, file):
    """The load cells' white noise and the encoders' rounding, ``1e-6 / sqrt(12)`` m.

    Second differences alone gave the SISO encoder x_m 21 times its noise (6.1e-6 m).
    """
    truth = _generator_noise(example)
    frame = pd.read_csv(EXAMPLES / example / f"{file}.csv")
    for column, sigma in truth.items():
        y = frame[column].to_numpy()
        if np.ptp(y) == 0:  # the stage is locked in force_only: x_o logs no noise at all
            assert noise_level(y)[0] == 0
            continue
        assert noise_level(y)[0] == pytest.approx(sigma, rel=0.05), (file, column)
    f_o = (frame["F_of"] - frame["F_or"]).to_numpy()  # the derived channel the studies fit
    assert noise_level(f_o)[0] == pytest.approx(math.hypot(truth["F_of"], truth["F_or"]), rel=0.05)


@pytest.mark.parametrize("sigma", [0.01, 0.5, 3.0])
def test_white_noise_on_smooth_signals_steps_and_impacts(sigma):
    rng = np.random.default_rng(5)
    signals = _smooth()
    signals["steps"] = signals["sines"] + np.where(T % 2 < 1, 50.0, -50.0)
    signals["impacts"] = 80 * np.abs(np.sin(2 * np.pi * 1.5 * T))  # a bouncing ball's height
    columns = np.column_stack([s + rng.normal(0, sigma, T.size) for s in signals.values()])
    found = noise_level(columns)
    assert found.shape == (len(signals),)
    np.testing.assert_allclose(found, sigma, rtol=0.05, err_msg=str(list(signals)))


@pytest.mark.parametrize("q", [1e-3, 1e-2, 0.1])
def test_a_quantised_smooth_signal_has_its_rounding_noise(q):
    columns = np.column_stack([np.round(s / q) * q for s in _smooth().values()])
    np.testing.assert_allclose(noise_level(columns), q / math.sqrt(12), rtol=0.05)


def test_noise_free_signals_show_none():
    signals = _smooth()
    signals["on a grid"] = 0.5 * T  # a simulated ramp: every value on a grid of 5e-4
    signals["constant"] = np.full(T.size, 7.0)
    signals["square wave"] = np.where(T % 1 < 0.5, 150.0, -150.0)  # a command, no noise
    for name, y in signals.items():
        found = noise_level(y)[0]
        assert np.isfinite(found) and 0 <= found <= 1e-6 * max(np.ptp(y), 1.0), name
    assert quantum(0.5 * T) == 0 and quantum(signals["square wave"]) == 0


def test_a_grid_counts_only_where_the_rounding_acts():
    q = 1e-6
    encoder = np.round(0.01 * np.sin(2 * np.pi * T) / q) * q
    assert quantum(encoder) == pytest.approx(q)
    assert quantum(encoder + np.random.default_rng(2).normal(0, 1e-7, T.size)) == 0  # off grid


@pytest.mark.parametrize("n", [2, 3, 4, 5])
def test_short_columns_give_a_finite_answer_without_warnings(n):
    y = np.column_stack([np.arange(n) ** 2 * 0.3, np.random.default_rng(n).normal(0, 1, n)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = noise_level(y)
    assert found.shape == (2,) and np.all(np.isfinite(found)) and np.all(found >= 0)


@pytest.mark.parametrize("n", [0, 1])
def test_fewer_than_two_samples_is_a_data_error(n):
    with pytest.raises(DataError, match=f"at least 2 samples, got {n}"):
        noise_level(np.ones((n, 2)))
