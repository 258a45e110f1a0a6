"""Every stopping rule at its boundary: one case just inside, one just outside (no FMU).

The rules: a range is *small* at a relative span of at most ``tolerance``; an S/N is
*flat* below ``significance_db``; a factor is *minor* below ``min_contribution``; Case 3
needs every factor flat and small; the stage stalls when every S/N has been flat for
``stall`` iterations and the best cost fell by at most ``stall_rtol`` of itself; and it
stops before an iteration past ``max_iterations``, at ``max_simulations``, or after
``pause_after`` iterations of this call. Rotated factors (search/nextlevels.py) have
their own copy of the tolerance and flatness rules, pinned the same way.
"""

from __future__ import annotations

import copy
import math
from types import SimpleNamespace

import numpy as np
import pytest
from test_taguchi_valley import ValleyEvaluator

from tsid_fmu.doe.leveling import LevelingOptions, relative_span, relevel
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi.frame import Factor, Frame
from tsid_fmu.search.taguchi.nextlevels import _rotated_decisions
from tsid_fmu.search.taguchi.stage import (
    TaguchiRun,
    _decide_rerun,
    _finished,
    _hand_back,
    _handover,
    _limits,
    _next_best,
    _stalled,
    taguchi_stage,
)
from tsid_fmu.study.schema import Method

FLAT = [-20.0, -20.0, -20.0]


def _case(levels: list[float], sn: list[float], **options) -> tuple[int, str]:
    d = relevel({"k": levels}, {"k": sn}, LevelingOptions(**options))
    return d.case, d.parameters[0].case


# -- the convergence tolerance (doe/leveling.py): 0.005 by default ------------------------


@pytest.mark.parametrize(
    ("levels", "span"),
    [([99.8, 100.0, 100.2], 0.004), ([99.75, 100.0, 100.25], 0.005)],
)
def test_a_flat_range_at_or_under_the_tolerance_converges(levels, span):
    assert relative_span(levels) == pytest.approx(span, rel=1e-12)
    assert _case(levels, FLAT) == (3, "converged")


@pytest.mark.parametrize(
    ("levels", "span"),
    [([99.7, 100.0, 100.3], 0.006), ([99.0, 100.0, 101.0], 0.02), ([98.0, 100.0, 102.0], 0.04)],
)
def test_a_flat_range_over_the_tolerance_is_narrowed_not_stopped(levels, span):
    """Spans between 0.005 and 0.05: a tolerance ten times too large stops here."""
    assert relative_span(levels) == pytest.approx(span, rel=1e-12)
    assert _case(levels, FLAT) == (2, "narrow")


def test_the_tolerance_option_moves_the_boundary():
    levels = [99.0, 100.0, 101.0]  # span 0.02
    assert _case(levels, FLAT, tolerance=0.02)[0] == 3
    assert _case(levels, FLAT, tolerance=0.0199)[0] == 2


# -- flatness (significance_db, 0.1 dB) and the Case 1/2/3 decision -----------------------


def test_an_sn_span_just_under_the_significance_is_flat():
    small = [99.9, 100.0, 100.1]
    assert _case(small, [0.0, 0.0999, 0.0]) == (3, "converged")
    assert _case([50.0, 100.0, 150.0], [0.0, 0.0999, 0.0]) == (2, "narrow")


def test_an_sn_span_at_the_significance_is_case_1():
    small = [99.9, 100.0, 100.1]
    # 0.1 - 0.0 is exactly significance_db: not flat (the rule is a strict "<")
    assert _case(small, [0.0, 0.1, 0.0]) == (1, "recentre")
    assert _case(small, [0.0, 0.0, 0.1001]) == (1, "shift")


def test_case_3_needs_every_factor_flat_and_small():
    small, wide = [99.9, 100.0, 100.1], [50.0, 100.0, 150.0]
    both = relevel({"a": small, "b": small}, {"a": FLAT, "b": FLAT})
    assert both.case == 3 and both.converged
    one_wide = relevel({"a": small, "b": wide}, {"a": FLAT, "b": FLAT})
    assert one_wide.case == 2 and not one_wide.converged
    one_moving = relevel({"a": small, "b": small}, {"a": FLAT, "b": [0.0, 0.2, 0.0]})
    assert one_moving.case == 1 and not one_moving.converged


