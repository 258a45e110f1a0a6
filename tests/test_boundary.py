"""The score test at a nesting point (:mod:`tsid_fmu.search.structure.boundary`).

The toy is the SISO plant's pair in miniature: the first output depends on ``v + b``
only (the motion, through viscous friction plus spring damping), the second on ``b``
alone (the load cells). Its richer structure nests the simpler one at ``b = 0``, a lower
bound. At the simpler fit embedded (``b = 0``, ``v`` = the sum), moving ``b`` alone
worsens the motion, so its own gradient points out of the bounds; moving ``b`` up and
``v`` down together lowers the cost. Each test fails with its rule removed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from spec_helpers import CurveEvaluator

from tsid_fmu.search.structure.boundary import score_step, significant
from tsid_fmu.search.verdict import gauss_newton_step

T = np.linspace(0.0, 10.0, 400)
SIGMA = 0.01


def _model(v: float, b: float) -> np.ndarray:
    return np.concatenate([np.sin(0.05 * (v + b) * T), 0.004 * b * np.cos(T)])


MEASURED = _model(51.5, 2.5) + np.random.default_rng(4).normal(0.0, SIGMA, 2 * T.size)
NAMES = ["v", "b"]
LEVELS = {"v": [1.0, 10.0, 80.0], "b": [0.1, 5.0, 20.0]}
BOUNDS = {"v": (0.0, math.inf), "b": (0.0, math.inf)}
AT_NESTING = {"v": 54.0, "b": 0.0}  # the simpler fit embedded: b on its bound


def _chi2(ev, x):
    r = ev.residuals(x)
    return float(r @ r)


def test_the_score_step_moves_off_a_bound_with_the_others_compensating():
    ev = CurveEvaluator(_model, MEASURED, SIGMA)
    r0 = ev.residuals(AT_NESTING)
    gap, point, runs = score_step(ev, NAMES, AT_NESTING, r0, ["b"], LEVELS, BOUNDS)
    assert runs == 2 and significant(gap, float(r0 @ r0), r0.size)
    assert point["b"] > 1.0 and point["v"] < 53.0  # b up, v down: along the sum
    assert _chi2(ev, point) < float(r0 @ r0) - 0.5 * gap  # the prediction holds there
    # the rule removed (each parameter held by its own gradient at its bound, as the
    # refinement's stationarity test does): b is held, nothing is predicted
    jac = np.column_stack(
        [(ev.residuals({**AT_NESTING, n: AT_NESTING[n] + h}) - r0) / h
         for n, h in (("v", 54e-6), ("b", 2e-3))]
    )  # fmt: skip
    held, _ = gauss_newton_step(jac, r0, np.array([54.0, 0.0]), np.zeros(2), np.full(2, np.inf))
    assert not significant(held, float(r0 @ r0), r0.size)


def test_a_nesting_point_the_data_support_is_left_alone():
    """Data of the simpler structure (b = 0): the score test predicts too little to move."""
    measured = _model(54.0, 0.0) + np.random.default_rng(5).normal(0.0, SIGMA, 2 * T.size)
    ev = CurveEvaluator(_model, measured, SIGMA)
    r0 = ev.residuals(AT_NESTING)
    gap, _, _ = score_step(ev, NAMES, AT_NESTING, r0, ["b"], LEVELS, BOUNDS)
    assert not significant(gap, float(r0 @ r0), r0.size)


@pytest.mark.parametrize(("gap", "expected"), [(6.7, True), (6.6, False)])
def test_significant_means_more_than_bics_charge_for_one_parameter(gap, expected):
    """ln(800) = 6.68 noise variances of chi2 / n = 1 each."""
    assert significant(gap, 800.0, 800) is expected


def test_a_prediction_the_steps_own_cost_does_not_bear_out_moves_nothing():
    """The score test's forward differences carry a model's event noise; only a step
    whose own cost is lower by the threshold is refined from (two runs check it)."""
    from tsid_fmu.search.structure.boundary import tried

    ev = CurveEvaluator(_model, MEASURED, SIGMA)
    r0 = ev.residuals(AT_NESTING)
    chi2 = float(r0 @ r0)
    _, point, _ = score_step(ev, NAMES, AT_NESTING, r0, ["b"], LEVELS, BOUNDS)
    best, cost, runs = tried(ev, AT_NESTING, point)
    assert runs == 2 and significant(chi2 - cost, chi2, r0.size) and best["b"] > 0.5
    # a wrong prediction (b up without v down: the motion worsens) is not borne out
    wrong = {"v": 54.0, "b": 2.5}
    _, cost, _ = tried(ev, AT_NESTING, wrong)
    assert not significant(chi2 - cost, chi2, r0.size)
