"""The adaptive pipeline's rules, each on a small FMU-free problem.

Start points are scored; a stalling Taguchi stage hands over to the refinement; an
answer beyond the first ranges is reached (ranges are extended to the bounds); a poor
fit sends the search back to the arrays, over growing horizons and to restarts; exit
status 0 only where a stationarity test holds. Each test fails when its rule is removed.
"""

from __future__ import annotations

import itertools
import json
import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import least_squares
from spec_helpers import CurveEvaluator, floor_experiment

from tsid_fmu import Experiment, Method, Parameter, Study
from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search import context, verdict
from tsid_fmu.search.local import adaptive
from tsid_fmu.search.local import flow as local
from tsid_fmu.search.local.refine import STOPPED
from tsid_fmu.search.outcome import LocalStop
from tsid_fmu.search.pipeline import run_stages
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.taguchi import stage as taguchi
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.taguchi.stage import TaguchiRun, taguchi_stage
from tsid_fmu.search.taguchi.start import start_points
from tsid_fmu.trail.folder import NullStore

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]
T = np.linspace(0.0, 4.0, 80)
TRUTH = {"a": 2.0, "k": 1.3}
SIGMA = 0.01
NOISE = np.random.default_rng(3).normal(0.0, SIGMA, T.size)


def _decay(a: float, k: float) -> np.ndarray:
    return a * np.exp(-k * T)


class FloorEvaluator(CurveEvaluator):
    """A curve evaluator with the spec ``noise_floor`` reads (residuals in noise units)."""

    def __init__(self, model, measured: np.ndarray, scale: float) -> None:
        super().__init__(model, measured, scale)
        self.spec = SimpleNamespace(experiments=[floor_experiment(measured, scale)])


class Evaluators:
    """Every sub-problem scored by one evaluator (a single-stage study)."""

    def __init__(self, ev: CurveEvaluator) -> None:
        self.ev = ev

    def spec(self, parameters, experiments, fixed):
        return self.ev.spec

    def get(self, parameters, experiments, fixed):
        return self.ev

    def shortened(self, parameters, experiments, fraction):
        return None  # a given evaluator cannot be shortened: no horizons


def _study(levels: dict[str, list[float]], bounds=None, **method) -> Study:
    data = pd.DataFrame({"time": T, "y": np.zeros_like(T)})
    bounds = bounds or {}
    params = [Parameter(n, lv, *bounds.get(n, (0.0, math.inf))) for n, lv in levels.items()]
    options = {"cost": "sse", "weighting": "noise", "replicates": 1, **method}
    return Study(
        fmu=ROOT / "no-such.fmu",
        parameters=params,
        experiments=[Experiment(data, inputs={}, outputs={"y": "y"}, noise={"y": SIGMA})],
        method=Method(**options),
    )


def _decay_evaluator() -> FloorEvaluator:
    return FloorEvaluator(_decay, _decay(**TRUTH) + NOISE, SIGMA)


def _optimum(model, measured, x0: dict[str, float]) -> tuple[dict[str, float], float]:
    names = list(x0)
    fit = least_squares(
        lambda v: (model(**dict(zip(names, v, strict=True))) - measured) / SIGMA,
        [x0[n] for n in names],
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
    )
    return dict(zip(names, fit.x, strict=True)), 2 * float(fit.cost)


def _stage_run(levels, **kw) -> TaguchiRun:
    space = Space(levels, {n: (0.0, math.inf) for n in levels}, LevelingOptions())
    return TaguchiRun(
        name="taguchi",
        space=space,
        first=Frame.from_levels(space, levels),
        method=Method(cost="sse", replicates=1, max_iterations=kw.pop("max_iterations", 6)),
        **kw,
    )


# -- start points -------------------------------------------------------------------------


