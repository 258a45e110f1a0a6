"""Structure identification without an FMU: discrete factors' response tables, the rule
that fixes a discrete factor, and the choice among candidate structures.

The toy model is ``y = a exp(-b t) + on * c``: the Boolean-like switch ``on`` adds an
offset ``c``, a parameter that only acts in the richer structure (which nests the
simpler one at ``c = 0``). Each test fails when its rule is removed.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from spec_helpers import CurveEvaluator, floor_experiment

import tsid_fmu.study.definition as definition
from tsid_fmu import Choice, Experiment, Method, Parameter, Study
from tsid_fmu.doe.arrays import get_array
from tsid_fmu.doe.leveling import LevelingDecision
from tsid_fmu.search.context import Context, Control
from tsid_fmu.search.frame import Frame
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.selection import Candidate, decide
from tsid_fmu.search.space import Space
from tsid_fmu.search.structure import discrete_table, settled
from tsid_fmu.search.structures import run_structure
from tsid_fmu.trail.folder import NullStore

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]
T = np.linspace(0.0, 4.0, 120)
SIGMA = 0.01


def _model(a: float, b: float, c: float, on: float) -> np.ndarray:
    return a * np.exp(-b * T) + (c if on else 0.0)


def _data(seed: int = 1, **truth: float) -> np.ndarray:
    return _model(**truth) + np.random.default_rng(seed).normal(0.0, SIGMA, T.size)


class _Evaluator(CurveEvaluator):
    def __init__(self, model, measured: np.ndarray) -> None:
        super().__init__(model, measured, SIGMA)
        self.spec = SimpleNamespace(experiments=[floor_experiment(measured, SIGMA)])

    def close(self) -> None:
        pass


class _Evaluators:
    """The toy's evaluators: ``start`` values (a structure) and ``fixed`` ones applied."""

    def __init__(self, measured: np.ndarray, start: dict[str, float], model=_model) -> None:
        self.measured, self.start, self.pool, self.model = measured, dict(start), {}, model

    def get(self, parameters, experiments, fixed):
        key = (tuple(parameters), tuple(sorted(fixed.items())))
        if key not in self.pool:
            base, model = {**self.start, **fixed}, self.model
            self.pool[key] = _Evaluator(lambda **s: model(**{**base, **s}), self.measured)
        return self.pool[key]

    def spec(self, parameters, experiments, fixed):
        return self.get(parameters, experiments, fixed).spec

    def shortened(self, parameters, experiments, fraction):
        return None

    def close(self) -> None:
        pass


@pytest.fixture(autouse=True)
def _no_fmu(monkeypatch):
    """The toy has no FMU: its choices are numbers already."""

    def resolve(fmu, choices):
        for c in choices:
            c.values = [float(v) for v in c.choices]

    monkeypatch.setattr(definition, "resolve_choices", resolve)


def _study(**method) -> Study:
    data = pd.DataFrame({"time": T, "y": np.zeros_like(T)})
    options = {"cost": "sse", "weighting": "noise", "replicates": 1, "max_iterations": 8}
    return Study(
        fmu=ROOT / "no-such.fmu",
        parameters=[
            Parameter("a", [1.0, 2.0, 3.0], 0.0, 10.0),
            Parameter("b", [0.5, 1.0, 2.0], 0.01, 10.0),
            Parameter("c", [0.05, 0.25, 0.65], 0.0, 1.0),
            Choice("on", [0, 1]),
        ],
        experiments=[Experiment(data, inputs={}, outputs={"y": "y"}, noise={"y": SIGMA})],
        method=Method(**{**options, **method}),
    )


def _identify(measured: np.ndarray):
    study = _study()
    ctx = Context(study, _Evaluators(measured, {}), NullStore(), None, Control())
    return run_structure(ctx, lambda sub: _Evaluators(measured, sub.start_values))


# -- the response table of a discrete factor, by hand -----------------------------------

