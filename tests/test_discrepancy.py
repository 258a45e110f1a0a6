"""Do the intervals hold? The verdict on the model's fit (``tsid_fmu.uncertainty.discrepancy``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tsid_fmu.report.notebook import MARKS, parameter_rows
from tsid_fmu.uncertainty.discrepancy import ALPHA, Discrepancy, constancy, judge

N = 2000
TIME = np.linspace(0.0, 20.0, N)
JAC = np.column_stack([np.sin(TIME), np.cos(0.7 * TIME), np.ones(N)])


def _ar1(rng: np.random.Generator, phi: float) -> np.ndarray:
    e = rng.normal(0.0, 1.0, N)
    out = np.empty(N)
    out[0] = e[0]
    for i in range(1, N):
        out[i] = phi * out[i - 1] + e[i] * np.sqrt(1 - phi**2)
    return out


def _test(data: np.ndarray) -> dict:
    """Fit ``JAC`` to ``data`` and run the constancy test as the intervals' series do."""
    theta = np.linalg.lstsq(JAC, data, rcond=None)[0]
    r = JAC @ theta - data
    sigma = np.sqrt(np.mean(r**2))
    series = [("e", "y", r / sigma, JAC / sigma)]
    fisher = series[0][3].T @ series[0][3]
    return constancy(series, np.linalg.pinv(fisher))


def test_a_correct_model_passes_with_white_and_with_coloured_noise():
    rng = np.random.default_rng(7)
    truth = JAC @ np.array([1.0, -0.5, 0.2])
    white = [_test(truth + rng.normal(0.0, 1.0, N))["p_value"] for _ in range(20)]
    coloured = [_test(truth + _ar1(rng, 0.8))["p_value"] for _ in range(20)]
    assert min(white) > ALPHA and min(coloured) > ALPHA
    # and the p-values spread over (0, 1) as they should for a true null
    assert 0.2 < float(np.median(white)) < 0.8


def test_a_gain_that_drifts_over_the_record_is_a_mismatch():
    rng = np.random.default_rng(8)
    drift = 1.0 + 0.1 * TIME / TIME[-1]  # the plant's gain rises by 10 % over the record
    data = JAC @ np.array([1.0, -0.5, 0.2]) * drift + rng.normal(0.0, 0.1, N)
    found = _test(data)
    assert found["p_value"] < 1e-5 and found["dof"] == 3 and found["segments"] == 2
    verdict = judge(found, [], [])
    assert verdict.verdict == "mismatch" and not verdict.holds
    assert "constancy test" in verdict.warning() and "do not hold" in verdict.warning()


def test_scores_that_do_not_sum_to_zero_are_no_mismatch():
    """A correct model, tested where its scores do not sum to zero: a Jacobian a little
    off the one the optimum was found with (forward differences of 2e-3 across the
    corners of OpenModelica's ramp, which move with its start time and duration), or an
    answer a little off the optimum. Each segment is tested less its share of the total
    score, so that is not read as the segments calling for different parameters; with
    the raw scores it was (the ramp: p = 7.6e-6 at a step of 2e-3, 0.24 at 5e-4)."""
    rng = np.random.default_rng(9)
    data = JAC @ np.array([1.0, -0.5, 0.2]) + rng.normal(0.0, 1.0, N)
    theta = np.linalg.lstsq(JAC, data, rcond=None)[0]
    inverse = np.linalg.pinv(JAC.T @ JAC)
    for shift in (0.0, 0.1, 0.3):
        r = JAC @ (theta + np.array([shift, 0.0, 0.0])) - data
        found = constancy([("e", "y", r, JAC)], inverse)
        assert found["p_value"] > 0.5 and found["dof"] == 3, (shift, found)


def test_the_verdict_is_one_decision_over_every_piece_of_evidence():
    calm = {"statistic": 1.0, "dof": 3, "p_value": 0.8, "segments": 2}
    assert judge(calm, [], []).verdict == "consistent" and judge(calm, [], []).warning() == ""
    coloured = judge(calm, ["e / y"], [], inflation=2.0)
    assert coloured.verdict == "coloured" and "may not hold" in coloured.warning()
    assert "cannot tell which" in coloured.warning() and "~x2" in coloured.warning()
    assert judge(calm, [], ["e / y"]).verdict == "mismatch"
    assert judge(calm, ["e / y"], ["e / y"]).verdict == "mismatch"


@pytest.mark.parametrize("verdict", ["consistent", "coloured", "mismatch"])
def test_the_parameter_table_says_in_each_interval_when_it_does_not_hold(verdict):
    u = SimpleNamespace(discrepancy=Discrepancy(verdict=verdict), relative={"k": 1.0})
    result = SimpleNamespace(
        study=None,
        params={"k": 2.0, "c": 1.0},
        names=["k", "c"],
        structure=None,
        intervals={"k": [1.9, 2.1], "c": [None, None]},
        uncertainty=u,
        weak={},
        sampled=None,
    )
    rows = {r[0]: r[3] for r in parameter_rows(result)}
    assert rows["k"].endswith(MARKS.get(verdict, "")) and rows["k"].startswith("1.9")
    assert (verdict == "consistent") == ("hold" not in rows["k"])
    assert rows["c"] == "not determined"