def test_the_start_point_is_scored_first_and_the_answer_is_never_worse():
    levels = {"a": [5.0, 6.0, 8.0], "k": [4.0, 5.0, 6.0]}  # every run far from the truth
    ev = _decay_evaluator()
    with_start = taguchi_stage(_stage_run(levels, starts=[(TRUTH, "given")], max_iterations=1), ev)
    without = taguchi_stage(_stage_run(levels, max_iterations=1), _decay_evaluator())
    assert with_start.cost == pytest.approx(ev.cost(**TRUTH), rel=1e-12)
    assert with_start.records[0].best_source == "given"
    assert with_start.records[0].starts[0]["source"] == "given"
    assert ev.asked[0] == TRUTH  # scored before the first array
    assert without.cost > 100 * with_start.cost  # what the rule protects against
    assert with_start.nfev == without.nfev + 1


def test_start_points_are_the_fmus_start_values_then_the_centre_of_the_levels():
    levels = {"F_cm": [10.0, 50.0, 110.0], "K_s": [1000.0, 4000.0, 6000.0]}
    space = Space(levels, {"F_cm": (0, math.inf), "K_s": (0, 5000.0)}, LevelingOptions())
    points = start_points(space, ROOT / "fmus" / "LSEA_SISO.fmu")
    (fmu, source), (centre, where) = points
    assert source == "the FMU's start values" and fmu["F_cm"] == 88.5
    assert fmu["K_s"] == 5000.0  # the FMU's 8600 clipped to the study's bound
    assert where == "the centre of the first levels"
    assert centre == space.to_x(np.zeros(2))
    assert start_points(space, ROOT / "no-such.fmu") == [(centre, where)]
    before = {"F_cm": 70.0, "K_s": 3000.0}
    assert start_points(space, None, before)[0] == (before, "the values before this stage")


# -- hand-over ----------------------------------------------------------------------------


def test_a_taguchi_stage_with_a_hand_over_ends_after_its_first_iteration():
    levels = {"a": [1.0, 2.5, 4.0], "k": [0.5, 1.5, 2.5]}
    on = taguchi_stage(_stage_run(levels, handover=True), _decay_evaluator())
    off = taguchi_stage(_stage_run(levels), _decay_evaluator())
    assert on.status == 0 and on.message == taguchi.HANDOVER.format(index=1)
    assert len(on.records) == 1 and on.records[-1].handover
    assert len(off.records) > len(on.records)


def test_a_pause_asked_for_at_the_hand_over_comes_before_the_refinement():
    """--pause-after 1 pauses a stage that hands over after its first iteration (it
    used to run on into the refinement); read back, it is the handed-over stage."""
    levels = {"a": [1.0, 2.5, 4.0], "k": [0.5, 1.5, 2.5]}
    paused = taguchi_stage(_stage_run(levels, handover=True, pause_after=1), _decay_evaluator())
    assert paused.status == 2 and paused.message.startswith("paused after iteration 1")
    assert len(paused.records) == 1 and paused.records[0].handover
    written = paused.records[0].to_dict()  # the trail's form, read back typed
    assert written["extra"]["handover"] == paused.records[0].handover
    read = IterationRecord.from_dict(written)
    assert read.handover == paused.records[0].handover and "handover" not in read.extra
    ev = _decay_evaluator()
    again = taguchi_stage(_stage_run(levels, handover=True, prior=paused.records), ev)
    assert ev.nfev == 0 and again.status == 0
    assert again.message == taguchi.HANDOVER.format(index=1)


def test_a_handed_over_stage_reads_back_as_finished_and_continues_without_a_second_handover():
    levels = {"a": [1.0, 2.5, 4.0], "k": [0.5, 1.5, 2.5]}
    first = taguchi_stage(_stage_run(levels, handover=True), _decay_evaluator())
    ev = _decay_evaluator()
    again = taguchi_stage(_stage_run(levels, handover=True, prior=first.records), ev)
    assert ev.nfev == 0 and again.message == first.message
    more = taguchi_stage(_stage_run(levels, prior=first.records, max_iterations=12), ev)
    assert len(more.records) > len(first.records) and "handed over" not in more.message


