"""The refinement stage: SciPy's trust-region least squares, without its wasted simulations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from spec_helpers import CurveEvaluator

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search import refine
from tsid_fmu.search.refine import refine_stage
from tsid_fmu.search.space import Space
from tsid_fmu.study.schema import Method

T = np.linspace(0.0, 4.0, 60)
TRUTH = {"a": 2.0, "k": 1.3, "c": 0.4}
NOISE = np.random.default_rng(3).normal(0.0, 0.01, T.size)


def _model(a: float, k: float, c: float) -> np.ndarray:
    return a * np.exp(-k * T) + c


MEASURED = _model(**TRUTH) + NOISE


def ResidualEvaluator() -> CurveEvaluator:
    """Scores sets by a nonlinear least-squares fit, and logs every set it simulates."""
    return CurveEvaluator(_model, MEASURED, 0.01)


def _stage(with_start=True):
    space = Space(
        {"a": [1.0, 1.5, 3.0], "k": [0.5, 1.0, 2.0], "c": [0.0, 0.5, 1.0]},
        {n: (0.0, math.inf) for n in TRUTH},
        LevelingOptions(),
    )
    start = {"a": 1.8, "k": 1.1, "c": 0.5}
    first = ResidualEvaluator().evaluate([start])
    ev = ResidualEvaluator()
    result = refine_stage(
        "refinement",
        space,
        start,
        float(first.costs[0, 0]),
        ev,
        Method(cost="sse", refine="least_squares", refine_max_nfev=500),
        start_residuals=first.residuals[0] if with_start else None,
    )
    return result, ev, start


def test_refinement_reaches_scipys_answer_without_scipys_last_jacobian(monkeypatch):
    result, ev, start = _stage()
    assert result.status == 0 and "stopped before another Jacobian" in result.message
    assert start not in ev.asked  # the start's residuals came from the caller
    assert result.nfev == ev.nfev
    # the same trust-region path with SciPy's own stopping: SciPy pays one more
    # Jacobian (p = 3 simulations) after the step that meets its test
    monkeypatch.setattr(refine._Problem, "_check_step", lambda self, s, r: None)
    plain, _, _ = _stage()
    assert plain.status == 0 and "least squares: `ftol`" in plain.message
    assert result.nfev == plain.nfev - 3
    assert result.x == plain.x and result.cost == plain.cost
    assert result.x == pytest.approx(TRUTH, rel=0.05)


def test_refinement_simulates_the_start_when_the_caller_has_no_residuals():
    result, ev, start = _stage(with_start=False)
    with_start, _, _ = _stage()
    assert len(ev.asked) == result.nfev == with_start.nfev + 1
    assert ev.asked[0] == pytest.approx(start, rel=1e-12)
    assert result.cost == with_start.cost


def test_a_least_squares_that_cannot_go_on_keeps_the_best_set_and_says_why(monkeypatch):
    """SciPy's step can fail on a Jacobian it cannot factor; the stage then answers with
    the lowest set scored, not shown to be an optimum (status 1), instead of raising."""
    import scipy.optimize

    real = scipy.optimize.least_squares

    def failing(fun, x0, **kwargs):
        kwargs["max_nfev"] = 3
        real(fun, x0, **kwargs)
        raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setattr(scipy.optimize, "least_squares", failing)
    result, ev, start = _stage()
    assert result.status == 1 and "could not go on" in result.message
    assert result.cost < ResidualEvaluator().cost(**start)  # the steps it took are kept
    assert result.cost == pytest.approx(ev.cost(**result.x))
