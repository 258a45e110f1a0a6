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

import tsid_fmu.search.structure.arrays as structure
import tsid_fmu.study.definition as definition
from tsid_fmu import Choice, Experiment, Method, Parameter, Study
from tsid_fmu.doe.arrays import get_array
from tsid_fmu.doe.leveling import LevelingDecision
from tsid_fmu.search.context import Context, Control
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.structure.arrays import DiscreteFactor, discrete_table, settled
from tsid_fmu.search.structure.compare import _candidates, run_structure
from tsid_fmu.search.structure.nesting import at_nesting_point
from tsid_fmu.search.structure.optima import consistent, measure, update
from tsid_fmu.search.structure.selection import Candidate, decide
from tsid_fmu.search.taguchi.frame import Frame
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


def test_the_arrays_fix_the_offset_the_data_show_and_keep_the_levels_of_the_choices(
    monkeypatch,
):
    # the rule, not the cap on the arrays' iterations: the toy's offset is significant
    # with the same best level from its 4th and 5th iterations
    monkeypatch.setattr(structure, "MAX_ITERATIONS", 8)
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


def test_the_arrays_stop_after_their_cap_with_the_switch_open_and_every_level_a_candidate():
    found = _identify(_data(a=2.0, b=1.3, c=0.3, on=1))
    stage = found.stages[0]
    (on,) = found.factors
    assert len(stage.records) == structure.MAX_ITERATIONS == 3
    assert on.fixed is None and "iteration limit (3)" in stage.message
    assert sorted(c.label for c in found.candidates) == ["on=0", "on=1"]
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
    assert simple.lrt_p >= 0.05 and simple.chosen
    assert "do not support" in simple.why or "stay where they make it on=0" in simple.why
    assert simple.lrt_against == "on=1"
    assert found.nested == [["on=0", "on=1"]]


def test_data_with_an_offset_choose_the_richer_structure():
    found = _identify(_data(a=2.0, b=1.3, c=0.3, on=1))
    by = {c.label: c for c in found.candidates}
    assert found.values == {"on": 1.0}
    assert by["on=1"].lrt_p < 1e-6 and by["on=1"].chosen
    assert by["on=1"].x["c"] == pytest.approx(0.3, abs=0.01)


def test_the_answer_has_the_parameters_of_the_chosen_structure_only():
    """A parameter with no effect in the chosen structure gets no value and no interval."""
    from tsid_fmu.identify import _of_structure

    simple = _identify(_data(a=2.0, b=1.3, c=0.0, on=0))
    assert [p.name for p in _of_structure(_study(), simple)] == ["a", "b"]  # no offset c
    rich = _identify(_data(a=2.0, b=1.3, c=0.3, on=1))
    assert [p.name for p in _of_structure(_study(), rich)] == ["a", "b", "c"]
    pick = rich.candidates[rich.chosen]
    assert "c" in pick.free  # free where the arrays saw it
    pick.active.remove("c")  # as on a bound that log coordinates cannot leave
    assert [p.name for p in _of_structure(_study(), rich)] == ["a", "b", "c"]
    pick.free.remove("c")
    assert [p.name for p in _of_structure(_study(), rich)] == ["a", "b"]
    simple.paused = True  # a paused search keeps them all, to go on from
    assert [p.name for p in _of_structure(_study(), simple)] == ["a", "b", "c"]


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


def test_among_tied_structures_the_one_with_fewer_parameters_is_reported_and_said_so():
    """Issue 45: a richer answer whose extra term ended switched off (``Tc`` 2e-19) acts
    as the simpler structure: both count k = 2, and the lower BIC (by 1e-10) chose the
    richer one, while the reason read "the simpler is reported". The tie-break counts
    the structure's own parameters after the free ones, and the reason comes from it."""
    n = 100
    small = Candidate("friction=0", {"s": 0.0}, {}, 1.0, 100.0, n, 2, ["x", "y"])
    rich = Candidate("friction=1", {"s": 1.0}, {}, 1.0, 100.0 - 1e-8, n, 2, ["x", "y"])
    small.free, rich.free = ["x", "y"], ["x", "y", "Tc"]
    assert rich.parameters == ["x", "y", "Tc"] and small.parameters == ["x", "y"]
    for order in ([small, rich], [rich, small]):
        chosen, tied = decide(order)
        assert order[chosen] is small and tied == [order.index(rich)]
        assert rich.bic < small.bic  # the BIC alone would pick the richer one
        assert small.why.endswith("the data do not decide; the simpler is reported")
        assert small.chosen and not rich.chosen
    # as simple in both counts: the lowest BIC, and the reason says that instead
    twin = Candidate("friction=2", {"s": 2.0}, {}, 1.0, 100.0 - 1e-8, n, 2, ["x", "w"])
    twin.free = ["x", "w"]
    chosen, _ = decide([small, twin])
    assert chosen == 1 and twin.why.endswith("the lowest BIC is reported")


