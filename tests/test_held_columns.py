"""A parameter the outputs do not depend on is held by the refinement (issue 62, item 4).

A zero Jacobian column makes SciPy's trust-region subproblem rank-deficient: the exact
Gauss-Newton step is never taken, and the refinement crawls (the conformance
benchmark's ``NO_EFFECT`` lag: 67 runs where 16 do without the idle parameter). The
first Jacobian decides which columns are held (:func:`tsid_fmu.numerics.rank.
unseen_columns`); every Jacobian differences them again, and one that is seen frees
its parameter.
"""

from __future__ import annotations

import math

import numpy as np
from spec_helpers import CurveEvaluator

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.numerics.rank import unseen_columns
from tsid_fmu.search.local.refine import refine_stage
from tsid_fmu.search.space import Space
from tsid_fmu.study.schema import Method

T = np.linspace(0.0, 4.0, 80)
NOISE = np.random.default_rng(7).normal(0.0, 0.01, T.size)
LEVELS = {"a": [1.0, 1.5, 3.0], "k": [0.5, 1.0, 2.0]}
METHOD = Method(cost="sse", refine="least_squares", refine_max_nfev=500)


def _lag(a: float, k: float, **_: float) -> np.ndarray:
    return a * np.exp(-k * T)


def _space(names: list[str], extra: dict | None = None) -> Space:
    levels = {n: LEVELS[n] for n in names} | (extra or {})
    return Space(levels, {n: (0.0, 10.0) for n in levels}, LevelingOptions())


def test_the_rank_rule_marks_zero_columns_only():
    jac = np.array([[1.0, 0.0, 1e-9, np.nan], [2.0, 0.0, 0.0, 0.0]])
    assert unseen_columns(jac).tolist() == [False, True, True, True]
    assert unseen_columns(np.zeros((3, 2))).tolist() == [True, True]


def test_a_parameter_that_acts_on_nothing_costs_its_columns_only():
    measured = _lag(2.0, 1.3) + NOISE
    start = {"a": 1.4, "k": 0.8}
    alone = CurveEvaluator(_lag, measured, 0.01)
    two = refine_stage("refinement", _space(["a", "k"]), start, math.inf, alone, METHOD)
    idle = CurveEvaluator(_lag, measured, 0.01)
    space = _space(["a", "k"], {"spare": [0.5, 1.0, 2.0]})
    three = refine_stage("refinement", space, {**start, "spare": 1.0}, math.inf, idle, METHOD)
    assert two.status == 0 and three.status == 0
    assert math.isclose(three.cost, two.cost, rel_tol=1e-9)
    assert three.x["spare"] == 1.0 and three.held == ["spare"]
    assert "held spare: the outputs do not depend on it" in three.message
    # one run for its column per Jacobian (measured without the rule: 64 runs against
    # 24, the least squares crawling in a rank-deficient trust region)
    assert three.nfev <= 1.5 * two.nfev, (three.nfev, two.nfev)


def _switched(a: float, k: float, b: float) -> np.ndarray:
    """``b`` acts only where ``a`` is above 1.6: zero at the start, not at the optimum."""
    return a * np.exp(-k * T) + b * max(a - 1.6, 0.0) * T


def test_a_held_parameter_that_begins_to_act_is_freed_and_refined():
    truth = {"a": 2.0, "k": 1.3, "b": 0.5}
    ev = CurveEvaluator(_switched, _switched(**truth) + NOISE, 0.01)
    space = _space(["a", "k"], {"b": [0.0, 0.5, 1.0]})
    out = refine_stage("refinement", space, {"a": 1.4, "k": 0.8, "b": 0.2}, math.inf, ev, METHOD)
    assert out.status == 0, out.message
    assert not out.held and "held" not in out.to_dict()["extra"]
    assert "freed b where the outputs began" in out.message
    assert abs(out.x["b"] - 0.5) < 0.05 and abs(out.x["a"] - 2.0) < 0.02