# Taguchi's L18: column 1 (two levels) is 1 for runs 1-9 and 2 for runs 10-18; columns 2
# and 3 (three levels) run 1,1,1,2,2,2,3,3,3 and 1,2,3,1,2,3,1,2,3 in each half.
L18_COLUMNS = np.array([[0] * 9 + [1] * 9, [0, 0, 0, 1, 1, 1, 2, 2, 2] * 2, [0, 1, 2] * 6]).T
SN = np.array([-20, -18, -22, -16, -14, -19, -21, -17, -15,
               -12, -10, -13, -9, -11, -8, -14, -10, -12], dtype=float)  # fmt: skip


def test_discrete_response_table_matches_a_hand_worked_L18():
    assert np.array_equal(np.asarray(get_array("L18").table[:, :3]), L18_COLUMNS)
    levels = {"on": [0.0, 1.0], "a": [1.0, 2.0, 3.0], "b": [1.0, 2.0, 4.0]}
    space = Space(levels, {n: (-9.0, 9.0) for n in levels}, Method().leveling)
    costs = 10.0 ** (-SN / 20.0)  # one replicate: S/N = -20 log10(cost)
    rec = IterationRecord(
        index=1, stage="structure", array="L18", columns=[0, 1, 2],
        frame=Frame.from_levels(space, levels), parameters=list(levels),
        level_index=L18_COLUMNS, sets=np.zeros((18, 3)), costs=costs[:, None],
        errors=[None] * 18, decision=LevelingDecision(), prediction={}, best_x={},
        best_cost=math.inf, best_source="", centre_source="", nfev=0, nfev_total=0,
        next_frame=Frame.from_levels(space, levels),
    )  # fmt: skip
    table = discrete_table(rec, "on")
    # by hand: level 1 = runs 1-9, level 2 = runs 10-18
    low = (-20 - 18 - 22 - 16 - 14 - 19 - 21 - 17 - 15) / 9  # -18.0
    high = (-12 - 10 - 13 - 9 - 11 - 8 - 14 - 10 - 12) / 9  # -11.0
    assert table["sn"] == pytest.approx([low, high], abs=1e-12)
    assert low == -18.0 and high == -11.0
    assert table["best"] == 1 and table["second"] == 0
    assert table["cost"] == pytest.approx([costs[:9].mean(), costs[9:].mean()], rel=1e-12)
    # ANOVA by hand: SS of each factor, error = the rest on 17 - 1 - 2 - 2 = 12 dof
    grand = SN.mean()
    ss_on = 9 * (low - grand) ** 2 + 9 * (high - grand) ** 2
    ss_a = sum(6 * (SN[L18_COLUMNS[:, 1] == k].mean() - grand) ** 2 for k in range(3))
    ss_b = sum(6 * (SN[L18_COLUMNS[:, 2] == k].mean() - grand) ** 2 for k in range(3))
    error = ((SN - grand) ** 2).sum() - ss_on - ss_a - ss_b
    f = ss_on / (error / 12)
    assert table["f"] == pytest.approx(f, rel=1e-9)
    assert table["p"] == pytest.approx(stats.f.sf(f, 1, 12), rel=1e-9)
    assert table["significant"] and not table["pooled"]


# -- the rule that fixes a discrete factor -------------------------------------------------


def test_a_discrete_factor_is_fixed_only_when_significant_with_the_same_best_twice():
    assert settled([(True, 1), (True, 1)])
    assert not settled([(True, 1)])
    assert not settled([(True, 0), (True, 1)])
    assert not settled([(False, 1), (True, 1)])
    assert not settled([(True, 1), (False, 1)])