def test_a_contribution_at_the_minimum_is_not_minor():
    levels = {"a": [1.0, 2.0, 3.0], "b": [10.0, 20.0, 30.0]}
    sn = {"a": [-30.0, -20.0, -25.0], "b": [-21.0, -20.0, -22.0]}
    opts = LevelingOptions(selective=True, min_contribution=5.0)

    def case_b(share: float) -> str:
        d = relevel(levels, sn, opts, contribution={"a": 90.0, "b": share})
        return d.parameters[1].case

    assert case_b(4.99) == "keep"
    assert case_b(5.0) == "recentre"


# -- the same rules for rotated factors (search/nextlevels.py) -----------------------------


def _rotated(half: float, sn: list[float]) -> tuple[float, int]:
    """Two rotated factors of offsets +/-``half`` about p = q = 100 (16 per unit)."""
    space = Space(
        {"p": [92.0, 108.0], "q": [92.0, 108.0]},
        {"p": (-math.inf, math.inf), "q": (-math.inf, math.inf)},
        LevelingOptions(),
    )
    offsets = np.array([-half, 0.0, half])
    factors = [
        Factor("A1", np.array([1.0, 0.0]), offsets),
        Factor("A2", np.array([0.0, 1.0]), offsets),
    ]
    frame = Frame(np.zeros(2), factors, anchor={"p": 100.0, "q": 100.0})
    d = _rotated_decisions(
        frame, space, {"A1": sn, "A2": FLAT}, np.zeros(2), "run 1", LevelingOptions(), {}
    )
    return frame.spans(space)["A1"], d.case


@pytest.mark.parametrize(("half", "span"), [(1 / 128, 0.0025), (1 / 64, 0.005)])
def test_flat_rotated_factors_at_or_under_the_tolerance_converge(half, span):
    assert _rotated(half, FLAT) == (pytest.approx(span, rel=1e-12), 3)


@pytest.mark.parametrize(("half", "span"), [(0.02, 0.0064), (0.125, 0.04)])
def test_flat_rotated_factors_over_the_tolerance_are_narrowed(half, span):
    assert _rotated(half, FLAT) == (pytest.approx(span, rel=1e-12), 2)


def test_a_rotated_factor_at_the_significance_is_case_1():
    assert _rotated(1 / 128, [0.0, 0.0999, 0.0])[1] == 3
    assert _rotated(1 / 128, [0.0, 0.1, 0.0])[1] == 1


def test_a_rotated_factor_contributing_exactly_the_minimum_is_not_minor():
    """As test_a_contribution_at_the_minimum_is_not_minor, for rotated factors."""
    space = Space(
        {"p": [92.0, 108.0], "q": [92.0, 108.0]},
        {"p": (-math.inf, math.inf), "q": (-math.inf, math.inf)},
        LevelingOptions(),
    )
    offsets = np.array([-0.25, 0.0, 0.25])
    factors = [
        Factor("A1", np.array([1.0, 0.0]), offsets),
        Factor("A2", np.array([0.0, 1.0]), offsets),
    ]
    frame = Frame(np.zeros(2), factors, anchor={"p": 100.0, "q": 100.0})
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-21.0, -20.0, -22.0]}
    opts = LevelingOptions(selective=True, min_contribution=5.0)

    def case_a2(share: float) -> str:
        d = _rotated_decisions(frame, space, sn, np.zeros(2), "run 1", opts, {"A2": share})
        return d.parameters[1].case

    assert case_a2(4.99) == "keep"
    assert case_a2(5.0) == "recentre"


# -- the stall rule (search/taguchi.py ``_stalled``): stall 2, stall_rtol 1e-4 ------------


def _records(costs: list[float], deltas: list[float] | None = None) -> list[SimpleNamespace]:
    deltas = deltas or [0.0] * len(costs)
    return [
        SimpleNamespace(
            best_cost=c, decision=SimpleNamespace(parameters=[SimpleNamespace(delta_db=d)])
        )
        for c, d in zip(costs, deltas, strict=True)
    ]


STALL = Method(leveling=LevelingOptions(stall_rtol=2.0**-10))  # exact in binary


