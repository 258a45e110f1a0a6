"""The Taguchi stage: iterations until the levels converge (Case 3) or a limit is reached.

Each iteration is :func:`tsid_fmu.search.taguchi.iteration.run_iteration`. Between iterations
the stage applies the MISO paper's lesson: when continuing from the best choice has not
lowered the cost for ``RERUN_AFTER`` iterations, the search is re-conducted from the
next-best run of the iteration that made that choice (the paper continued from its run
7, then went back to run 4). The answer is the best parameter set seen, so it is never
worse than any run evaluated.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from tsid_fmu.errors import SimulationError, StudyError
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.timelimit import timed_out
from tsid_fmu.numerics.tuning import RERUN_AFTER
from tsid_fmu.search.record import IterationRecord, Rerun, json_float
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.taguchi.iteration import Best, ProgressCallback, run_iteration
from tsid_fmu.search.taguchi.nextlevels import next_frame
from tsid_fmu.study.schema import Method

__all__ = ["HANDOVER", "RERUN_AFTER", "Recorder", "TaguchiRun", "taguchi_stage"]


HANDOVER = (
    "handed over to the refinement after iteration {index}: its array spans the first "
    "ranges, and a least-squares refinement from its best set finishes faster than more "
    "arrays (they go on where the refinement's answer is not settled)"
)
"""Why a stage with a hand-over (``refine = "auto"``) ends after its first iteration."""


def _hand_back(records: list[IterationRecord], run: TaguchiRun) -> str | None:
    """Whether a continued stage hands back to the refinement (``run.hand_back_below``).

    A stage continued because the refinement's answer was unsettled has done its job
    once its best set lies below that answer and an iteration has stopped lowering it
    (by less than ``stall_rtol`` of itself, the stall of Case 3): a lower basin's point
    is then in hand, and the refinement finishes from it faster than more arrays.
    """
    below = run.hand_back_below
    if below is None or len(records) < 2:
        return None
    before, now = records[-2].best_cost, records[-1].best_cost
    if not (math.isfinite(now) and now < below):
        return None
    if before - now >= run.method.leveling.stall_rtol * abs(now):
        return None
    return (
        f"handed back to the refinement: the best cost {now:.6g} is below the refinement's "
        f"{below:.6g} and iteration {records[-1].index} lowered it by less than "
        f"{run.method.leveling.stall_rtol:g} of itself"
    )


class Recorder(Protocol):
    """Receives each finished iteration (the audit trail writes it to disk)."""

    def iteration(self, record: IterationRecord) -> None:
        """Keep a finished iteration."""


@dataclass
class TaguchiRun:
    """How to run (or continue) one Taguchi stage."""

    name: str
    space: Space
    first: Frame
    method: Method
    fixed: Mapping[str, float] = field(default_factory=dict)
    prior: list[IterationRecord] = field(default_factory=list)
    override: Frame | None = None
    override_note: str | None = None
    nfev_before: int = 0
    max_iterations: int | None = None
    pause_after: int | None = None
    experiments: list[str] = field(default_factory=list)
    starts: list[tuple[dict[str, float], str]] = field(default_factory=list)
    handover: bool = False
    hand_back_below: float | None = None


def _next_best(
    records: list[IterationRecord], run: TaguchiRun
) -> tuple[IterationRecord, int] | None:
    """Find the run to re-conduct from when the last iterations did not lower the cost."""
    if len(records) < RERUN_AFTER + 1:
        return None
    last, src = records[-1], records[-1 - RERUN_AFTER]
    if last.best_cost < src.best_cost or last.decision.converged:
        return None
    if any(r.rerun for r in records[-RERUN_AFTER:]):
        return None  # give a re-run its own iterations before judging it
    wide = 10 * run.method.leveling.tolerance
    if all(v <= wide for v in last.next_frame.spans(run.space).values()):
        return None  # near convergence a flat iteration is expected, not a wrong turn
    tried = {tuple(r.rerun_from) for r in records if r.rerun_from is not None}
    costs = src.measured_costs
    for i in [int(i) for i in np.argsort(costs, kind="stable")][1:]:
        if np.isfinite(costs[i]) and (src.index, i) not in tried:
            return src, i
    return None


def frame_from_run(record: IterationRecord, run: int, space: Space, method: Method) -> Frame:
    """Make the next frame of ``record`` centred on its run ``run`` (0-based) instead.

    Raises
    ------
    StudyError
        ``record`` has no such run (the message counts from 1, as the trail does).
    """
    if not 0 <= run < len(record.sets):
        raise StudyError(
            f"continue from run {run + 1}: iteration {record.index} of {record.stage} has "
            f"runs 1 to {len(record.sets)}"
        )
    x = {n: float(v) for n, v in zip(record.parameters, record.sets[run], strict=True)}
    label = f"iteration {record.index}, run {run + 1}"
    _, frame = next_frame(
        record.frame,
        space,
        record.sn_means(),
        (x, label),
        method.leveling,
        record.anova.contribution,
        None,
    )
    return frame


def _decide_rerun(
    records: list[IterationRecord], run: TaguchiRun, reruns: int, progress: ProgressCallback | None
) -> tuple[Frame, str, list[int]] | None:
    if records[-1].decision.converged or reruns >= run.method.max_reruns:
        return None
    alt = _next_best(records, run)
    if alt is None:
        return None
    src, i = alt
    frame = frame_from_run(src, i, run.space, run.method)
    note = (
        f"iteration {records[-1].index} did not lower the cost ({records[-1].best_cost:.6g}); "
        f"re-conducted from iteration {src.index}, run {i + 1} (next best)"
    )
    if progress:
        progress("rerun", {"message": note})
    return frame, note, [src.index, i]


def _stalled(records: list[IterationRecord], method: Method) -> str | None:
    """Case 3 by stalling: every S/N flat for ``stall`` iterations without a better cost."""
    n = method.leveling.stall
    if n == 0 or len(records) < n + 1:
        return None
    recent = records[-n:]
    if not all(
        all(d.delta_db < method.leveling.significance_db for d in r.decision.parameters)
        for r in recent
    ):
        return None
    before = records[-n - 1].best_cost
    if before - recent[-1].best_cost > method.leveling.stall_rtol * abs(before):
        return None
    return (
        f"Case 3: every S/N flat for {n} iterations and the best cost fell by less than "
        f"{method.leveling.stall_rtol:g} of itself: the remaining ranges are what the data "
        "hardly determine"
    )


def _handover(records: list[IterationRecord]) -> str | None:
    """Whether the last iteration ends the stage for the refinement: the first one does.

    The first array spans the first ranges, and its best set (a run, its predicted
    optimum or a start point) lies in the best basin the arrays have seen. A
    least-squares refinement from there, with its stationarity and fit tests, is the
    cheapest way to find out whether that basin holds the optimum: where its answer is
    not settled, this stage goes on from its records (:mod:`tsid_fmu.search.local.flow`),
    so further arrays are paid for only where a local method failed. Measured on the
    generalisation benchmark's development seeds (72 runs): handing over after the
    first iteration kept every success (72/72) at a median of 84 simulations, where
    waiting until an iteration lowered the best cost by less than half within 100 times
    the noise floor took 162.5 (and a hand-over once the arrays' linear residual model
    explained 90 % of their costs, 154.5). An iteration whose runs all failed hands
    nothing over.
    """
    if not math.isfinite(records[-1].best_cost):
        return None
    return HANDOVER.format(index=records[-1].index)


def _evaluate_starts(
    run: TaguchiRun, evaluator: Evaluator, progress: ProgressCallback | None
) -> tuple[Best | None, list[dict]]:
    """Score the start points; return the best and what the trail keeps of them."""
    if not run.starts:
        return None, []
    ev = evaluator.evaluate([dict(x) for x, _ in run.starts])
    if all(timed_out(e) for e in ev.errors):
        # an FMU that finishes no simulation would take the limit on every row too
        raise SimulationError(
            f"{run.name}: no start point finished a simulation within the time limit "
            f"({len(ev.errors)} tried: {', '.join(s for _, s in run.starts)}); first "
            f"reason: {ev.errors[0]}; check the FMU at these values, or give a longer "
            "--timeout"
        )
    kept, best = [], None
    for (x, source), cost in zip(run.starts, ev.costs[:, 0], strict=True):
        cost = float(cost) if np.isfinite(cost) else math.inf
        kept.append({"x": dict(x), "cost": json_float(cost), "source": source})
        if best is None or cost < best.cost:
            best = Best(dict(x), cost, source)
    if progress and best is not None:
        progress("start", {"stage": run.name, "cost": best.cost, "source": best.source})
    return best, kept


def _paused(run: TaguchiRun, ran: int) -> bool:
    """Whether ``run.pause_after`` iterations have run in this call."""
    return run.pause_after is not None and ran >= run.pause_after


def _limits(run: TaguchiRun, index: int, nfev: int, ran: int) -> tuple[int, str] | None:
    """Whether the stage must stop before iteration ``index`` (status, message)."""
    limit = run.max_iterations or run.method.max_iterations
    if index > limit:
        return 1, f"iteration limit ({limit}) reached before the levels converged"
    budget = run.method.max_simulations
    if budget is not None and nfev - run.nfev_before >= budget:
        return 1, f"simulation limit ({budget}) reached before the levels converged"
    if _paused(run, ran):
        return 2, f"paused after iteration {index - 1}: review the proposed levels and resume"
    return None


def _resume_point(
    run: TaguchiRun,
) -> tuple[list[IterationRecord], Frame, tuple[str, list[int] | None] | None, Best | None]:
    """Return the records so far, the next frame, a pending re-run and the best set."""
    records = list(run.prior)
    frame, pending = run.first, None
    if records:
        last = records[-1]
        frame = run.override or last.next_frame
        if run.override is not None:
            pending = (run.override_note or "levels edited by a person", None)
        elif last.next_rerun is not None:
            frame = last.next_rerun.frame
            pending = (last.next_rerun.note, last.next_rerun.origin)
    best = (
        Best(records[-1].best_x, records[-1].best_cost, records[-1].best_source)
        if records
        else None
    )
    return records, frame, pending, best


def _finished(
    run: TaguchiRun, records: list[IterationRecord], pending: object
) -> tuple[int, str] | None:
    """Whether a continued stage had already ended (converged, or handed over)."""
    if not records or pending is not None:
        return None
    if records[-1].decision.converged:
        return 0, records[-1].decision.message
    if run.handover and records[-1].handover:
        return 0, records[-1].handover
    if records[-1].handback:
        return 0, records[-1].handback
    return None


def taguchi_stage(
    run: TaguchiRun,
    evaluator: Evaluator,
    recorder: Recorder | None = None,
    progress: ProgressCallback | None = None,
) -> StageResult:
    """Run (or continue) a Taguchi stage; see the module docstring.

    A new stage first scores ``run.starts`` (the FMU's start values, the centre of the
    levels): its answer is never worse than doing nothing. With ``run.handover``, the
    first iteration ends the stage for the refinement (:func:`_handover`); once a stage
    has handed over, continuing it (with or without ``handover``) runs on without a
    second hand-over.
    """
    records, frame, pending, best = _resume_point(run)
    nfev = records[-1].nfev_total if records else run.nfev_before
    done = _finished(run, records, pending)
    if done is not None:
        return _result(run, records, best, nfev, *done)
    starts: list[dict] = []
    if not records:  # never worse than doing nothing: the start points are scored first
        n0 = evaluator.nfev
        best, starts = _evaluate_starts(run, evaluator, progress)
        nfev += evaluator.nfev - n0
    handover = run.handover and not any(r.handover for r in records)
    reruns = sum(r.rerun_from is not None for r in records)
    status, message, ran = 1, "", 0
    while (stop := _limits(run, len(records) + 1, nfev, ran)) is None:
        index = len(records) + 1
        if progress:
            progress("iteration", {"stage": run.name, "iteration": index, "frame": frame})
        rec = run_iteration(
            index, run.name, frame, run.space, evaluator, run.method, best, nfev, progress
        )
        if pending is not None:
            rec.rerun = pending[0]
            if pending[1] is not None:
                rec.rerun_from = list(pending[1])
        if index == 1 and starts:
            rec.starts = starts
        records.append(rec)
        best, nfev, ran = Best(rec.best_x, rec.best_cost, rec.best_source), rec.nfev_total, ran + 1
        frame, pending, ended = _decide(records, run, reruns, handover, progress)
        reruns += pending is not None and pending[1] is not None
        if recorder is not None:
            recorder.iteration(rec)
        if progress:
            progress("iteration done", {"record": rec})
        if ended is not None and rec.handover and _paused(run, ran):
            # a pause asked for here comes before the refinement; --resume goes on to it
            note = f"paused after iteration {index}, handed over: resume to refine"
            return _result(run, records, best, nfev, 2, note)
        if ended is not None:
            return _result(run, records, best, nfev, 0, ended)
    status, message = stop
    return _result(run, records, best, nfev, status, message)


def _decide(
    records: list[IterationRecord],
    run: TaguchiRun,
    reruns: int,
    handover: bool,
    progress: ProgressCallback | None,
) -> tuple[Frame, tuple[str, list[int]] | None, str | None]:
    """After an iteration: Case 3 by stalling, the hand-over, or a re-run.

    Returns the next frame, a pending re-run (note, origin) and, if the stage ends, why.
    """
    rec = records[-1]
    stalled = None if rec.decision.converged else _stalled(records, run.method)
    if stalled:
        rec.decision.converged, rec.decision.message = True, stalled
    if rec.decision.converged:
        return rec.next_frame, None, rec.decision.message
    handed = _handover(records) if handover else None
    if handed:
        rec.handover = handed
        return rec.next_frame, None, handed
    back = None if handover else _hand_back(records, run)
    if back:
        rec.handback = back
        return rec.next_frame, None, back
    alt = _decide_rerun(records, run, reruns, progress)
    if alt is None:
        return rec.next_frame, None, None
    frame, note, origin = alt
    rec.next_rerun = Rerun(frame, note, list(origin))
    return frame, (note, origin), None


def _result(
    run: TaguchiRun,
    records: list[IterationRecord],
    best: Best | None,
    nfev: int,
    status: int,
    message: str,
) -> StageResult:
    x = {**run.fixed, **(best.x if best else {})}
    return StageResult(
        name=run.name,
        kind=StageKind.TAGUCHI,
        x=x,
        cost=best.cost if best else float("inf"),
        nfev=nfev - run.nfev_before,
        message=message,
        status=status,
        records=records,
        experiments=list(run.experiments),
    )