def test_the_arrays_fix_the_offset_the_data_show_and_keep_the_levels_of_the_choices():
    found = _identify(_data(a=2.0, b=1.3, c=0.3, on=1))
    stage = found.stages[0]
    (on,) = found.factors
    assert on.fixed == 1 and on.labels[on.fixed] == "1"
    k = len(on.history)
    assert k >= 2 and settled(on.history) and not settled(on.history[:-1])
    for rec in stage.records:
        assert rec.levels.get("on", [0.0, 1.0]) == [0.0, 1.0]  # never re-leveled
    assert "on" not in stage.records[-1].next_frame.names  # fixed: out of the arrays
    assert found.values == {"on": 1.0}


def test_a_switch_without_effect_stays_open_and_its_structures_are_indistinguishable():
    data = _data(a=2.0, b=1.3, c=0.0, on=0)

    def same(a, b, c, on):  # the switch (and so the offset) changes nothing
        return _model(a, b, 0.0, 0)

    ctx = Context(_study(), _Evaluators(data, {}, same), NullStore(), None, Control())
    found = run_structure(ctx, lambda sub: _Evaluators(data, sub.start_values, same))
    (on,) = found.factors
    assert on.fixed is None and len(on.history) >= 2
    assert not any(sig for sig, _ in on.history)
    assert len(found.candidates) == 2 and found.tied
    assert "indistinguishable" in found.candidates[found.chosen].why


# -- the choice among structures ---------------------------------------------------------


def test_data_without_offset_choose_the_simpler_structure_by_the_likelihood_ratio():
    found = _identify(_data(a=2.0, b=1.3, c=0.0, on=0))
    by = {c.label: c for c in found.candidates}
    simple, rich = by["on=0"], by["on=1"]
    assert (simple.k, rich.k) == (2, 3)
    assert rich.cost <= simple.cost  # the richer one always fits a little better ...
    assert found.values == {"on": 0.0}  # ... but the data do not support its offset
    assert simple.lrt_p >= 0.05 and simple.chosen and "do not support" in simple.why
    assert simple.lrt_against == "on=1"
    assert found.extra["nested"] == [["on=0", "on=1"]]


def test_data_with_an_offset_choose_the_richer_structure():
    found = _identify(_data(a=2.0, b=1.3, c=0.3, on=1))
    by = {c.label: c for c in found.candidates}
    assert found.values == {"on": 1.0}
    assert by["on=1"].lrt_p < 1e-6 and by["on=1"].chosen
    assert by["on=1"].x["c"] == pytest.approx(0.3, abs=0.01)


def test_information_criteria_and_the_decision_by_hand():
    n = 100
    a = Candidate("A", {"s": 0.0}, {}, 1.0, 100.0, n, 2, ["x", "y"])
    b = Candidate("B", {"s": 1.0}, {}, 1.0, 90.0, n, 3, ["x", "y", "z"])
    chosen, tied = decide([a, b])  # not nested: BIC decides
    assert a.aic == pytest.approx(n * math.log(100.0 / n) + 2 * 3)
    assert b.bic == pytest.approx(n * math.log(90.0 / n) + 4 * math.log(n))
    assert chosen == 1 and tied == [] and b.bic < a.bic - 2
    e = Candidate("E", {"s": 1.0}, {}, 1.0, 99.0, n, 3, ["x", "y", "z"])
    chosen, tied = decide([a, e])  # 1 % lower chi2 does not pay ln(100) = 4.6
    assert chosen == 0 and tied == [] and e.bic > a.bic + 2
    c = Candidate("C", {"s": 1.0}, {}, 1.0, 80.0, n, 3, ["x", "y", "z"])
    chosen, _ = decide([a, c], {(0, 1)})
    lrt = n * math.log(100.0 / 80.0)
    assert chosen == 1 and c.lrt_p == pytest.approx(stats.chi2.sf(lrt, 1))
    d = Candidate("D", {"s": 2.0}, {}, 1.0, 99.5, n, 2, ["x", "w"])
    chosen, tied = decide([a, d])  # same k, BIC within 2, chi2 within noise
    assert tied and "indistinguishable" in (a.why if a.chosen else d.why)
