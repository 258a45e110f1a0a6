"""The one restart loop (issue 61, item 2): a start is refined from once, at most ``limit``.

:class:`~tsid_fmu.search.local.restarts.Restarts` holds the rule for the local search's
restarts, a structure candidate's restarts and a refinement restarted from its own
answer (:func:`~tsid_fmu.search.structure.optima.settle`).
"""

from __future__ import annotations

import math

import pytest

from tsid_fmu.search.local.restarts import Restarts
from tsid_fmu.search.outcome import LocalStop, Stationarity
from tsid_fmu.search.stage import StageResult


def _stage(x: dict[str, float], cost: float = 1.0, **kw) -> StageResult:
    return StageResult("r", "refinement", dict(x), cost, 3, "done", **kw)


def test_a_start_is_refined_from_once_and_numbered_by_the_attempts():
    calls = []

    def refine(start, k, why):
        calls.append((start, k, why))
        return _stage(start)

    loop = Restarts()
    assert loop.run({"a": 1}, refine, "first") is not None
    assert loop.run({"a": 1.0}, refine, "again") is None  # the same start, as floats
    assert loop.run({"a": 2.0}, refine, "second") is not None
    assert calls == [({"a": 1.0}, 1, "first"), ({"a": 2.0}, 2, "second")]
    assert loop.count == 2 and loop.tried == [{"a": 1.0}, {"a": 2.0}]


def test_at_most_limit_restarts_run_and_a_shared_tried_list_is_the_callers():
    tried = [{"a": 0.0}]
    loop = Restarts(limit=2, tried=tried)
    refine = lambda start, k, why: _stage(start)  # noqa: E731
    assert loop.run({"a": 0.0}, refine) is None  # refined from before the loop existed
    assert loop.run({"a": 1.0}, refine) and loop.run({"a": 2.0}, refine)
    assert not loop.left and loop.run({"a": 3.0}, refine) is None
    assert tried == [{"a": 0.0}, {"a": 1.0}, {"a": 2.0}]


def test_the_loop_asks_again_after_each_restart_and_ends_when_nothing_is_wanted():
    seen: list[StageResult] = []
    starts = iter([{"a": 1.0}, {"a": 2.0}])

    def pick():
        if len(seen) == 2:
            return None  # settled
        return next(starts), f"unsettled after {len(seen)}"

    def refine(start, k, why):
        stage = _stage(start)
        stage.message = why
        seen.append(stage)
        return stage

    out = Restarts(limit=5).loop(pick, refine)
    assert [s.message for s in out] == ["unsettled after 0", "unsettled after 1"]
    # a pick that repeats a start ends the loop instead of refining again
    again = Restarts(limit=5)
    assert len(again.loop(lambda: ({"a": 1.0}, ""), lambda s, k, w: _stage(s))) == 1
    assert math.isinf(Restarts().limit)


@pytest.mark.parametrize("moved", [True, False])
def test_settle_restarts_from_its_answer_only_where_it_moved(monkeypatch, moved):
    """A refinement stopped at a tolerance short of its own test is refined once more
    from its answer; one that never left its start would only repeat itself."""
    import tsid_fmu.search.structure.optima as optima

    start = {"a": 1.0}
    calls = []
    short = Stationarity(False, "projected Gauss-Newton", 1.0, 2.0, "a lower point")

    def polish(name, study, x, ev, progress=None):
        calls.append(dict(x))
        end = {"a": 2.0} if moved else dict(x)
        return _stage(end, cost=2.0, status=1, stop=LocalStop.FTOL, stationarity=short)

    monkeypatch.setattr(optima, "polish", polish)
    study = type("S", (), {"parameter_names": ["a"]})()
    stage = optima.settle("refinement", study, start, object())
    assert calls == ([start, {"a": 2.0}] if moved else [start])
    assert stage.nfev == (6 if moved else 3)
