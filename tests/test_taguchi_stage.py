"""The bookkeeping of a Taguchi stage (search/taguchi.py), without an FMU.

A stage re-runs from the next-best run when two iterations did not lower the cost (at
most ``max_reruns`` times, counted over a continued stage too), hands over to the
refinement once, scores its start points first and reads a continued stage back from
its records. These tests kill the mutants docs/dev/mutation-survivors.md listed as open in
``taguchi_stage``, ``_decide``, ``_resume_point``,
``_evaluate_starts``, ``_next_best`` and ``_decide_rerun``.
"""

from __future__ import annotations

import copy
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from spec_helpers import CurveEvaluator
from test_taguchi_valley import ValleyEvaluator, _valley_run

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.errors import SimulationError
from tsid_fmu.evaluate.protocol import Evaluation
from tsid_fmu.evaluate.timelimit import EXCEEDED
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi import stage as taguchi
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.taguchi.stage import (
    HANDOVER,
    RERUN_AFTER,
    TaguchiRun,
    _decide,
    _decide_rerun,
    _evaluate_starts,
    _next_best,
    _resume_point,
    taguchi_stage,
)
from tsid_fmu.study.schema import Method

# -- a stage that re-runs: a flat bowl whose minimum is the centre of the first levels --


def _bowl(p: float, q: float) -> np.ndarray:
    # cost 1 + 1e-4 (p - 2)^2 + 1.69e-4 (q - 0.8)^2: every S/N flat (Case 2), and the
    # centre run of the first L9 is the minimum, so no later iteration lowers the cost
    return np.array([1.0, 0.01 * (p - 2.0), 0.013 * (q - 0.8)])


class _RowEvaluator(CurveEvaluator):
    """The bowl, reporting each batch's rows to the progress callback as an FMU pool does."""

    def __init__(self) -> None:
        super().__init__(_bowl, np.zeros(3), 1.0)

    def evaluate(self, sets, progress=None) -> Evaluation:
        out = super().evaluate(sets)
        if progress is not None:
            progress(len(sets), len(sets))
        return out


def _bowl_run(**kw) -> TaguchiRun:
    levels = {"p": [1.0, 2.0, 3.0], "q": [0.4, 0.8, 1.2]}
    leveling = LevelingOptions(stall=0)  # no Case 3 by stalling: the re-runs decide
    space = Space(levels, {n: (1e-6, math.inf) for n in levels}, leveling)
    method = Method(
        cost="sse", array="L9", max_iterations=kw.pop("max_iterations", 12), leveling=leveling
    )
    return TaguchiRun(
        name="bowl", space=space, first=Frame.from_levels(space, levels), method=method, **kw
    )


def _run_bowl(run: TaguchiRun) -> tuple[object, list]:
    events: list = []
    stage = taguchi_stage(run, _RowEvaluator(), None, lambda k, d: events.append((k, d)))
    return stage, events