def test_the_auto_pipeline_hands_over_and_ends_at_the_least_squares_optimum():
    study = _study({"a": [0.5, 1.5, 4.0], "k": [0.3, 1.0, 3.0]})
    ev = _decay_evaluator()
    stages = run_stages(study, Evaluators(ev), NullStore())
    x, best = _optimum(_decay, ev.measured, TRUTH)
    answer = adaptive.answer_stage(stages)
    assert answer.cost == pytest.approx(best, rel=1e-6)
    assert all(answer.x[n] == pytest.approx(x[n], rel=1e-4) for n in x)
    assert stages[0].message.startswith("handed over") and stages[1].kind == "refinement"
    assert adaptive.verdict(stages)[0] == 0
    fixed = _decay_evaluator()
    run_stages(_study(study.first_levels(), refine="least_squares"), Evaluators(fixed), NullStore())
    assert ev.nfev < fixed.nfev  # the arrays stop where a local method finishes faster


# -- ranges extended to the bounds -----------------------------------------------------------


def test_an_optimum_beyond_the_first_ranges_is_reached_and_a_bound_is_respected():
    far = {"a": [0.4, 0.6, 0.9], "k": [0.3, 0.5, 0.8]}  # the truth is above every level
    ev = _decay_evaluator()
    stages = run_stages(_study(far), Evaluators(ev), NullStore())
    answer = adaptive.answer_stage(stages)
    _, best = _optimum(_decay, ev.measured, TRUTH)
    assert answer.x["a"] > 2 * max(far["a"]) and answer.cost == pytest.approx(best, rel=1e-6)
    bounded = run_stages(
        _study(far, bounds={"a": (0.0, 1.0)}), Evaluators(_decay_evaluator()), NullStore()
    )
    answer = adaptive.answer_stage(bounded)
    assert answer.x["a"] == pytest.approx(1.0)  # held at its bound, and
    assert adaptive.verdict(bounded)[0] == 0  # stationary there (the projected test)
    assert answer.poor_fit["ratio"] > verdict.POOR_FIT  # and named a poor fit


# -- local minima: back to the arrays, then restarts ----------------------------------------

W = np.linspace(0.0, 4.0, 300)


def _ring(w: float, a: float) -> np.ndarray:
    return a * np.sin(w * W)


RING = _ring(3.0, 1.0) + np.random.default_rng(5).normal(0.0, SIGMA, W.size)


def _ring_study(**method) -> Study:
    data = pd.DataFrame({"time": W, "y": np.zeros_like(W)})
    # the truth w = 3 lies above the first levels; a sine's cost has a row of minima in w
    params = [Parameter("w", [0.8, 1.5, 2.2], 0.5, 8.0), Parameter("a", [0.5, 1.0, 2.0], 0.0)]
    return Study(
        fmu=ROOT / "no-such.fmu",
        parameters=params,
        experiments=[Experiment(data, inputs={}, outputs={"y": "y"}, noise={"y": SIGMA})],
        method=Method(cost="sse", weighting="noise", replicates=1, **method),
    )


def test_a_poor_fit_after_the_refinement_sends_the_search_back_until_the_global_optimum(
    monkeypatch,
):
    # the hand-over comes after the first array; the refinement lands in a local minimum
    ev = FloorEvaluator(_ring, RING, SIGMA)
    stages = run_stages(_ring_study(), Evaluators(ev), NullStore())
    answer = adaptive.answer_stage(stages)
    first = next(s for s in stages if s.kind == "refinement")
    assert first.cost > 100 * answer.cost  # the first refinement sat in a local minimum
    assert answer.x["w"] == pytest.approx(3.0, rel=1e-3)
    assert answer.cost < verdict.POOR_FIT * W.size
    assert adaptive.verdict(stages)[0] == 0
    # without the rule, the local minimum would be the answer
    monkeypatch.setattr(local, "POOR_FIT", math.inf)
    alone = run_stages(_ring_study(), Evaluators(FloorEvaluator(_ring, RING, SIGMA)), NullStore())
    assert adaptive.answer_stage(alone).cost > 100 * answer.cost