def test_data_of_the_simpler_structure_that_push_the_extra_term_to_its_bound_choose_it():
    """Issue 45's held-out case in a toy: the data lie a little below what the offset can
    reach, so on=1's offset c ends on its bound, 0 (2.8e-16 in log coordinates), where
    it changes nothing. That is on=0: the nesting is recorded, on=0 reported, and its
    reason says why."""
    found = _identify(_data(a=2.0, b=1.3, c=0.0, on=0) - 0.004)
    by = {c.label: c for c in found.candidates}
    simple, rich = by["on=0"], by["on=1"]
    # c acts on nothing there, but on=1 may move it: it counts (issue 65: a nesting test
    # counts what each structure may move, never 0 degrees of freedom)
    assert rich.x["c"] < 1e-9 and simple.k == 2 and rich.k == 3
    assert "c" not in rich.active
    assert found.values == {"on": 0.0} and simple.chosen and not rich.chosen
    assert found.nested == [["on=0", "on=1"]]
    assert "nested in on=1, whose extra parameter(s) c stay where they make it on=0" in (simple.why)
    assert "stay where they make it on=0" in rich.why


# -- every candidate at its own optimum ----------------------------------------------------


def test_every_level_of_a_fixed_factor_with_few_levels_is_a_candidate():
    # the arrays fixed law 3 (the richest, which nests the others) with law 2 runner-up:
    # law 1 must still be compared, or data of law 1 can never choose it
    law = DiscreteFactor("law", [1.0, 2.0, 3.0], ["1", "2", "3"], fixed=2, runner_up=1)
    points = [(1.0, {"law": 3.0}), (5.0, {"law": 2.0}), (9.0, {"law": 1.0})]
    found = _candidates([law], points)
    assert [v["law"] for v, _ in found] == [3.0, 2.0, 1.0]
    assert found[0][1] == "the arrays' choice"


def _toy_candidate(study, measured, on, x, label):
    ev = _Evaluators(measured, {"on": on}).get(study.parameter_names, [], {})
    cand = Candidate(label, {"on": on}, {}, math.inf, math.inf, 0, 0, [])
    update(cand, measure(ev, study, x))
    return cand


def _refit(measured, on):
    """The toy's restart: least squares from a start, in structure ``on``."""
    from scipy.optimize import least_squares

    names = ["a", "b", "c"]

    def restart(cands, i, start):
        def res(p):
            return (_model(*p, on) - measured) / SIGMA

        fit = least_squares(res, [start[n] for n in names], bounds=([0, 0.01, 0], [10, 10, 1]))
        x = dict(zip(names, map(float, fit.x), strict=True))
        if not 2 * fit.cost < cands[i].cost:
            return False
        update(cands[i], measure(_Evaluators(measured, {"on": on}).get(names, [], {}), _study(), x))
        return True

    return restart


def _nested_pair(measured, simple_x, rich_x):
    study = _study()
    cands = [
        _toy_candidate(study, measured, 0.0, simple_x, "on=0"),
        _toy_candidate(study, measured, 1.0, rich_x, "on=1"),
    ]
    evs = [_Evaluators(measured, {"on": 0.0}), _Evaluators(measured, {"on": 1.0})]
    fits = [_refit(measured, 0.0), _refit(measured, 1.0)]
    calls = []

    def restart(i, start, why):
        calls.append((i, why))
        return fits[i](cands, i, start)

    return cands, [study, study], evs, restart, calls


def test_a_stuck_simpler_candidate_is_restarted_from_the_richer_answer_and_chosen():
    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    # the simpler structure stuck far from its optimum; the richer one at its own
    cands, studies, evs, restart, calls = _nested_pair(
        measured, {"a": 0.5, "b": 6.0, "c": 0.2}, {"a": 2.0, "b": 1.3, "c": 0.0}
    )
    stuck = cands[0].cost
    assert decide(cands, {(0, 1)})[0] == 1  # compared as they stand: the wrong choice
    nested = consistent(cands, studies, evs, restart)
    assert set(nested) == {(0, 1)} and any(i == 0 and "followed" in w for i, w in calls)
    assert cands[0].cost < 1e-3 * stuck and cands[0].x["b"] == pytest.approx(1.3, abs=0.02)
    chosen, _ = decide(cands, set(nested))
    assert chosen == 0 and "do not support" in cands[0].why


