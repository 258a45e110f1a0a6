"""Taguchi iterations on canonical factors (tsid_fmu.canonical)."""

from types import SimpleNamespace

import numpy as np
import pytest

from tsid_fmu.canonical import canonical_iteration
from tsid_fmu.errors import StudyError
from tsid_fmu.runner import Evaluation

T = np.linspace(0.0, 6.0, 400)
TRUTH = {"p": 3.0, "q": 0.5}


def model(p, q):
    # the output depends on p*q and p/q only: along the p and q axes the cost surface
    # is a narrow valley at an angle, the case main effects over p and q handle badly
    return np.column_stack([p * q * np.sin(T) + (p / q) * np.cos(2 * T)])


class CurveEvaluator:
    """Scores (p, q) against noisy 'measurements' of the model without an FMU.

    Like a study's noise replicates, each replicate perturbs the input (here it scales
    ``p`` by ``1 + bias[r]``); with a biased draw their mean cost is lowest away from the
    least-squares answer, which only the cost on the measured input (``clean=True``) has.
    """

    def __init__(self, bias=(0.0,)):
        rng = np.random.default_rng(0)
        self.measured = model(**TRUTH) + rng.normal(0, 0.01, (T.size, 1))
        self.prep = SimpleNamespace(measured=self.measured, experiment=SimpleNamespace(name="c"))
        self.bias = bias
        self.nfev = 0

    def cost(self, p, q, bias=0.0):
        return float(np.sum((model(p * (1 + bias), q) - self.measured) ** 2))

    def evaluate(self, sets, progress=None, *, clean=False):
        biases = (0.0,) if clean else self.bias
        self.nfev += len(sets) * len(biases)
        costs = np.array([[self.cost(**s, bias=b) for b in biases] for s in sets])
        return Evaluation(costs=costs, errors=[None] * len(sets), nfev=len(sets))

    def simulate_clean(self, params):
        self.nfev += 1
        return [(self.prep, model(**params), None)]

    def simulate_clean_many(self, sets):
        return [self.simulate_clean(p) for p in sets]


@pytest.mark.parametrize("bias", [(0.0,), (0.02, 0.03)], ids=["no replicates", "biased replicates"])
def test_converges_along_a_coupled_valley_and_never_worsens(bias):
    ev = CurveEvaluator(bias)
    start = {"p": 2.0, "q": 0.8}  # 33 % and 60 % off, compensating in p*q
    best = (start, ev.cost(**start), "start")
    costs = [best[1]]
    radius = float("inf")
    for i in range(1, 13):
        rec = canonical_iteration(i, ev, ["p", "q"], best, {}, 0.1, radius)
        radius = rec.extra["radius"]
        assert rec.best_cost <= best[1]  # the best set seen is kept
        best = (rec.best_x, rec.best_cost, rec.best_source)
        costs.append(rec.best_cost)
        if rec.converged:
            break
    assert rec.converged
    # the replicates' mean cost is lowest near p = 3 / 1.025; the answer is the clean one
    assert abs(best[0]["p"] / TRUTH["p"] - 1) < 1e-3
    assert abs(best[0]["q"] / TRUTH["q"] - 1) < 1e-3
    assert costs[-1] < 1e-3 * costs[0]
    assert best[1] == pytest.approx(ev.cost(**best[0]))  # the cost reported is the clean one
    frame = rec.runs_frame()
    assert list(frame.columns[:4]) == ["iteration", "run", "p", "q"] and len(frame) == 25
    assert "S/N [dB]" in frame and "cost r1" in frame


def test_bounds_are_respected_and_parameters_at_zero_need_a_scale():
    ev = CurveEvaluator()
    best = ({"p": 2.0, "q": 0.8}, ev.cost(p=2.0, q=0.8), "start")
    rec = canonical_iteration(1, ev, ["p", "q"], best, {"q": (0.7, 1.0)}, 0.1)
    assert rec.values[:, 1].min() >= 0.7 and rec.values[:, 1].max() <= 1.0
    at_zero = ({"p": 0.0, "q": 0.5}, ev.cost(p=0.0, q=0.5), "x")
    with pytest.raises(StudyError, match="p is 0 and no scale was given"):
        canonical_iteration(1, ev, ["p", "q"], at_zero, {}, 0.1)
    # with a scale, a parameter on its bound at 0 moves off it (one-sided differences)
    rec = canonical_iteration(1, ev, ["p", "q"], at_zero, {"p": (0.0, 9.0)}, 0.1, scales={"p": 0.1})
    assert rec.values[:, 0].min() >= 0.0 and rec.values[:, 0].max() > 0.0
    assert rec.best_x["p"] > 0 and rec.best_cost < at_zero[1]


def test_record_round_trips_through_strict_json_with_failed_runs():
    import json

    from tsid_fmu.canonical import CanonicalRecord

    ev = CurveEvaluator()
    best = ({"p": 2.0, "q": 0.8}, ev.cost(p=2.0, q=0.8), "start")
    rec = canonical_iteration(1, ev, ["p", "q"], best, {}, 0.1)
    rec.costs[3, 0] = np.inf  # a failed run
    rec.sn_means[0, 0] = -np.inf
    rec.extra["sn_spread_db"][0] = np.inf
    text = json.dumps(rec.to_dict(), allow_nan=False)  # other tools read it too
    back = CanonicalRecord.from_dict(json.loads(text))
    assert np.isinf(back.costs[3, 0]) and np.isnan(back.sn_means[0, 0])
    assert back.best_x == rec.best_x and back.extra["radius"] == rec.extra["radius"]
    assert np.isnan(back.extra["sn_spread_db"][0])
    np.testing.assert_array_equal(back.values, rec.values)