def test_a_restart_starts_from_the_best_scored_set_away_from_every_explored_one():
    levels = {"a": [1.0, 2.5, 4.0], "k": [0.5, 1.5, 2.5]}
    stage = taguchi_stage(_stage_run(levels, max_iterations=1), _decay_evaluator())
    space = Space(levels, {n: (0.0, math.inf) for n in levels}, LevelingOptions())
    costs = stage.records[0].measured_costs
    order = np.argsort(costs)
    best = dict(zip(stage.records[0].parameters, stage.records[0].sets[order[0]], strict=True))
    found, cost, origin = adaptive.restart_start([stage], space, [best])
    assert origin == "a run of the arrays"
    assert cost > costs[order[0]] and found != best
    s, t = space.to_s(found), space.to_s(best)
    assert np.max(np.abs(s - t)) >= adaptive.RESTART_SEPARATION
    everything = [dict(zip(levels, row, strict=True)) for row in stage.records[0].sets]
    assert adaptive.restart_start([stage], space, everything) is None


def test_restarts_try_the_start_points_first_where_a_local_method_alone_would_start():
    levels = {"a": [1.0, 2.5, 4.0], "k": [0.5, 1.5, 2.5]}
    starts = [({"a": 1.7, "k": 1.0}, "given")]
    stage = taguchi_stage(_stage_run(levels, starts=starts, max_iterations=1), _decay_evaluator())
    space = Space(levels, {n: (0.0, math.inf) for n in levels}, LevelingOptions())
    best = dict(zip(stage.records[0].parameters, stage.records[0].sets[0], strict=True))
    found, _, origin = adaptive.restart_start([stage], space, [best], starts_first=True)
    assert (found, origin) == (starts[0][0], "given")
    _, _, origin = adaptive.restart_start([stage], space, [best, found], starts_first=True)
    assert origin == "a run of the arrays"


# -- the stationarity gate ------------------------------------------------------------------


def test_the_projected_gauss_newton_gap_of_a_linear_problem():
    jac = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
    r = np.ones(3)
    free = np.full(2, math.inf)
    step = np.linalg.lstsq(jac, -r, rcond=None)[0]
    exact = 3.0 - float(np.sum((r + jac @ step) ** 2))
    assert verdict.gauss_newton_gap(jac, r, np.zeros(2), -free, free) == pytest.approx(exact)
    # both coordinates at a lower bound the gradient pushes through: nothing to gain
    assert verdict.gauss_newton_gap(jac, r, np.zeros(2), np.zeros(2), free) == 0.0
    # a bound 0.1 away cuts the step short: a smaller gain, not none
    cut = verdict.gauss_newton_gap(jac, r, np.zeros(2), np.full(2, -0.1), free)
    assert 0 < cut < exact


def test_exit_zero_needs_the_stationarity_test_to_hold():
    study = _study(
        {"a": [0.5, 1.5, 4.0], "k": [0.3, 1.0, 3.0]},
        refine="least_squares",
        refine_max_nfev=3,
        max_iterations=1,
    )
    stages = run_stages(study, Evaluators(_decay_evaluator()), NullStore())
    refined = stages[-1]
    assert refined.status == 1 and not refined.stationarity.holds
    status, why = adaptive.verdict(stages)
    assert status == 1 and "not shown to be an optimum" in why


def test_the_local_probe_test_finds_a_lower_neighbour_and_takes_it():
    levels = {"a": [1.0, 2.0, 3.0], "k": [1.0, 1.3, 1.6]}
    space = Space(levels, {n: (0.0, math.inf) for n in levels}, LevelingOptions())
    ev = _decay_evaluator()
    x, best = _optimum(_decay, ev.measured, TRUTH)
    at = verdict.probe_test(ev, space, x, best, 0.005)
    assert at[0].holds and at[1] == x and ev.nfev == 4
    off = {"a": x["a"] * 1.05, "k": x["k"]}
    test, moved, cost = verdict.probe_test(ev, space, off, ev.cost(**off), 0.005)
    assert not test.holds and cost < ev.cost(**off) and moved["a"] < off["a"]


def test_refine_none_ends_with_a_check_stage_that_decides_the_verdict():
    study = _study({"a": [1.0, 1.7, 2.6], "k": [0.8, 1.1, 1.7]}, refine="none", max_iterations=1)
    stages = run_stages(study, Evaluators(_decay_evaluator()), NullStore())
    assert stages[-1].kind == "check" and stages[-1].nfev == 4
    assert adaptive.verdict(stages)[0] == (0 if stages[-1].stationarity.holds else 1)
    assert adaptive.verdict(stages)[0] == 1  # one array does not reach the optimum