def test_a_stage_re_runs_from_the_next_best_run_at_most_max_reruns_times():
    stage, events = _run_bowl(_bowl_run())
    recs = stage.records
    assert stage.status == 1 and len(recs) == 12  # the iteration limit, no convergence
    # the best set never changes after iteration 1's centre run, and keeps its source
    assert {r.best_cost for r in recs} == {1.0}
    assert all(r.best_source == "iteration 1, run 5" for r in recs)
    decided = [r.index for r in recs if r.next_rerun is not None]
    assert decided == [3, 6]  # two (max_reruns) re-runs, then no more
    assert Method().max_reruns == 2
    notes = []
    for i in decided:
        nxt = recs[i - 1].to_dict()["extra"]["next"]  # as the trail keeps it
        assert set(nxt) == {"frame", "note", "from"}
        src, run = nxt["from"]
        assert src == i - RERUN_AFTER  # the iteration that made the choice
        assert nxt["note"] == (
            f"iteration {i} did not lower the cost (1); re-conducted from iteration {src}, "
            f"run {run + 1} (next best)"
        )
        # the next iteration runs on that frame and says why
        after = recs[i]
        assert after.frame.to_dict() == nxt["frame"]
        assert after.rerun == nxt["note"] and after.rerun_from == [src, run]
        notes.append(nxt["note"])
    assert [d["message"] for k, d in events if k == "rerun"] == notes
    assert sum(bool(r.rerun) for r in recs) == 2
    # the trail keeps them in extra and reads them back typed
    for rec in recs:
        back = IterationRecord.from_dict(json.loads(json.dumps(rec.to_dict())))
        assert (back.rerun, back.rerun_from) == (rec.rerun, rec.rerun_from)
        assert (back.next_rerun is None) == (rec.next_rerun is None) and back.extra == rec.extra
        if rec.next_rerun is not None:
            assert back.next_rerun.to_dict() == rec.next_rerun.to_dict()
    # each iteration's rows reached the progress callback with the stage's name
    rows = [d for k, d in events if k == "row"]
    assert [(d["iteration"], d["done"], d["total"]) for d in rows] == [
        (r.index, 9, 9) for r in recs
    ]
    assert all(d["stage"] == "bowl" for d in rows) and all(r.stage == "bowl" for r in recs)


def test_a_stage_paused_after_a_rerun_continues_the_rerun_count():
    """Paused after iteration 4 (the first re-run's iteration), the continued call has one
    re-run left: the stage ends as the uninterrupted one. ``nfev_before`` is what the
    study ran before the stage (as the pipeline passes it on both calls): the records
    count on from the last one."""
    whole, _ = _run_bowl(_bowl_run(nfev_before=7))
    first, _ = _run_bowl(_bowl_run(nfev_before=7, pause_after=4))
    assert first.status == 2 and [r.index for r in first.records if r.rerun] == [4]
    rest, _ = _run_bowl(_bowl_run(nfev_before=7, prior=first.records))
    assert [r.to_dict()["extra"] for r in rest.records] == [
        r.to_dict()["extra"] for r in whole.records
    ]
    assert [r.nfev_total for r in rest.records] == [r.nfev_total for r in whole.records]
    assert rest.nfev == whole.nfev == whole.records[-1].nfev_total - 7
    assert rest.message == whole.message


def test_a_simulation_limit_stops_a_stage():
    run = _bowl_run()
    run.method = Method(cost="sse", array="L9", max_simulations=25, leveling=run.method.leveling)
    stage, _ = _run_bowl(run)
    assert stage.status == 1 and len(stage.records) == 3  # 10 simulations an iteration
    assert stage.message == "simulation limit (25) reached before the levels converged"


def test_a_converged_stage_with_levels_edited_by_a_person_runs_on():
    whole = taguchi_stage(_valley_run(), ValleyEvaluator())
    assert whole.status == 0 and whole.records[-1].decision.converged
    n = len(whole.records)
    prior = copy.deepcopy(whole.records)
    again = taguchi_stage(_valley_run(prior=prior), ValleyEvaluator())  # ended: runs nothing
    assert again.records == prior and again.x == whole.x and again.cost == whole.cost
    edited = _valley_run(
        prior=copy.deepcopy(whole.records), override=whole.records[0].frame, max_iterations=n + 1
    )
    more = taguchi_stage(edited, ValleyEvaluator())
    assert len(more.records) == n + 1
    assert more.records[-1].rerun == "levels edited by a person"


def test_a_continued_stage_hands_over_once():
    whole = taguchi_stage(_valley_run(handover=True), ValleyEvaluator())
    k = len(whole.records)
    assert whole.message.startswith("handed over to the refinement")
    assert whole.records[-1].handover
    # paused before the hand-over: the continued stage still hands over
    first = taguchi_stage(_valley_run(handover=True, pause_after=k - 1), ValleyEvaluator())
    rest = taguchi_stage(_valley_run(handover=True, prior=first.records), ValleyEvaluator())
    assert rest.message == whole.message and len(rest.records) == k
    # continued after it (new levels given): no second hand-over
    more = taguchi_stage(
        _valley_run(
            handover=True,
            prior=copy.deepcopy(whole.records),
            override=whole.records[-1].next_frame,
            max_iterations=k + 3,
        ),
        ValleyEvaluator(),
    )
    assert more.status == 1 and len(more.records) == k + 3
    assert not any(r.handover for r in more.records[k:])