def test_a_fall_of_just_less_than_stall_rtol_stalls():
    rtol = 1e-4
    method = Method()
    assert method.leveling.stall_rtol == rtol and method.leveling.stall == 2
    assert _stalled(_records([1.0, 1.0, 1.0 - 0.99 * rtol]), method) is not None
    assert _stalled(_records([8.0, 7.0, 8.0 * (1 - 0.99 * rtol)]), method) is not None
    # exactly stall_rtol of itself still counts as not improving
    assert _stalled(_records([1.0, 1.0, 1.0 - 2.0**-10]), STALL) is not None


def test_a_fall_of_just_more_than_stall_rtol_does_not_stall():
    """Kills a ``stall_rtol`` 1000 times too large (a 1.01e-4 fall would then stall)."""
    rtol = 1e-4
    assert _stalled(_records([1.0, 1.0, 1.0 - 1.01 * rtol]), Method()) is None
    assert _stalled(_records([8.0, 7.0, 8.0 * (1 - 1.01 * rtol)]), Method()) is None
    assert _stalled(_records([1.0, 1.0, 1.0 - 2.0**-10 - 2.0**-20]), STALL) is None


def test_the_stall_rule_counts_stall_flat_iterations():
    fall = 1.0 - 0.5e-4
    assert _stalled(_records([1.0, 1.0]), Method()) is None  # stall + 1 records needed
    assert _stalled(_records([1.0, 1.0, fall]), Method()) is not None
    # the iteration before the window may be significant; one inside it may not
    assert _stalled(_records([1.0, 1.0, fall], [5.0, 0.0999, 0.0]), Method()) is not None
    assert _stalled(_records([1.0, 1.0, fall], [0.0, 0.1, 0.0]), Method()) is None
    assert _stalled(_records([1.0, 1.0, fall], [0.0, 0.0, 0.1]), Method()) is None
    assert _stalled(_records([1.0] * 4), Method(leveling=LevelingOptions(stall=3))) is not None
    assert _stalled(_records([1.0] * 3), Method(leveling=LevelingOptions(stall=3))) is None
    assert _stalled(_records([1.0] * 9), Method(leveling=LevelingOptions(stall=0))) is None


# -- the limits (search/taguchi.py ``_limits``) --------------------------------------------


def _run(**kw) -> SimpleNamespace:
    method = Method(max_iterations=kw.pop("method_max", 5), max_simulations=kw.pop("budget", None))
    args = {"max_iterations": None, "nfev_before": 0, "pause_after": None, **kw}
    return SimpleNamespace(method=method, **args)


def test_the_iteration_limit_allows_the_last_iteration_and_stops_the_next():
    assert _limits(_run(), 5, 0, 4) is None
    assert _limits(_run(), 6, 0, 5) == (
        1,
        "iteration limit (5) reached before the levels converged",
    )
    # a call's own limit replaces the method's
    assert _limits(_run(max_iterations=3), 3, 0, 2) is None
    assert _limits(_run(max_iterations=3), 4, 0, 3)[0] == 1


def test_the_simulation_limit_counts_this_stages_simulations():
    run = _run(budget=100, nfev_before=40)
    assert _limits(run, 2, 139, 1) is None
    assert _limits(run, 2, 140, 1) == (
        1,
        "simulation limit (100) reached before the levels converged",
    )


def test_pause_after_stops_after_that_many_iterations_of_this_call():
    run = _run(pause_after=2, method_max=20)
    assert _limits(run, 7, 0, 1) is None
    assert _limits(run, 7, 0, 2) == (
        2,
        "paused after iteration 6: review the proposed levels and resume",
    )


def _valley(max_iterations: int):
    levels = {"p": [1.0, 2.0, 4.0], "q": [0.2, 0.8, 1.6]}
    space = Space(levels, {n: (1e-6, math.inf) for n in levels}, LevelingOptions())
    run = TaguchiRun(
        name="taguchi",
        space=space,
        first=Frame.from_levels(space, levels),
        method=Method(cost="sse", array="L9", max_iterations=max_iterations),
    )
    return taguchi_stage(run, ValleyEvaluator())


def test_a_stage_that_converges_on_its_last_allowed_iteration_converges():
    free = _valley(60)
    assert free.status == 0
    n = len(free.records)
    exact = _valley(n)
    assert exact.status == 0 and len(exact.records) == n, exact.message
    short = _valley(n - 1)
    assert short.status == 1 and len(short.records) == n - 1
    assert short.message == f"iteration limit ({n - 1}) reached before the levels converged"


