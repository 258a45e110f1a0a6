"""The Taguchi stage on its own: it converges by itself in a coupled valley, never losing
its best set (the behaviour the canonical-factor stage of the first round was tested
for, before the restructure replaced it by rotated factors inside the Taguchi stage)."""

from __future__ import annotations

import copy
import itertools
import math

import numpy as np
import pytest
from scipy.optimize import least_squares
from spec_helpers import CurveEvaluator

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search.record import Rerun
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.taguchi.stage import TaguchiRun, taguchi_stage
from tsid_fmu.study.schema import Method

T = np.linspace(0.0, 6.0, 400)
TRUTH = {"p": 3.0, "q": 0.5}
NOISE = np.random.default_rng(0).normal(0.0, 0.01, T.size)


def _model(p: float, q: float) -> np.ndarray:
    # the output depends on p*q and p/q only: along the p and q axes the cost surface is
    # a narrow valley at an angle, which main effects over p and q handle badly
    return p * q * np.sin(T) + (p / q) * np.cos(2 * T)


MEASURED = _model(**TRUTH) + NOISE


def ValleyEvaluator() -> CurveEvaluator:
    """Scores (p, q) by the weighted sum of squares against the noisy measurement."""
    return CurveEvaluator(_model, MEASURED, 0.01)


@pytest.mark.parametrize("array", ["L9", "L25"])
def test_taguchi_stage_converges_along_a_coupled_valley_and_never_worsens(array):
    levels = {"p": [1.0, 2.0, 4.0], "q": [0.2, 0.8, 1.6]} if array == "L9" else None
    if levels is None:  # five levels each, the truth off every level
        levels = {"p": [1.0, 1.5, 2.2, 3.3, 5.0], "q": [0.2, 0.3, 0.45, 0.7, 1.1]}
    space = Space(levels, {n: (1e-6, math.inf) for n in levels}, LevelingOptions())
    ev = ValleyEvaluator()
    run = TaguchiRun(
        name="taguchi",
        space=space,
        first=Frame.from_levels(space, levels),
        method=Method(cost="sse", array=array, max_iterations=60),
    )
    stage = taguchi_stage(run, ev)
    assert stage.status == 0, stage.message  # converged by itself, no refinement
    best = [rec.best_cost for rec in stage.records]
    assert all(b <= a for a, b in itertools.pairwise(best))  # the best is kept
    assert stage.cost == pytest.approx(ev.cost(**stage.x), rel=1e-12)
    assert stage.nfev == ev.nfev
    # against SciPy's least squares from the truth: the same minimum
    fit = least_squares(
        lambda v: (_model(*v) - MEASURED) / 0.01, [TRUTH["p"], TRUTH["q"]], xtol=1e-12
    )
    lsq = 2 * fit.cost
    assert stage.cost <= (1 + 1e-6) * lsq, (stage.cost, lsq)
    for k, v in zip(("p", "q"), fit.x, strict=True):
        assert abs(stage.x[k] / v - 1) < 1e-4, (k, stage.x[k], v)
    assert stage.nfev <= 300  # 156-160 simulations when this test was written


def test_an_iteration_with_a_failed_run_round_trips_through_strict_json():
    import json

    from tsid_fmu.search.record import IterationRecord

    levels = {"p": [1.0, 2.0, 4.0], "q": [0.2, 0.8, 1.6]}
    space = Space(levels, {n: (1e-6, math.inf) for n in levels}, LevelingOptions())
    run = TaguchiRun(
        name="taguchi",
        space=space,
        first=Frame.from_levels(space, levels),
        method=Method(cost="sse", array="L9", max_iterations=1),
    )
    rec = taguchi_stage(run, ValleyEvaluator()).records[0]
    rec.costs[3, 0] = np.inf  # a failed run
    rec.errors[3] = "experiment: simulation failed"
    text = json.dumps(rec.to_dict(), allow_nan=False)  # other tools read it too
    back = IterationRecord.from_dict(json.loads(text))
    assert np.isinf(back.costs[3, 0]) and back.errors[3] == rec.errors[3]
    assert back.best_x == rec.best_x and back.best_cost == rec.best_cost
    np.testing.assert_array_equal(back.sets, rec.sets)
    np.testing.assert_array_equal(
        back.costs[np.isfinite(rec.costs)], rec.costs[np.isfinite(rec.costs)]
    )


# -- what a stage reports, and a stage continued after a pause (killed mutants of
# docs/dev/mutation-survivors.md: the progress events, the recorder, the start points and
# the resume were reached by no fast test)


def _valley_run(**kw) -> TaguchiRun:
    levels = {"p": [1.0, 2.0, 4.0], "q": [0.2, 0.8, 1.6]}
    space = Space(levels, {n: (1e-6, math.inf) for n in levels}, LevelingOptions())
    method = Method(cost="sse", array="L9", max_iterations=kw.pop("max_iterations", 60))
    return TaguchiRun(
        name="valley", space=space, first=Frame.from_levels(space, levels), method=method, **kw
    )