# -- _decide, _start_cost, _resume_point on records made by hand -------------------------


def _rec(index, cost, converged=False, deltas=(0.0,), extra=None):
    return SimpleNamespace(
        index=index,
        best_cost=cost,
        decision=SimpleNamespace(
            converged=converged,
            message=f"own message {index}",
            parameters=[SimpleNamespace(delta_db=d) for d in deltas],
        ),
        extra=dict(extra or {}),
        next_frame=f"frame after {index}",
        handover="",
        handback="",
        rerun="",
        rerun_from=None,
        next_rerun=None,
    )


def _decide_run(**kw):
    args = {"hand_back_below": None, "handover": False, **kw}
    return SimpleNamespace(method=Method(), space=None, **args)


def test_a_converged_iteration_keeps_its_own_message_when_it_would_also_stall():
    recs = [_rec(1, 1.0), _rec(2, 1.0), _rec(3, 1.0, converged=True)]
    assert _decide(recs, _decide_run(), 0, False, None) == ("frame after 3", None, "own message 3")
    assert recs[-1].decision.message == "own message 3"


def test_the_first_iteration_hands_over():
    recs = [_rec(1, 0.75, deltas=(1.0,), extra={"starts": [{"cost": 0.5}]})]
    frame, pending, ended = _decide(recs, _decide_run(), 0, True, None)
    assert ended == HANDOVER.format(index=1)
    assert ended.startswith("handed over to the refinement after iteration 1")
    assert recs[0].handover == ended and pending is None and frame == "frame after 1"


def test_a_stage_that_may_hand_over_hands_over_rather_than_back():
    """A fall below stall_rtol under the refinement's answer would hand back; a stage
    that has not handed over yet hands over instead."""
    recs = [_rec(1, 0.5 + 2.0**-20, deltas=(1.0,)), _rec(2, 0.5, deltas=(1.0,))]
    run = _decide_run(hand_back_below=1.0)
    assert _decide(recs, run, 0, True, None)[2] == HANDOVER.format(index=2)
    assert not recs[-1].handback
    ended = _decide(recs, run, 0, False, None)[2]
    assert ended.startswith("handed back to the refinement") and recs[-1].handback


def test_a_continued_stage_starts_from_the_last_records_best():
    recs = [
        SimpleNamespace(
            index=i,
            best_x={"p": float(i)},
            best_cost=10.0 - i,
            best_source=f"iteration {i}",
            next_frame=f"frame {i}",
            extra={},
            next_rerun=None,
        )
        for i in (1, 2, 3)
    ]
    run = SimpleNamespace(prior=recs, first="first", override=None, override_note=None)
    records, frame, pending, best = _resume_point(run)
    assert records == recs and frame == "frame 3" and pending is None
    assert (best.x, best.cost, best.source) == ({"p": 3.0}, 7.0, "iteration 3")


# -- the start points -----------------------------------------------------------------------


class _Fixed:
    """Returns the given costs and errors for a batch, whatever the sets."""

    nfev = 0

    def __init__(self, costs, errors):
        self.costs, self.errors = costs, errors

    def evaluate(self, sets, progress=None):
        return Evaluation(np.array([[c] for c in self.costs]), list(self.errors), len(sets))


def _starts_run():
    starts = [({"p": 1.0}, "fmu"), ({"p": 2.0}, "centre"), ({"p": 3.0}, "last stage")]
    return SimpleNamespace(name="phase 1", starts=starts)