def test_a_refinement_out_of_runs_sends_the_search_back_to_the_arrays(monkeypatch):
    polish = context.polish

    def out_of_runs(name, *args, **kwargs):
        stage = polish(name, *args, **kwargs)
        if name == "refinement":  # its test held, but its budget ended it
            stage.stop = LocalStop.LIMIT
        return stage

    monkeypatch.setattr(context, "polish", out_of_runs)
    study = _study({"a": [0.5, 1.5, 4.0], "k": [0.3, 1.0, 3.0]})
    stages = run_stages(study, Evaluators(_decay_evaluator()), NullStore())
    first = stages[0]
    assert "ran out of simulations" in first.resumed
    assert not first.records[-1].handover  # it went on past the hand-over
    monkeypatch.setattr(local, "_collapsed", lambda stage: None)
    alone = run_stages(study, Evaluators(_decay_evaluator()), NullStore())
    assert not alone[0].resumed and len(alone[0].records) < len(first.records)


def test_a_collapsed_trust_region_whose_test_holds_ends_the_search(monkeypatch):
    """A stop at xtol is a tolerance like the others: the stationarity test decides."""
    polish = context.polish

    def collapsing(name, *args, **kwargs):
        stage = polish(name, *args, **kwargs)
        if name == "refinement":  # as SciPy says it when the trust region collapses
            stage.message = f"least squares: {STOPPED[LocalStop.XTOL]}"
            stage.stop = LocalStop.XTOL
        return stage

    monkeypatch.setattr(context, "polish", collapsing)
    study = _study({"a": [0.5, 1.5, 4.0], "k": [0.3, 1.0, 3.0]})
    stages = run_stages(study, Evaluators(_decay_evaluator()), NullStore())
    assert stages[1].stationarity.holds and not stages[0].resumed
    assert [s.kind for s in stages] == ["taguchi", "refinement"]
    assert adaptive.verdict(stages)[0] == 0


def test_a_continued_stage_hands_back_once_below_the_refinement_and_stalled():
    levels = {"a": [1.0, 2.5, 4.0], "k": [0.5, 1.5, 2.5]}
    first = taguchi_stage(_stage_run(levels, handover=True), _decay_evaluator())
    below = first.cost * 0.95  # a refinement's answer a little below the arrays' best
    run = {"prior": first.records, "max_iterations": 30}
    on = taguchi_stage(_stage_run(levels, hand_back_below=below, **run), _decay_evaluator())
    off = taguchi_stage(_stage_run(levels, **run), _decay_evaluator())
    assert on.message.startswith("handed back to the refinement") and on.status == 0
    rtol = LevelingOptions().stall_rtol
    costs = [r.best_cost for r in on.records[len(first.records) - 1 :]]
    falls = [(b < below) and (a - b < rtol * b) for a, b in itertools.pairwise(costs)]
    assert falls[-1] and not any(falls[:-1])  # at the first iteration where both hold
    assert len(off.records) > len(on.records) and "handed back" not in off.message
    ev = _decay_evaluator()  # read back from the trail: finished, nothing simulated
    again = taguchi_stage(_stage_run(levels, handover=True, prior=on.records), ev)
    assert ev.nfev == 0 and again.message == on.message