def test_a_richer_candidate_above_the_simpler_one_is_restarted_from_it_embedded():
    measured = _data(a=2.0, b=1.3, c=0.3, on=1)
    # the richer structure stuck above the simpler one's optimum (which it nests at c=0)
    from scipy.optimize import least_squares

    fit = least_squares(lambda p: (_model(*p, 0.0, 0) - measured) / SIGMA, [2.0, 1.0])
    simple = {"a": float(fit.x[0]), "b": float(fit.x[1]), "c": 0.5}
    cands, studies, evs, restart, calls = _nested_pair(
        measured, simple, {"a": 0.3, "b": 8.0, "c": 0.9}
    )
    assert cands[1].cost > cands[0].cost
    assert decide(cands, {(0, 1)})[0] == 0  # as they stand: the wrong choice
    nested = consistent(cands, studies, evs, restart)
    assert calls[0][0] == 1 and calls[0][1].startswith("cost above on=0")
    assert cands[1].cost < cands[0].cost
    assert cands[1].x["c"] == pytest.approx(0.3, abs=0.01)
    chosen, _ = decide(cands, set(nested))
    assert chosen == 1 and cands[1].lrt_p < 1e-6


def test_later_candidates_are_refined_from_warm_starts_to_their_optimum_in_few_runs():
    from scipy.optimize import least_squares

    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    found = _identify(measured)
    first, later = found.candidates
    assert first.origin.startswith("the arrays' choice")
    fit = least_squares(lambda p: (_model(*p, later.values["on"]) - measured) / SIGMA, [2, 1, 0.1])
    assert later.cost <= 1.001 * 2 * fit.cost
    # a refinement from the best of its start points, not a study of its own
    (summary,) = [s for s in found.stages if s.kind == "candidate"]
    assert summary.extra["stages"][0].startswith("refinement from the")
    assert not any(n.startswith("taguchi") for n in summary.extra["stages"])


def test_a_richer_answer_at_the_nesting_point_never_wins_whatever_its_cost():
    n = 20000
    # on Coulomb data, law 3 at F_sm = F_cm (law 2's structure) fitted 0.4 % lower than
    # law 2 through stick-slip events: the LRT alone would credit its Stribeck terms
    law3 = Candidate("3", {"s": 3.0}, {}, 1.0, 18489.6, n, 7, list("abcdefg"))
    law2 = Candidate("2", {"s": 2.0}, {}, 1.0, 18564.6, n, 5, list("abcde"))
    law1 = Candidate("1", {"s": 1.0}, {}, 1.0, 18567.3, n, 4, list("abcd"))
    nested = {(1, 0), (2, 0), (2, 1)}
    assert decide([law3, law2, law1], nested)[0] == 0
    chosen, _ = decide([law3, law2, law1], nested, {(1, 0)})
    assert chosen == 2 and law1.lrt_against == "2" and "do not support" in law1.why
    assert "stay where they make it 2" in law3.why


def test_at_nesting_point_compares_the_extra_parameters_with_the_embedding():
    study = _study()
    small = Candidate("on=0", {}, {"a": 2.0, "b": 1.3, "c": 0.4}, 1.0, 1.0, 1, 2, ["a", "b"])
    big = Candidate("on=1", {}, {"a": 2.0, "b": 1.3, "c": 0.001}, 1.0, 1.0, 1, 3, ["a", "b", "c"])
    assert at_nesting_point(study, small, big, {"a": 2.0, "b": 1.3, "c": 0.0})
    big.x["c"] = 0.3
    assert not at_nesting_point(study, small, big, {"a": 2.0, "b": 1.3, "c": 0.0})


def test_a_richer_candidate_is_also_refined_from_the_simpler_answer_embedded():
    measured = _data(a=2.0, b=1.3, c=0.3, on=1)
    # the richer structure in a local minimum below the simpler optimum: only a start
    # from the simpler answer embedded reaches its own optimum
    from scipy.optimize import least_squares

    fit = least_squares(lambda p: (_model(*p, 0.0, 0) - measured) / SIGMA, [2.0, 1.0])
    simple = {"a": float(fit.x[0]), "b": float(fit.x[1]), "c": 0.5}
    cands, studies, evs, restart, calls = _nested_pair(
        measured, simple, {"a": 1.9, "b": 1.5, "c": 0.32}
    )
    stuck = cands[1].cost
    assert stuck < cands[0].cost
    consistent(cands, studies, evs, restart)
    assert any(i == 1 and "embedded" in w for i, w in calls)
    assert cands[1].cost < 0.5 * stuck


# -- the simplest structure first, the richer ones from its answer embedded --------------