# -- the hand-over, the hand-back and a continued stage (search/taguchi.py) ---------------
# Killed mutants of docs/dev/mutation-survivors.md: each boundary is met exactly (costs are
# binary fractions), and each message is pinned whole (it is what the trail and the
# report show as the reason the stage ended).


def _recs(
    costs: list[float], converged: list[bool] | None = None, handover="", handback=""
) -> list:
    converged = converged or [False] * len(costs)
    last = len(costs) - 1
    return [
        SimpleNamespace(
            index=i + 1,
            best_cost=c,
            decision=SimpleNamespace(converged=v, message=f"converged at {i + 1}"),
            extra={},
            handover=handover if i == last else "",
            handback=handback if i == last else "",
        )
        for i, (c, v) in enumerate(zip(costs, converged, strict=True))
    ]


def _handing(below: float | None = None, handover=False):
    return SimpleNamespace(method=STALL, hand_back_below=below, handover=handover)


def test_the_hand_over_comes_after_the_first_iteration_with_a_finished_run():
    assert _handover(_recs([0.75])) == (
        "handed over to the refinement after iteration 1: its array spans the first "
        "ranges, and a least-squares refinement from its best set finishes faster than more "
        "arrays (they go on where the refinement's answer is not settled)"
    )
    assert _handover(_recs([4.0, 2.0])).startswith(
        "handed over to the refinement after iteration 2:"
    )
    # an iteration whose runs all failed has nothing to hand over
    assert _handover(_recs([math.inf])) is None


def test_the_hand_back_needs_a_cost_below_the_refinements_and_a_stall():
    rtol = STALL.leveling.stall_rtol  # 2**-10
    run = _handing(below=1.0)
    # a fall of exactly stall_rtol of the cost is no stall; two records are enough
    assert _hand_back(_recs([0.5 + 0.5 * rtol, 0.5]), run) is None
    assert _hand_back(_recs([0.5 + 0.4 * rtol, 0.5]), run) == (
        "handed back to the refinement: the best cost 0.5 is below the refinement's 1 "
        "and iteration 2 lowered it by less than 0.000976562 of itself"
    )
    # not below the refinement's answer (equal, or above): go on
    assert _hand_back(_recs([1.0, 1.0]), run) is None
    assert _hand_back(_recs([3.0, 3.0]), run) is None
    assert _hand_back(_recs([0.5]), run) is None
    assert _hand_back(_recs([0.9, 0.5, 0.5]), run).endswith(
        "iteration 3 lowered it by less than 0.000976562 of itself"
    )


def test_the_stall_message_and_a_window_longer_than_two():
    assert _stalled(_records([1.0, 1.0, 1.0]), Method()) == (
        "Case 3: every S/N flat for 2 iterations and the best cost fell by less than "
        "0.0001 of itself: the remaining ranges are what the data hardly determine"
    )
    # stall 3: the fall is measured to the last record, not to the second of the window
    three = Method(leveling=LevelingOptions(stall=3))
    assert _stalled(_records([1.0, 1.0, 1.0, 0.5]), three) is None


def test_a_continued_stage_that_had_ended_reads_back_as_ended():
    converged = _recs([3.0, 2.0, 1.0], [False, False, True])
    assert _finished(_handing(), converged, None) == (0, "converged at 3")
    assert _finished(_handing(), converged, "pending") is None
    assert _finished(_handing(), _recs([3.0, 2.0, 1.0], [False, True, False]), None) is None
    handed = _recs([2.0, 1.0], handover="handed over")
    assert _finished(_handing(handover=True), handed, None) == (0, "handed over")
    assert _finished(_handing(handover=False), handed, None) is None
    assert _finished(_handing(), _recs([2.0, 1.0], handback="back"), None) == (0, "back")
    assert _finished(_handing(), [], None) is None


# -- the re-run from the next-best run (search/taguchi.py ``_next_best``) ------------------