def test_a_crawl_continued_to_an_optimum_in_its_combination_ends_the_search(monkeypatch):
    """The combination's stage merges into the refinement that crawled: judged again."""
    polish = context.polish

    def crawling(name, *args, **kwargs):
        stage = polish(name, *args, **kwargs)
        if name == "refinement":  # stopped in a valley, its test failing
            stage.stop = LocalStop.VALLEY
            stage.stationarity = verdict.Stationarity(False, verdict.GN_TEST, 1.0, 1.0, "")
            stage.cost *= 1.01
        return stage

    def combined(study, evs, stages, progress=None):
        answer = adaptive.answer_stage(stages)
        test = verdict.Stationarity(True, verdict.GN_TEST, 0.0, answer.cost / 1.01, "")
        lower = StageResult(
            "refinement in the combinations the data fix: a + 1 k",
            "refinement",
            dict(answer.x),
            answer.cost / 1.01,
            3,
            "least squares in the combinations; stationary",
            0,
            stationarity=test,
            pairs=[["a", "k", 1.0]],
        )
        return lower, 3

    monkeypatch.setattr(context, "polish", crawling)
    monkeypatch.setattr(local, "refine_in_combinations", combined)
    study = _study({"a": [0.5, 1.5, 4.0], "k": [0.3, 1.0, 3.0]})
    stages = run_stages(study, Evaluators(_decay_evaluator()), NullStore())
    assert not stages[0].resumed  # the arrays did not go on
    assert stages[1].crawled["nfev"] > 0  # the combination continued the crawl
    assert adaptive.verdict(stages)[0] == 0


def test_the_pipeline_continues_the_arrays_only_to_below_the_refinements_answer(monkeypatch):
    polish = context.polish

    def limited_high(name, *args, **kwargs):
        stage = polish(name, *args, **kwargs)
        if name == "refinement":  # out of runs, and well above the arrays' best
            stage.stop = LocalStop.LIMIT
            stage.cost *= 1.5
        return stage

    monkeypatch.setattr(context, "polish", limited_high)
    study = _study({"a": [0.5, 1.5, 4.0], "k": [0.3, 1.0, 3.0]})
    stages = run_stages(study, Evaluators(_decay_evaluator()), NullStore())
    assert "ran out of simulations" in stages[0].resumed
    assert stages[0].message.startswith("handed back to the refinement")
    assert stages[0].cost < stages[1].cost


# -- growing horizons -----------------------------------------------------------------------

LONG = np.linspace(0.0, 20.0, 800)  # 9.5 periods of the true sine


def _long(w: float, a: float) -> np.ndarray:
    return a * np.sin(w * LONG)


LONG_Y = _long(3.0, 1.0) + np.random.default_rng(8).normal(0.0, SIGMA, LONG.size)


class Shortening(Evaluators):
    """Evaluators that also score the first part of the record (as identify's do)."""

    def __init__(self, measured: np.ndarray) -> None:
        super().__init__(FloorEvaluator(_long, measured, SIGMA))
        self.fractions: list[float] = []
        self.measured = measured

    def shortened(self, parameters, experiments, fraction):
        self.fractions.append(fraction)
        k = math.ceil(fraction * LONG.size)
        return FloorEvaluator(lambda w, a: _long(w, a)[:k], self.measured[:k], SIGMA)


def _horizon_run(start: dict[str, float], measured: np.ndarray = LONG_Y):
    data = pd.DataFrame({"time": LONG, "y": np.zeros_like(LONG)})
    params = [Parameter("w", [2.0, 2.5, 3.2], 0.5, 8.0), Parameter("a", [0.5, 1.0, 2.0], 0.0)]
    study = Study(
        fmu=ROOT / "no-such.fmu",
        parameters=params,
        experiments=[Experiment(data, inputs={}, outputs={"y": "y"}, noise={"y": SIGMA})],
        method=Method(cost="sse", weighting="noise", replicates=1),
    )
    evaluators = Shortening(measured)
    ctx = context.Context(study, evaluators, NullStore(), None, context.Control())
    exps = [e.name for e in study.experiments]
    cost = evaluators.ev.cost(**start)
    arrays = StageResult("taguchi", "taguchi", dict(start), cost, 0, "given")
    stages = [arrays, context.refinement(ctx, start, exps)]
    evaluators.restart = local._horizons(ctx, stages, float(LONG.size), exps)
    return stages, evaluators