def test_the_simplest_structure_gets_the_own_study_and_the_richer_its_answer_embedded():
    # the arrays rank on=1 first (the data have an offset): the own study still goes to
    # on=0 (2 free parameters against 3), and on=1 starts from on=0's answer embedded
    measured = _data(a=2.0, b=1.3, c=0.3, on=1)
    made = []

    def make(sub):
        made.append(_Evaluators(measured, sub.start_values))
        return made[-1]

    found = run_structure(Context(_study(), make(_study()), NullStore(), None, Control()), make)
    first, later = sorted(found.candidates, key=lambda c: c.folder)
    assert first.label == "on=0" and "the simplest (2 free parameters)" in first.origin
    assert later.label == "on=1" and "the simplest" not in later.origin
    (summary,) = [s for s in found.stages if s.kind == "candidate"]
    assert summary.name == "structure on=0"
    assert any(n.startswith("taguchi") for n in summary.extra["stages"])
    assert not any(s.kind == "taguchi" for s in found.stages[2:])  # on=1: no study of its own
    # on=0's answer embedded in on=1: its a and b held, the offset fitted to reproduce it
    asked = [x for e in made if e.start.get("on") == 1.0 for ev in e.pool.values()
             for x in ev.asked]  # fmt: skip
    held = [x for x in asked if (x["a"], x["b"]) == (first.x["a"], first.x["b"])]
    assert len({x["c"] for x in held}) >= 2
    assert found.values == {"on": 1.0} and later.x["c"] == pytest.approx(0.3, abs=0.01)


def test_an_embedding_reaches_a_nesting_value_on_a_bound_that_log_coordinates_cannot():
    from tsid_fmu.search.structure.nesting import embed

    def model(a, b, c, on):  # any c > 0 switches a step on (as a friction term would)
        return _model(a, b, c + 0.05 * (c > 0), on)

    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    study = _study()
    # the offset's levels a decade apart from 0.01: log coordinates, where c = 0 (its
    # lower bound, the nesting value) is at minus infinity
    study.parameters[2] = Parameter("c", [0.01, 0.1, 1.0], 0.0, 1.0)
    small = _toy_candidate(study, measured, 0.0, {"a": 2.0, "b": 1.3, "c": 0.5}, "on=0")
    ev = _Evaluators(measured, {"on": 1.0}, model).get(study.parameter_names, [], {})
    ok, point = embed(ev, study, small, ["a", "b", "c"], {"a": 1.0, "b": 1.0, "c": 0.5})
    assert ok and point["c"] == 0.0 and point["a"] == small.x["a"]
    assert ev.nfev == 1  # every extra parameter on its lower bound, tried first


def test_a_chosen_answer_from_a_warm_start_gets_its_own_study_unless_shown_optimal():
    from tsid_fmu.search.outcome import Stationarity
    from tsid_fmu.search.stage import StageResult
    from tsid_fmu.search.structure.candidates import needs_own_study

    def stage(holds):
        test = Stationarity(holds, "gauss-newton", 0.0, 1.0, "")
        return StageResult("refinement", "refinement", {"a": 1.0}, 1.0, 10, "", stationarity=test)

    assert needs_own_study(1, {0}, [stage(False)])
    assert not needs_own_study(1, {0}, [stage(True)])
    assert not needs_own_study(0, {0}, [stage(False)])  # it had one
    assert needs_own_study(1, {0}, [StageResult("refinement", "refinement", {}, 1.0, 1, "")])


def test_a_poor_fit_gives_the_richest_candidate_without_one_a_study_of_its_own():
    from tsid_fmu.search.outcome import Stationarity
    from tsid_fmu.search.stage import StageResult
    from tsid_fmu.search.structure.candidates import next_own_study

    def stage(holds):
        test = Stationarity(holds, "gauss-newton", 0.0, 1.0, "")
        return StageResult("refinement", "refinement", {"a": 1.0}, 1.0, 10, "", stationarity=test)

    n = 1000  # the noise floor of 1000 noise-weighted residuals
    law1 = Candidate("1", {"s": 1.0}, {}, 1.6e11, 1.6e11, n, 4, list("abcd"))
    law2 = Candidate("2", {"s": 2.0}, {}, 1.6e11, 1.6e11, n, 5, list("abcde"))
    law3 = Candidate("3", {"s": 3.0}, {}, 2.0e11, 2.0e11, n, 7, list("abcdefg"))
    cands, stages = [law1, law2, law3], [[stage(True)], [stage(True)], [stage(True)]]
    # law 1 chosen (it had the own study), far above the floor: law 3 is given one
    assert next_own_study(0, {0}, stages, cands, float(n)) == 2
    assert next_own_study(0, {0, 2}, stages, cands, float(n)) == 1
    assert next_own_study(0, {0, 1, 2}, stages, cands, float(n)) is None
    law1.cost = 19.0 * n  # within POOR_FIT (20) times the floor: the choice stands
    assert next_own_study(0, {0}, stages, cands, float(n)) is None
    stages[1] = [stage(False)]  # a chosen warm start not shown optimal comes first
    assert next_own_study(1, {0}, stages, cands, float(n)) == 1