def _flat_records(costs, converged=(), kept=None, spans=0.2):
    """Records whose runs cost ``10 * index + run`` (run 0 best), spans of ``spans``;
    ``kept`` gives an iteration's ``rerun`` and ``rerun_from``."""
    frame = SimpleNamespace(spans=lambda space: {"p": spans, "q": 0.01})
    return [
        SimpleNamespace(
            index=i + 1,
            best_cost=c,
            decision=SimpleNamespace(converged=i in converged),
            **{"rerun": "", "rerun_from": None, **(kept or {}).get(i, {})},
            next_frame=frame,
            measured_costs=np.array([10.0 * (i + 1) + k for k in (0, 3, 1, np.inf, 2)]),
        )
        for i, c in enumerate(costs)
    ]


RERUN = SimpleNamespace(method=Method(), space=None)


def test_the_next_best_run_is_taken_after_rerun_after_iterations_without_a_gain():
    recs = _flat_records([3.0, 3.0, 3.0])
    src, i = _next_best(recs, RERUN)
    assert src is recs[0] and i == 2  # the second-cheapest run of the iteration before
    assert _next_best(recs[:2], RERUN) is None
    assert _next_best(_flat_records([3.0, 3.0, 2.9]), RERUN) is None  # a gain
    five = _flat_records([5.0, 4.0, 3.0, 3.0, 3.0], converged=(1,))
    assert _next_best(five, RERUN)[0] is five[2]  # from RERUN_AFTER before the last
    assert _next_best(_flat_records([3.0] * 3, converged=(2,)), RERUN) is None
    assert _next_best(_flat_records([3.0] * 4, converged=(2,)), RERUN) is not None


def test_a_rerun_gets_its_own_iterations_and_is_not_repeated():
    assert _next_best(_flat_records([3.0] * 3, kept={1: {"rerun": "x"}}), RERUN) is None
    assert _next_best(_flat_records([3.0] * 3, kept={0: {"rerun": "x"}}), RERUN) is not None
    tried = _flat_records([3.0] * 3, kept={1: {"rerun_from": [1, 2]}})
    assert _next_best(tried, RERUN)[1] == 4  # then run 4 (the failed run 3 is skipped)
    both = _flat_records([3.0] * 3, kept={1: {"rerun_from": [1, 2]}, 0: {"rerun_from": [1, 4]}})
    assert _next_best(both, RERUN)[1] == 1


def test_near_convergence_a_flat_iteration_is_no_wrong_turn():
    """Every span at most ten times the tolerance (0.05): no re-run."""
    assert _next_best(_flat_records([3.0] * 3, spans=0.05), RERUN) is None
    assert _next_best(_flat_records([3.0] * 3, spans=0.0501), RERUN) is not None


def test_the_rerun_decision_its_note_and_its_frame():
    levels = {"p": [1.0, 2.0, 4.0], "q": [0.2, 0.8, 1.6]}
    space = Space(levels, {n: (1e-6, math.inf) for n in levels}, LevelingOptions())
    run = TaguchiRun(
        name="t",
        space=space,
        first=Frame.from_levels(space, levels),
        method=Method(cost="sse", array="L9", max_iterations=3),
    )
    recs = copy.deepcopy(taguchi_stage(run, ValleyEvaluator()).records)
    for r in recs:
        r.decision.converged = False
    recs[2].best_cost = recs[0].best_cost  # no gain over two iterations
    i = int(np.argsort(recs[0].measured_costs, kind="stable")[1])
    events = []
    frame, note, origin = _decide_rerun(recs, run, 0, lambda k, d: events.append((k, d)))
    assert origin == [1, i]
    assert note == (
        f"iteration 3 did not lower the cost ({recs[0].best_cost:.6g}); re-conducted from "
        f"iteration 1, run {i + 1} (next best)"
    )
    assert events == [("rerun", {"message": note})]
    x = dict(zip(recs[0].parameters, map(float, recs[0].sets[i]), strict=True))
    expected = relevel(
        recs[0].frame.level_values(space),
        recs[0].sn_means(),
        run.method.leveling,
        bounds=space.bounds,
        centre=x,
        contribution=recs[0].anova.contribution,
        centre_label=f"iteration 1, run {i + 1}",
    )
    assert frame.level_values(space) == expected.next_levels()
    # the limit on re-runs, and a converged last iteration, stop it
    assert _decide_rerun(recs, run, run.method.max_reruns, None) is None
    assert _decide_rerun(recs, run, run.method.max_reruns - 1, None) is not None
    recs[2].decision.converged = True
    assert _decide_rerun(recs, run, 0, None) is None