def test_a_stage_reports_its_start_points_and_each_iteration_in_order():
    starts = [({"p": 2.0, "q": 0.8}, "centre"), ({"p": 9.0, "q": 9.0}, "far")]
    events, kept = [], []
    recorder = type("R", (), {"iteration": lambda self, rec: kept.append(rec)})()
    ev = ValleyEvaluator()
    ev.evaluate([{"p": 1.0, "q": 1.0}])  # an evaluator already used: its count is not 0
    run = _valley_run(starts=starts, fixed={"k": 7.0}, experiments=["e1"], nfev_before=5)
    stage = taguchi_stage(run, ev, recorder, lambda kind, data: events.append((kind, data)))
    assert stage.status == 0 and stage.name == "valley" and stage.experiments == ["e1"]
    assert stage.x["k"] == 7.0 and stage.nfev == ev.nfev - 1  # the start points counted
    assert kept == stage.records  # each record once, in order
    centre = ev.cost(p=2.0, q=0.8)
    assert events[0] == ("start", {"stage": "valley", "cost": centre, "source": "centre"})
    assert stage.records[0].starts == [
        {"x": {"p": 2.0, "q": 0.8}, "cost": centre, "source": "centre"},
        {"x": {"p": 9.0, "q": 9.0}, "cost": ev.cost(p=9.0, q=9.0), "source": "far"},
    ]
    assert all(not r.starts for r in stage.records[1:])
    assert all("starts" not in r.to_dict()["extra"] for r in stage.records[1:])
    begun = [d for k, d in events if k == "iteration"]
    done = [d["record"] for k, d in events if k == "iteration done"]
    assert [d["iteration"] for d in begun] == list(range(1, len(stage.records) + 1))
    assert all(d["stage"] == "valley" for d in begun) and done == stage.records
    assert begun[0]["frame"] is run.first
    assert stage.records[-1].nfev_total == ev.nfev - 1 + 5


def test_a_stage_paused_and_continued_ends_as_the_uninterrupted_one():
    whole = taguchi_stage(_valley_run(), ValleyEvaluator())
    first = taguchi_stage(_valley_run(pause_after=2), ValleyEvaluator())
    assert first.status == 2 and len(first.records) == 2
    rest = taguchi_stage(
        _valley_run(prior=first.records, nfev_before=first.nfev), ValleyEvaluator()
    )
    assert rest.status == whole.status == 0 and rest.message == whole.message
    assert [r.best_cost for r in rest.records] == [r.best_cost for r in whole.records]
    assert rest.nfev + first.nfev == whole.nfev and rest.x == whole.x
    # continuing a stage that had ended runs nothing more
    again = taguchi_stage(
        _valley_run(prior=whole.records, nfev_before=whole.nfev), ValleyEvaluator()
    )
    assert again.status == 0 and again.nfev == 0 and again.message == whole.message


def test_a_stage_whose_sn_is_always_flat_ends_by_stalling():
    """A significance no S/N reaches keeps every factor flat (Case 2, narrowing) and a
    tolerance no range reaches rules out Case 3 by size: the stall rule ends the stage."""
    run = _valley_run()
    run.method = Method(
        cost="sse",
        array="L9",
        max_iterations=60,
        leveling=LevelingOptions(significance_db=1e6, tolerance=1e-9),
    )
    stage = taguchi_stage(run, ValleyEvaluator())
    assert stage.status == 0 and stage.records[-1].decision.converged
    assert stage.message.startswith("Case 3: every S/N flat for 2 iterations")
    assert stage.message == stage.records[-1].decision.message
    assert not any(r.decision.converged for r in stage.records[:-1])


def test_a_stage_paused_before_its_first_iteration_has_no_answer():
    stage = taguchi_stage(_valley_run(pause_after=0, fixed={"k": 1.0}), ValleyEvaluator())
    assert stage.status == 2 and stage.records == [] and stage.nfev == 0
    assert stage.cost == math.inf and stage.x == {"k": 1.0}


def test_a_stage_continued_after_a_pending_rerun_or_edited_levels_starts_from_them():
    """The trail keeps a decided re-run in the last record (``next_rerun``; ``extra["next"]``
    in its JSON) and a person may edit the next levels (``override``): a continued stage
    runs its next iteration on those levels and says so in the record."""
    done = taguchi_stage(_valley_run(max_iterations=3), ValleyEvaluator())
    prior = copy.deepcopy(done.records)
    for r in prior:
        r.decision.converged = False
    chosen = prior[0].frame
    prior[-1].next_rerun = Rerun(chosen, "re-run note", [1, 2])
    nfev = prior[-1].nfev_total
    run = _valley_run(prior=prior, nfev_before=nfev, max_iterations=4)
    rec = taguchi_stage(run, ValleyEvaluator()).records[-1]
    assert rec.index == 4 and rec.frame.level_values(run.space) == chosen.level_values(run.space)
    assert rec.rerun == "re-run note" and rec.rerun_from == [1, 2]
    # levels edited by a person replace the decided ones, without a re-run origin
    prior = copy.deepcopy(done.records)
    for r in prior:
        r.decision.converged = False
    edited = _valley_run(prior=prior, nfev_before=nfev, max_iterations=4, override=chosen)
    rec = taguchi_stage(edited, ValleyEvaluator()).records[-1]
    assert rec.rerun == "levels edited by a person" and rec.rerun_from is None
    assert "rerun_from" not in rec.to_dict()["extra"]
    assert rec.frame.level_values(run.space) == chosen.level_values(run.space)
    # the best so far is carried into the continued stage: never worse than before
    assert rec.best_cost <= prior[-1].best_cost