def _wave(a: float, b: float, c: float, w: float, on: float) -> np.ndarray:
    # the oscillation has a dead band: amplitudes below 0.02 do not show
    return a * np.exp(-b * T) + (c * np.sin(w * T) if on and c > 0.02 else 0.0)


def test_a_chosen_warm_start_stuck_in_a_poor_fit_is_identified_again_by_its_own_study():
    # on=1 adds an oscillation c sin(w t) with a dead band (c <= 0.02 shows nothing):
    # embedded from on=0 (inside the band) neither c nor w has a gradient, so the warm
    # refinement stops far above the noise; only a study of its own (the Taguchi stage
    # over c and w) finds w = 7
    measured = _wave(2.0, 1.3, 0.3, 7.0, 1) + np.random.default_rng(1).normal(0, SIGMA, T.size)
    data = pd.DataFrame({"time": T, "y": np.zeros_like(T)})
    study = Study(
        fmu=ROOT / "no-such.fmu",
        parameters=[
            Parameter("a", [1.0, 2.0, 3.0], 0.0, 10.0),
            Parameter("b", [0.5, 1.0, 2.0], 0.01, 10.0),
            Parameter("c", [0.05, 0.25, 0.65], 0.0, 1.0),
            Parameter("w", [2.0, 5.0, 9.0], 0.5, 20.0),
            Choice("on", [0, 1]),
        ],
        experiments=[Experiment(data, inputs={}, outputs={"y": "y"}, noise={"y": SIGMA})],
        method=Method(cost="sse", weighting="noise", replicates=1, max_iterations=8),
    )
    ctx = Context(study, _Evaluators(measured, {}, _wave), NullStore(), None, Control())
    found = run_structure(ctx, lambda sub: _Evaluators(measured, sub.start_values, _wave))
    rich = found.candidates[found.chosen]
    assert rich.label == "on=1" and "a study of its own after the comparison" in rich.origin
    assert rich.cost < 2 * T.size and rich.x["w"] == pytest.approx(7.0, abs=0.01)
    warm = [s for s in found.stages if s.name.startswith("refinement from")]
    assert warm and warm[0].cost > 100 * T.size  # where the warm start stopped


# -- the checks' cost: each embedding fit stops once it reproduces, each found once ------


def test_an_embedding_fit_stops_at_the_first_point_that_reproduces_the_simpler_fit():
    from tsid_fmu.search.structure.nesting import REPRODUCE, _fit_extra

    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    study = _study()
    # log coordinates for the offset: its nesting value, c = 0, lies at minus infinity,
    # so a fit run to its end walks on towards it long after c no longer shows
    study.parameters[2] = Parameter("c", [0.01, 0.1, 1.0], 0.0, 1.0)
    small = _toy_candidate(study, measured, 0.0, {"a": 2.0, "b": 1.3, "c": 0.5}, "on=0")
    big = _toy_candidate(study, measured, 1.0, {"a": 2.0, "b": 1.3, "c": 0.5}, "on=1")
    ev = _Evaluators(measured, {"on": 1.0}).get(study.parameter_names, [], {})
    tol = REPRODUCE * small.chi2 / small.n
    base = {**big.x, "a": small.x["a"], "b": small.x["b"]}
    ok, point = _fit_extra(ev, study, small, base, ["c"], tol)
    gap = np.sum(((_model(point["a"], point["b"], point["c"], 1) - measured) / SIGMA
                  - small.residuals) ** 2)  # fmt: skip
    assert ok and 0 < point["c"] < 1e-3 and gap <= tol
    assert ev.nfev <= 25  # run on to its end, the fit takes 36 runs here (limit 40)


def test_an_embedding_fit_that_scipy_cannot_go_on_with_is_not_reproduced(monkeypatch):
    """SciPy's step can fail on a Jacobian it cannot factor: the fit then says "not
    reproduced" (the embedding's other routes follow), instead of raising."""
    import scipy.optimize

    from tsid_fmu.search.structure.nesting import REPRODUCE, _fit_extra

    def failing(fun, x0, **kwargs):
        fun(x0)
        raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setattr(scipy.optimize, "least_squares", failing)
    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    study = _study()
    small = _toy_candidate(study, measured, 0.0, {"a": 2.0, "b": 1.3, "c": 0.5}, "on=0")
    big = _toy_candidate(study, measured, 1.0, {"a": 2.0, "b": 1.3, "c": 0.5}, "on=1")
    ev = _Evaluators(measured, {"on": 1.0}).get(study.parameter_names, [], {})
    base = {**big.x, "a": small.x["a"], "b": small.x["b"]}
    ok, point = _fit_extra(ev, study, small, base, ["c"], REPRODUCE * small.chi2 / small.n)
    assert not ok and point["c"] == pytest.approx(base["c"])