def test_start_points_that_all_time_out_stop_the_stage_with_a_clear_message():
    errors = [f"e1: 30 s {EXCEEDED}", f"e2: 31 s {EXCEEDED}", f"e1: 32 s {EXCEEDED}"]
    with pytest.raises(SimulationError) as info:
        _evaluate_starts(_starts_run(), _Fixed([math.inf] * 3, errors), None)
    assert str(info.value) == (
        "phase 1: no start point finished a simulation within the time limit (3 tried: "
        f"fmu, centre, last stage); first reason: e1: 30 s {EXCEEDED}; check the FMU at "
        "these values, or give a longer --timeout"
    )
    # one that finished (or failed otherwise) is scored as usual
    errors[1] = None
    best, _ = _evaluate_starts(_starts_run(), _Fixed([math.inf, 4.0, math.inf], errors), None)
    assert best.source == "centre"


def test_a_start_point_without_a_finite_cost_is_never_the_best():
    events = []
    ev = _Fixed([math.nan, 4.0, 5.0], [None, None, None])
    best, kept = _evaluate_starts(_starts_run(), ev, lambda k, d: events.append((k, d)))
    assert (best.x, best.cost, best.source) == ({"p": 2.0}, 4.0, "centre")
    assert [k["cost"] for k in kept] == [None, 4.0, 5.0]
    assert events == [("start", {"stage": "phase 1", "cost": 4.0, "source": "centre"})]


# -- ties between runs, and the note's cost ------------------------------------------------


def test_runs_tied_in_cost_are_re_conducted_in_run_order():
    """An L27 whose runs all cost the same but its best (run 5): the next-best runs are
    runs 1, 2, 3 in that order (a stable sort), not in a sort's arbitrary tie order."""
    costs = np.full(27, 2.0)
    costs[4] = 1.0
    frame = SimpleNamespace(spans=lambda space: {"p": 0.2})
    recs = [
        SimpleNamespace(
            index=i + 1,
            best_cost=1.0,
            decision=SimpleNamespace(converged=False),
            extra={},
            rerun="",
            rerun_from=None,
            next_frame=frame,
            measured_costs=costs,
        )
        for i in range(3)
    ]
    run = SimpleNamespace(method=Method(), space=None)
    picked = []
    for k in range(3):
        src, i = _next_best(recs, run)
        assert src is recs[0]
        picked.append(i)
        recs[k].rerun_from = [1, i]  # a run re-conducted from is not taken again
    assert picked == [0, 1, 2]


def test_the_rerun_note_gives_the_last_iterations_cost(monkeypatch):
    recs = [
        SimpleNamespace(
            index=i + 1,
            best_cost=c,
            decision=SimpleNamespace(converged=False),
            extra={},
            rerun="",
            rerun_from=None,
            next_frame=SimpleNamespace(spans=lambda space: {"p": 0.2}),
            measured_costs=np.array([c, c + 1.0, c + 2.0]),
        )
        for i, c in enumerate([5.0, 4.0, 3.0, 3.0, 3.0])
    ]
    run = SimpleNamespace(method=Method(), space=None)
    alt = _next_best(recs, run)
    assert alt[0] is recs[2] and alt[1] == 1
    seen = []  # the frame itself is pinned by test_stopping_rules.py
    monkeypatch.setattr(
        taguchi, "frame_from_run", lambda src, i, space, method: seen.append((src.index, i)) or "f"
    )
    frame, note, origin = _decide_rerun(recs, run, 0, None)
    assert note == (
        "iteration 5 did not lower the cost (3); re-conducted from iteration 3, run 2 (next best)"
    )
    assert origin == [3, 1] and seen == [(3, 1)] and frame == "f"


def test_of_start_points_tied_in_cost_the_first_listed_is_the_best():
    best, _ = _evaluate_starts(_starts_run(), _Fixed([4.0, 4.0, 5.0], [None] * 3), None)
    assert best.source == "fmu"