def test_a_local_minimum_is_left_by_following_the_data_from_its_first_part(monkeypatch):
    # w = 2.4 lies two valleys of the full record's cost away from the truth (w = 3)
    stages, evaluators = _horizon_run({"w": 2.4, "a": 1.0})
    assert stages[1].cost > 100 * LONG.size  # the refinement alone: a local minimum
    assert [s.kind for s in stages[2:]] == ["horizon"] * 3 + ["refinement"]
    assert evaluators.fractions == list(adaptive.HORIZONS)
    assert [s.fraction for s in stages[2:5]] == list(adaptive.HORIZONS)
    assert stages[2].start == pytest.approx({"w": 2.4, "a": 1.0})  # the arrays' best
    answer = adaptive.answer_stage(stages)
    assert answer is stages[-1] and answer.x["w"] == pytest.approx(3.0, rel=1e-3)
    assert answer.cost < 2 * LONG.size
    assert not answer.agrees and evaluators.restart  # a new answer: no agreement
    # the horizons' costs, over part of the data, never compete with the full cost
    assert all(s.cost < answer.cost for s in stages[2:5])
    # without the short horizons, the same refinement stays in the local minimum
    monkeypatch.setattr(local, "HORIZONS", ())
    alone, _ = _horizon_run({"w": 2.4, "a": 1.0})
    assert adaptive.answer_stage(alone).cost > 100 * LONG.size


def test_a_horizon_is_a_waypoint_that_ends_once_a_step_gains_little(monkeypatch):
    stages, _ = _horizon_run({"w": 2.4, "a": 1.0})
    horizons, last = stages[2:5], stages[-1]
    assert LocalStop.WAYPOINT in [s.stop for s in horizons]
    assert "enough for a waypoint" in horizons[1].message
    assert last.stop is not LocalStop.WAYPOINT  # the full data: the usual tolerances
    # without the rule every horizon converges to SciPy's tolerances: more runs, and
    # the refinement on the full data ends at the same answer
    full = context.polish

    def exact(*args, waypoint=False, **kwargs):
        return full(*args, **kwargs)

    monkeypatch.setattr(local, "polish", exact)
    exact_stages, _ = _horizon_run({"w": 2.4, "a": 1.0})
    assert LocalStop.WAYPOINT not in [s.stop for s in exact_stages]
    spent = sum(s.nfev for s in stages[2:])
    assert sum(s.nfev for s in exact_stages[2:]) > spent
    assert exact_stages[-1].x["w"] == pytest.approx(last.x["w"], rel=1e-6)
    assert exact_stages[-1].cost == pytest.approx(last.cost, rel=1e-6)


def test_a_settled_answer_runs_no_horizon():
    stages, evaluators = _horizon_run({"w": 2.98, "a": 1.0})  # the truth's own valley
    assert [s.kind for s in stages] == ["taguchi", "refinement"]
    assert evaluators.fractions == []


def test_a_poor_fit_that_the_horizons_reach_again_needs_no_restart(monkeypatch):
    # an offset the model cannot make: the best fit is poor, but it is the only valley
    offset = LONG_Y + 0.5
    stages, evaluators = _horizon_run({"w": 2.98, "a": 1.0}, offset)
    assert stages[1].cost > 100 * LONG.size  # a poor fit: the horizons run
    assert evaluators.fractions == list(adaptive.HORIZONS)
    last = stages[-1]
    assert last.agrees == "refinement"
    assert last.cost == pytest.approx(stages[1].cost, rel=adaptive.AGREE)
    assert evaluators.restart is False  # so no restart follows
    monkeypatch.setattr(local, "AGREE", -1.0)  # without the rule: restarts
    again, ev2 = _horizon_run({"w": 2.98, "a": 1.0}, offset)
    assert ev2.restart is True and not again[-1].agrees


def test_the_poor_fit_warning_says_which_search_found_no_lower_basin():
    from tsid_fmu.weak import poor_fit as _poor_fit

    stage = StageResult("refinement", "refinement", {"w": 3.0}, 1e6, 10, "")
    assert _poor_fit(stage) == []
    stage.poor_fit = {"floor": 800.0, "ratio": 1250.0, "restarts": 2}
    assert "1.25e+03 times the noise floor, and 2 restart(s)" in _poor_fit(stage)[0]
    stage.poor_fit.update(restarts=0, horizons_agree=True)
    assert "from their first part reached the same answer" in _poor_fit(stage)[0]