def test_a_nesting_check_puts_extra_parameters_near_their_bounds_on_them_first():
    """The check at the answers: c's nesting value, 0, is its lower bound, which log
    coordinates reach only at minus infinity. The richer answer's c = 0.005 lies within
    NESTING_POINT of the first levels' range (0.99) of it: moved there (one run, and one
    at the richer answer), it reproduces exactly. A fit first walks c towards it (and
    stops short, at the first point within the tolerance). At c = 0.05, not near its
    bound, c is fitted from there."""
    from tsid_fmu.search.structure.nesting import nesting

    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    study = _study()
    study.parameters[2] = Parameter("c", [0.01, 0.1, 1.0], 0.0, 1.0)
    small = _toy_candidate(study, measured, 0.0, {"a": 2.0, "b": 1.3, "c": 0.5}, "on=0")
    for c, on_bound in ((0.005, True), (0.05, False)):
        big = _toy_candidate(study, measured, 1.0, {"a": 2.0, "b": 1.3, "c": 0.5}, "on=1")
        big.x["c"] = c
        evs = [_Evaluators(measured, {"on": 0.0}), _Evaluators(measured, {"on": 1.0})]
        before = big.nfev
        (point,) = nesting([small, big], [study, study], evs).values()
        assert (point["c"] == 0.0) == on_bound and point["a"] == small.x["a"]
        assert (big.nfev - before <= 2) == on_bound


def test_a_nesting_found_earlier_is_reused_where_the_richer_answer_fits_far_better():
    from tsid_fmu.search.structure.nesting import known, nesting

    measured = _data(a=2.0, b=1.3, c=0.3, on=1)
    cands, studies, evs, _, _ = _nested_pair(
        measured, {"a": 2.2, "b": 1.1, "c": 0.5}, {"a": 2.0, "b": 1.3, "c": 0.3}
    )
    assert cands[1].chi2 < 0.01 * cands[0].chi2
    earlier = {"a": cands[0].x["a"], "b": cands[0].x["b"], "c": 0.0}
    cache: dict = {}
    known(cache, 0, 1, cands[0], earlier)
    assert nesting(cands, studies, evs, cache) == {(0, 1): earlier}
    assert all(ev.nfev == 0 for ev in evs[1].pool.values())  # no fit at the richer answer
    # a richer answer that fits hardly better may sit at a nesting point: the fit is made
    cands[1].chi2 = 0.9 * cands[0].chi2
    cache = {}
    known(cache, 0, 1, cands[0], earlier)
    assert set(nesting(cands, studies, evs, cache)) == {(0, 1)}
    assert sum(ev.nfev for ev in evs[1].pool.values()) > 0
    # far better, no embedding known, the simpler answer settled: nothing turns on the
    # pair (no restart, no follow, the LRT and BIC agree), and it is not checked
    cands[1].chi2 = 0.01 * cands[0].chi2
    before = sum(ev.nfev for ev in evs[1].pool.values())
    assert nesting(cands, studies, evs, {}, settled={0}) == {}
    assert sum(ev.nfev for ev in evs[1].pool.values()) == before
    assert set(nesting(cands, studies, evs, {})) == {(0, 1)}  # not settled: checked


def test_a_richer_candidate_is_restarted_from_one_simpler_answer_once():
    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    # a richer answer above the simpler one, which a restart from the simpler answer
    # embedded does not lower (the restart keeps the lower): not tried again
    cands, studies, evs, _, _ = _nested_pair(
        measured, {"a": 2.0, "b": 1.3, "c": 0.5}, {"a": 2.0, "b": 1.3, "c": 0.0}
    )
    cands[1].chi2 = cands[1].cost = 1.5 * cands[0].chi2
    calls = []

    def restart(i, start, why):
        calls.append((i, why))
        return False

    cache: dict = {}
    consistent(cands, studies, evs, restart, cache=cache)
    consistent(cands, studies, evs, restart, cache=cache)  # after another candidate's study
    assert [w for _, w in calls if w.startswith("cost above")] == [
        "cost above on=0, which it nests: from its answer embedded"
    ]
    # above by less than an embedding may differ (1e-7, as law 2 at law 1's fit): it
    # reproduces the simpler fit already, and is not restarted at all
    cands[1].chi2 = cands[1].cost = cands[0].chi2 * (1 + 1e-7)
    calls.clear()
    consistent(cands, studies, evs, restart)
    assert not [w for _, w in calls if w.startswith("cost above")]


