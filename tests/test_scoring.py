import warnings

import numpy as np
import pytest

from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.cost import Cost, fit_percent, metrics


def test_costs_on_known_signals():
    t = np.linspace(0, 2, 2001)
    y = np.sin(t)
    s = y + 0.5
    assert Cost("iae")(t, y, s) == pytest.approx(1.0)
    assert Cost("sse")(t, y, s) == pytest.approx(0.25 * t.size)
    assert Cost("rmse")(t, y, s) == pytest.approx(0.5)
    assert Cost("ise")(t, y, s) == pytest.approx(0.5)


def test_fit_percent_and_nrmse():
    y = np.array([0.0, 1.0, 2.0, 3.0])
    assert fit_percent(y, y)[0] == pytest.approx(100)
    assert fit_percent(y, np.full(4, y.mean()))[0] == pytest.approx(0)
    m = metrics(np.arange(4.0), y, y + 0.1, ["out"])
    assert m["out"]["fit_percent"] == pytest.approx(100 * (1 - m["out"]["nrmse"]))


def test_weights_and_non_finite():
    t = np.arange(5.0)
    y = np.zeros((5, 2))
    s = np.column_stack([np.ones(5), 2 * np.ones(5)])
    assert Cost("sse", weights=(1, 0.5))(t, y, s) == pytest.approx(5 + 0.5 * 20)
    s[2, 1] = np.nan
    assert Cost("sse")(t, y, s) == np.inf
    with pytest.raises(StudyError, match="weights"):
        Cost("sse", weights=(1,))(t, y, np.ones((5, 2)))


def test_a_finite_simulation_whose_square_overflows_costs_inf_without_a_warning():
    t = np.arange(3.0)
    huge = np.array([1e200, -1e200, 0.0])  # finite, but its square is not
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning would fail the test
        assert Cost("sse")(t, np.zeros(3), huge) == np.inf
        assert Cost("ise")(t, np.zeros(3), huge) == np.inf


def test_unknown_cost_is_named():
    with pytest.raises(StudyError, match="unknown cost 'mae'"):
        Cost("mae")


def test_noise_level_sees_white_noise_through_signal_and_steps():
    from tsid_fmu.evaluate.cost import noise_level

    t = np.arange(0, 10, 1e-3)
    smooth = 100 * np.sin(2 * np.pi * t) + np.where(t % 2 < 1, 50.0, -50.0)  # with steps
    rng = np.random.default_rng(3)
    y = np.column_stack(
        [smooth + rng.normal(0, 1.6, t.size), smooth / 4 + rng.normal(0, 0.4, t.size)]
    )
    sigma = noise_level(y)
    assert sigma == pytest.approx([1.6, 0.4], rel=0.05)
    assert noise_level(smooth)[0] < 0.01  # a clean signal shows (almost) none