def test_a_stationarity_test_reads_back_typed_and_an_old_trails_as_the_models():
    """What decided a test is a field, not a phrase of its message."""
    tried = verdict.Stationarity(False, verdict.GN_TEST, 40.0, 9.0e3, "lower", "trial", 55.0)
    back = verdict.Stationarity.from_dict(tried.to_dict())
    assert back == tried and back.by_trial
    probed = verdict.Stationarity(False, "local probes", 3.0, 9.0e3, "lower", "probe", 3.0)
    assert not verdict.Stationarity.from_dict(probed.to_dict()).by_trial
    old = {"holds": False, "test": verdict.GN_TEST, "gap": 40.0, "cost": 9.0e3,
           "detail": f"a decrease of 40; {verdict.LOWER_TRIED} 55"}  # fmt: skip
    read = verdict.Stationarity.from_dict(old)
    assert read.decided_by == "model" and not read.by_trial  # the message is not parsed
    assert verdict.Stationarity.from_dict({}) is None
    assert StageResult("r", "refinement", {}, 1.0, 0, "").stationarity is None
    stage = StageResult("r", "refinement", {}, 1.0, 0, "", stationarity=tried)
    stage.stop = LocalStop.VALLEY  # the trail's JSON form reads back typed
    stage.parallel, stage.pairs, stage.agrees = [["a", "k", 2.0]], [], "refinement"
    written = stage.to_dict()["extra"]
    assert written["stop"] == "valley" and written["parallel"] == [["a", "k", 2.0]]
    again = StageResult.from_dict(stage.to_dict())
    assert again.stationarity == tried and again.stop is LocalStop.VALLEY
    assert (again.parallel, again.pairs, again.agrees) == ([["a", "k", 2.0]], [], "refinement")
    assert not {"stationarity", "stop", "parallel", "pairs", "agrees"} & set(again.extra)


def test_a_stages_typed_outcomes_read_back_from_its_json_alone():
    """Each typed attribute a decision reads goes into ``extra`` under its name only in
    :meth:`StageResult.to_dict`, and reads back typed; unset ones are not written."""
    from tsid_fmu.search.phases.contribution import Contribution
    from tsid_fmu.study.schema import Phase

    bare = StageResult("c", "check", {"w": 1.0}, 2.0, 3, "done")
    assert bare.to_dict()["extra"] == {}
    stage = StageResult("c", "contribution", {"w": 1.0}, 2.0, 3, "done", extra={"note": 1})
    stage.start, stage.start_cost, stage.start_from = {"w": 0.5}, 7.0, "the arrays"
    stage.resumed, stage.crawled = "ran out", {"cost": 9.0, "nfev": 4}
    stage.poor_fit = {"floor": 1.0, "ratio": 300.0, "restarts": 1, "horizons_agree": False}
    stage.phases = [Phase(["a", "b"], ["e1"], "phase 1")]
    written = stage.to_dict()["extra"]
    assert written["start"] == {"w": 0.5} and written["phases"][0]["parameters"] == ["a", "b"]
    again = StageResult.from_dict(json.loads(json.dumps(stage.to_dict())))
    for attr in ("start", "start_cost", "start_from", "resumed", "crawled", "poor_fit"):
        assert getattr(again, attr) == getattr(stage, attr), attr
    assert again.phases == stage.phases and isinstance(again.phases[0], Phase)
    assert again.extra == {"note": 1}  # only what no decision reads stays in extra
    stage.start_cost = 0.0  # a zero is a value, not "unset"
    assert StageResult.from_dict(stage.to_dict()).start_cost == 0.0
    # a contribution stage's tables are kept as four keys of extra of their own
    stage.contribution = Contribution(None, {"e1": {"a": 90.0}}, {"e1": []}, {"e1": [["a"]]})
    written = stage.to_dict()["extra"]
    assert written["percent"] == {"e1": {"a": 90.0}} and written["groups"] == {"e1": [["a"]]}
    again = StageResult.from_dict(json.loads(json.dumps(stage.to_dict())))
    assert again.contribution == stage.contribution and again.extra == {"note": 1}