def test_a_candidate_shown_at_an_optimum_is_not_followed_from_a_richer_answer():
    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    # the simpler candidate stuck above the richer one that nests it: settled (a study of
    # its own, or a stationary answer) it is not followed from the richer answer in any
    # round; otherwise it is
    cands, studies, evs, restart, calls = _nested_pair(
        measured, {"a": 0.5, "b": 6.0, "c": 0.2}, {"a": 2.0, "b": 1.3, "c": 0.0}
    )
    consistent(cands, studies, evs, restart, settled={0})
    assert not any("followed" in w for _, w in calls)
    consistent(cands, studies, evs, restart)
    assert any(i == 0 and "followed" in w for i, w in calls)


def test_only_the_lowest_cost_earlier_answer_that_embeds_is_embedded():
    from tsid_fmu.search.structure.candidates import embedded_answers

    measured = _data(a=2.0, b=1.3, c=0.3, on=1)
    study = _study()
    worse = _toy_candidate(study, measured, 0.0, {"a": 1.0, "b": 2.0, "c": 0.5}, "worse")
    better = _toy_candidate(study, measured, 0.0, {"a": 2.1, "b": 1.2, "c": 0.5}, "better")
    assert better.cost < worse.cost
    evs = _Evaluators(measured, {"on": 1.0})
    found, runs = embedded_answers(study, [worse, better], ["a", "b", "c"], None, evs)
    assert [(s, label) for s, _, label in found] == [(1, "better")]
    assert runs == sum(ev.nfev for ev in evs.pool.values()) > 0


def test_where_the_best_earlier_answer_does_not_embed_no_other_is_tried(monkeypatch):
    from tsid_fmu.search.structure import candidates

    measured = _data(a=2.0, b=1.3, c=0.3, on=1)
    study = _study()
    worse = _toy_candidate(study, measured, 0.0, {"a": 1.0, "b": 2.0, "c": 0.5}, "worse")
    better = _toy_candidate(study, measured, 0.0, {"a": 2.1, "b": 1.2, "c": 0.5}, "better")
    tried = []

    def embed(ev, study, small, active, x):
        tried.append(small.label)
        return small.label == "worse", dict(x)  # only the worse answer would embed

    monkeypatch.setattr(candidates, "embed", embed)
    evs = _Evaluators(measured, {"on": 1.0})
    found, _ = candidates.embedded_answers(study, [worse, better], ["a", "b", "c"], None, evs)
    assert found == [] and tried == ["better"]


def test_among_earlier_answers_as_good_as_the_best_the_simplest_is_embedded():
    import dataclasses

    from tsid_fmu.search.structure.candidates import embedded_answers

    measured = _data(a=2.0, b=1.3, c=0.3, on=1)
    study = _study()
    simple = _toy_candidate(study, measured, 0.0, {"a": 2.1, "b": 1.2, "c": 0.5}, "simple")
    # a richer answer at the simple fit, lower by less than an embedding may differ (as
    # law 2 at law 1's fit): the simpler one is embedded, its fit has fewer unknowns
    richer = dataclasses.replace(simple, label="richer", k=3, chi2=simple.chi2 * (1 - 1e-9))
    found, _ = embedded_answers(study, [simple, richer], ["a", "b", "c"], None,
                                _Evaluators(measured, {"on": 1.0}))  # fmt: skip
    assert [label for _, _, label in found] == ["simple"]
    richer.chi2 = 0.5 * simple.chi2  # far better: the lowest first
    found, _ = embedded_answers(study, [simple, richer], ["a", "b", "c"], None,
                                _Evaluators(measured, {"on": 1.0}))  # fmt: skip
    assert [label for _, _, label in found] == ["richer"]


def test_a_warm_answer_shown_stationary_is_settled_for_the_nesting_checks(monkeypatch):
    from tsid_fmu.search.structure import compare as structures
    from tsid_fmu.search.structure.candidates import stationary

    seen = []
    real = structures.consistent

    def spy(cands, studies, evs, restart, **options):
        seen.append(set(options["settled"]))
        return real(cands, studies, evs, restart, **options)

    monkeypatch.setattr(structures, "consistent", spy)
    found = _identify(_data(a=2.0, b=1.3, c=0.3, on=1))
    (warm,) = [s for s in found.stages if s.name.startswith("refinement from")]
    assert stationary([warm])  # on=1, refined from on=0's answer embedded
    assert seen and seen[0] == {0, 1}  # on=0 had its own study; on=1 is stationary


def test_a_richer_candidate_refined_from_one_of_two_equal_answers_is_not_restarted():
    import dataclasses

    measured = _data(a=2.0, b=1.3, c=0.3, on=1)
    cands, studies, evs, _, _ = _nested_pair(
        measured, {"a": 2.1, "b": 1.2, "c": 0.5}, {"a": 2.0, "b": 1.3, "c": 0.3}
    )
    calls = []

    def restart(i, start, why):
        calls.append((i, why))
        return False

    # a second simpler answer at the first one's fit, 1e-9 lower (as law 2 at law 1's
    # fit); the richer one was refined from the first embedded: that start is as good
    twin = dataclasses.replace(cands[0], label="twin", chi2=cands[0].chi2 * (1 - 1e-9),
                               cost=cands[0].cost * (1 - 1e-9))  # fmt: skip
    cands = [cands[0], cands[1], twin]
    consistent(cands, [*studies, studies[0]], [*evs, evs[0]], restart, started={(0, 1)})
    assert not [w for _, w in calls if "which it nests, embedded" in w]


@pytest.mark.parametrize("unit_c", ["1/s", ""])
def test_an_embedding_tries_a_simpler_parameter_of_the_same_unit_as_a_nesting_value(unit_c):
    """A second decay rate ``c`` adds nothing where it equals the first, ``b`` (as a
    static friction force equal to the Coulomb one adds no Stribeck effect). In the same
    unit, ``c = b`` is tried (a run at the start, one at the lower bound, one at ``b``)
    and reproduces exactly. Without a unit in common, ``c`` is fitted, and ends near
    ``b`` but not on it, in more runs."""
    from tsid_fmu.search.structure.nesting import embed

    def model(a, b, c, on):
        return a * np.exp(-b * T) if not on else 0.5 * a * (np.exp(-b * T) + np.exp(-c * T))

    measured = _data(a=2.0, b=1.3, c=0.0, on=0)
    study = _study()
    study.parameters[1] = Parameter("b", [0.5, 1.0, 2.0], 0.01, 10.0, "1/s")
    study.parameters[2] = Parameter("c", [0.5, 1.0, 2.0], 0.01, 10.0, unit_c)
    small = _toy_candidate(study, measured, 0.0, {"a": 2.0, "b": 1.3, "c": 0.5}, "on=0")
    small.active, small.k = ["a", "b"], 2
    ev = _Evaluators(measured, {"on": 1.0}, model).get(study.parameter_names, [], {})
    ok, point = embed(ev, study, small, ["a", "b", "c"], {"a": 1.0, "b": 1.0, "c": 0.5})
    assert ok and point["a"] == small.x["a"] and point["b"] == small.x["b"]
    if unit_c:
        assert point["c"] == small.x["b"] and ev.nfev == 4  # all on bounds, start, bound, b
    else:
        assert point["c"] != small.x["b"] and ev.nfev > 4


@pytest.mark.parametrize(
    ("status", "stop", "holds", "calls"),
    [(1, "ftol", False, 2), (0, "xtol", True, 1), (1, None, False, 1), (1, "ftol", None, 1)],
)
def test_a_refinement_stopped_short_of_its_test_is_refined_once_more(
    monkeypatch, status, stop, holds, calls
):
    """A refinement that stopped at its tolerances (``stop``) but whose stationarity test
    found a lower point (status 1) is refined again from its answer, once; one stopped
    by its simulation limit (no ``stop``), shown stationary, or without a test, is not."""
    from tsid_fmu.search.outcome import LocalStop, Stationarity
    from tsid_fmu.search.stage import StageResult
    from tsid_fmu.search.structure import optima

    starts = []

    def polish(name, study, start, ev, progress):
        starts.append(dict(start))
        if len(starts) == 1:
            test = Stationarity(holds, "gn", 0.0, 5.0, "") if holds is not None else None
            x = {"a": 2.0, "b": 1.2, "c": 0.4}
            return StageResult(name, "refinement", x, 5.0, 7, "first", status,
                               stationarity=test, stop=LocalStop(stop or ""))  # fmt: skip
        x = {"a": 2.0, "b": 1.3, "c": 0.4}
        test = Stationarity(True, "gn", 0.0, 4.0, "")
        return StageResult(name, "refinement", x, 4.0, 3, "second", 0,
                           stationarity=test, stop=LocalStop.XTOL)  # fmt: skip

    monkeypatch.setattr(optima, "polish", polish)
    stage = optima.settle("restart", _study(), {"a": 1.0, "b": 1.0, "c": 0.5}, None)
    assert len(starts) == calls
    if calls == 2:
        assert starts[1] == {"a": 2.0, "b": 1.2, "c": 0.4}  # from the first's answer
        assert stage.nfev == 10 and stage.cost == 4.0 and stage.status == 0
    else:
        assert stage.nfev == 7 and stage.message == "first"
