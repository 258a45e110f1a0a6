"""The local search after the arrays: refinement, back to the arrays, horizons, restarts.

The order of the steps and why each is taken are in :mod:`tsid_fmu.search.local.adaptive`;
with ``refine = "none"`` (or a cost other than ``sse``) :func:`check` runs the local
probe test at the arrays' answer instead.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.search.context import Context, note, polish, refinement
from tsid_fmu.search.local.adaptive import AGREE, HORIZONS, answer_stage, restart_start
from tsid_fmu.search.local.combined import refine_in_combinations
from tsid_fmu.search.local.restarts import Restarts
from tsid_fmu.search.outcome import LocalStop
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.search.verdict import POOR_FIT, noise_floor, probe_test

__all__ = ["check", "local_search"]

#: Continues the handed-over Taguchi stage from its records, until it ends or hands back
#: below the given cost (the refinement's answer).
Resume = Callable[[list[IterationRecord], float], StageResult]


def _unsettled(stages: list[StageResult], floor: float) -> str | None:
    """Why the answer so far needs more search: no stationarity shown, or a poor fit."""
    answer = answer_stage(stages)
    test = answer.stationarity
    if test is None or not test.holds:
        detail = test.detail if test is not None else "no stationarity test was made"
        return f"the refined answer is not shown to be an optimum ({detail})"
    if floor > 0 and answer.cost > POOR_FIT * floor:
        return (
            f"the refined answer is a poor fit (cost {answer.cost:.6g}, "
            f"{answer.cost / floor:.3g} times the noise floor)"
        )
    return None


def _collapsed(refined: StageResult) -> str | None:
    """Whether the refinement stopped short: its budget ran out.

    A refinement that ran out of simulations did not end by its own tests; on a rough
    cost its last point can pass the stationarity test at 1.014 times the optimum (the
    accuracy benchmark's SISO encoder study, when the first refinement was given a third
    of the usual budget). A refinement that stopped at a tolerance, its trust region
    collapsed (``xtol``) included, is judged by its stationarity test alone
    (:func:`_unsettled`): that test simulates the Gauss-Newton step where the model does
    not hold (:func:`~tsid_fmu.search.verdict.gauss_newton_test`), so a collapse on a
    rough cost that stops short of the optimum fails it. Sending every collapse back to
    the arrays cost the generalisation seeds simulations and gained no success, and on
    the SISO rig family it changed no run (``docs/benchmarks/generalisation.md``).
    """
    if refined.kind == StageKind.REFINEMENT and refined.stop is LocalStop.LIMIT:
        return "the refinement ran out of simulations before its own tests ended it"
    return None


def local_search(
    ctx: Context, stages: list[StageResult], adaptive: bool, resume: Resume
) -> list[StageResult]:
    """Refine the best set; with ``adaptive``, go on where it is not settled.

    See :mod:`tsid_fmu.search.local.adaptive` for the order of the steps; ``resume`` continues
    the handed-over Taguchi stage (``stages[0]``) from its records to its own end.
    """
    study = ctx.study
    exps = study.identify_names()
    stages.append(refinement(ctx, _handed_over(stages), exps))
    if not adaptive:
        return _in_combinations(ctx, stages, exps)
    evaluator = ctx.evaluators.get(study.parameter_names, exps, {})
    floor = noise_floor(evaluator, study.method.weighting == "noise")
    first = stages[0]
    why = _unsettled(stages, floor) or _collapsed(stages[-1])
    if why:
        # judged again from what it left: a refinement in the combinations that
        # continues one which crawled is merged into it (the count stays the same)
        stages = _in_combinations(ctx, stages, exps, "combinations_first")
        why = _unsettled(stages, floor) or _collapsed(stages[-1])
    if why and first.kind == StageKind.TAGUCHI and any(r.handover for r in first.records):
        note(ctx, f"{why}: the Taguchi stage goes on")
        stages[0] = resume(first.records, stages[-1].cost)
        stages[0].resumed = why
        if stages[0].status == 2:
            return stages
        if stages[0].cost < stages[-1].cost:
            name = "refinement after the Taguchi stage went on"
            stages.append(refinement(ctx, stages[0].x, exps, "refinement_02", name))
    restarts = _restarts(ctx, stages, floor, exps) if _horizons(ctx, stages, floor, exps) else 0
    answer = answer_stage(_in_combinations(ctx, stages, exps))
    if floor > 0 and answer.cost > POOR_FIT * floor:
        ratio = answer.cost / floor
        agreed = any(s.agrees for s in stages)
        answer.poor_fit = {
            "floor": floor,
            "ratio": ratio,
            "restarts": restarts,
            "horizons_agree": agreed,
        }
    return stages


def _handed_over(stages: list[StageResult]) -> dict[str, float]:
    """Return where the first refinement starts: the best set when the arrays handed over.

    On ``--resume`` the Taguchi stage reads back with the iterations it ran after the
    hand-over too (the refinement's answer was not settled); the first refinement still
    starts where it did, so that it is read back rather than run again from elsewhere.
    """
    first = stages[0]
    if first.kind == StageKind.TAGUCHI:
        handed = [r for r in first.records if r.handover]
        if handed and handed[0] is not first.records[-1]:
            return {**first.x, **handed[0].best_x}
    return answer_stage(stages).x


def _in_combinations(
    ctx: Context, stages: list[StageResult], exps: list[str], key: str = "combinations"
) -> list[StageResult]:
    """Refine the answer in the combinations the data fix, where that lowers it.

    :func:`~tsid_fmu.search.local.combined.refine_in_combinations`: only where the answer's
    test held by a trial alone or found a lower point, and two parameters act through
    their combination. Measured on the SISO plant's law 3 (its study alone, dev seed
    122): the refinement's test held by a trial at 17470, 1.021 x the optimum, in the
    valley along ``F_vm + B_s``; refined in that combination, 17104 in 91 more runs. A
    finished one from the same answer is read back.
    """
    if stages[-1].status == 2:
        return stages  # paused: nothing more runs
    answer = answer_stage(stages)
    start = {n: float(answer.x[n]) for n in ctx.study.parameter_names}
    done = ctx.store.stage(key)
    if done is not None and done.start == start:
        return _continued(ctx, stages, answer, done, key)
    lower, _ = refine_in_combinations(ctx.study, ctx.evaluators, stages, ctx.progress)
    if lower is None:
        return stages
    lower.experiments = list(exps)
    lower.start = start
    if lower.status != 2:  # a paused one is run again on --resume
        ctx.store.write_stage(key, lower)
    return _continued(ctx, stages, answer, lower, key)


def _continued(
    ctx: Context, stages: list[StageResult], answer: StageResult, lower: StageResult, key: str
) -> list[StageResult]:
    """Append ``lower``; or, where it continues a refinement that crawled, merge the two.

    A refinement stopped in a valley along parallel columns (``stop`` ``VALLEY``,
    :mod:`~tsid_fmu.search.local.problem`) is not finished: the refinement in the
    combination is its continuation, so the two are one stage, with their simulations
    summed, the continuation's answer and test, and the first part in ``crawled``.
    Where the trust region stops along the valley depends on the last digits of its
    arithmetic (another BLAS kernel: 18605 against 18622 on the SISO example, 94
    against 102 runs), so a stage ending there would report a figure that the data
    do not determine; the two together end at the optimum. The merged stage has a
    folder of its own in the trail (``KEY_continued``), written again from the two on
    ``--resume``.
    """
    crawled = stages[-1]
    if crawled is not answer or crawled.stop is not LocalStop.VALLEY or lower.status == 2:
        stages.append(lower)
        return stages
    what = lower.name.removeprefix("refinement ")
    part = crawled.to_dict()  # the first part as the trail keeps it
    kept = {k: v for k, v in part["extra"].items() if k in ("stop", "stationarity", "start_cost")}
    stages[-1] = StageResult(
        name=crawled.name,
        kind=crawled.kind,
        x=dict(lower.x),
        cost=lower.cost,
        nfev=crawled.nfev + lower.nfev,
        message=f"{crawled.message}; then {what}: {lower.message}",
        status=lower.status,
        records=crawled.records,
        experiments=list(lower.experiments or crawled.experiments),
        extra=dict(lower.extra),
        stationarity=lower.stationarity,
        stop=lower.stop,
        parallel=lower.parallel,
        pairs=lower.pairs,
        start=crawled.start if crawled.start is not None else lower.start,
        start_cost=crawled.start_cost if crawled.start_cost is not None else lower.start_cost,
        crawled=kept | {k: part[k] for k in ("cost", "nfev", "x")},
        held=list(lower.held),
        solver=lower.solver,
    )
    ctx.store.write_stage(f"{key}_continued", stages[-1])
    return stages


def _horizons(ctx: Context, stages: list[StageResult], floor: float, exps: list[str]) -> bool:
    """Follow a minimum from the first part of the data to all of it, while unsettled.

    The refinement runs on the first :data:`HORIZONS` fractions of each experiment's
    samples in turn, each from the last one's answer, starting at the arrays' best set;
    then on the full data. Over a short horizon the simulated and measured signals
    cannot drift a whole period apart, so a lightly damped or swinging model's cost has
    few valleys there: the classic continuation for oscillators. A horizon is a waypoint,
    not an answer: it needs only the basin, so it ends at the first step that gains less
    than the stationarity gate's share of its cost
    (:attr:`~tsid_fmu.search.outcome.LocalStop.WAYPOINT`, the inexact inner solves of a
    continuation); the refinement on the full data converges to the usual tolerances.

    Returns whether restarts may still help: False when the answer was settled, or when
    the horizons, a second route, ended at the same stationary answer (within
    :data:`AGREE` of its cost): a poor fit that both routes reach is the model's or the
    noise's, not a local minimum's.
    """
    why = _unsettled(stages, floor)
    if why is None:
        return False
    before = answer_stage(stages)
    study = ctx.study
    names = study.parameter_names
    arrays = [s for s in stages if s.kind == StageKind.TAGUCHI and math.isfinite(s.cost)]
    x = dict((min(arrays, key=lambda s: s.cost) if arrays else answer_stage(stages)).x)
    note(ctx, f"{why}: the refinement follows the data's first part to its end")
    samples = sum(len(e.measured) for e in ctx.evaluators.spec(names, exps, {}).experiments)
    for k, fraction in enumerate(HORIZONS, 1):
        evaluator = ctx.evaluators.shortened(names, exps, fraction)
        if evaluator is None:
            return True
        if sum(len(e.measured) for e in evaluator.spec.experiments) >= samples:
            break
        stage = _horizon_stage(ctx, evaluator, x, f"horizon_{k:02d}", fraction)
        stage.experiments = list(exps)
        stages.append(stage)
        x = {n: float(stage.x[n]) for n in names}
    last = refinement(ctx, x, exps, "horizon_full", "refinement after the horizons")
    stages.append(last)
    test = last.stationarity
    if test is not None and test.holds and abs(last.cost - before.cost) <= AGREE * before.cost:
        note(ctx, "the horizons reached the same answer: no restart")
        last.agrees = before.name
        return False
    return True


def _horizon_stage(
    ctx: Context, evaluator: Evaluator, start: Mapping[str, float], key: str, fraction: float
) -> StageResult:
    """Refine on a shortened record (a finished one from the same start is read back)."""
    start = {n: float(start[n]) for n in ctx.study.parameter_names}
    done = ctx.store.stage(key)
    if done is not None and done.start == start:
        return done
    share = f"{100 * fraction:.3g} %"
    name = f"refinement on the first {share} of the data"
    result = polish(name, ctx.study, start, evaluator, ctx.progress, waypoint=True)
    result.kind = StageKind.HORIZON
    result.message = f"cost over the first {share} of each experiment's samples; {result.message}"
    result.start = start
    result.fraction = fraction
    ctx.store.write_stage(key, result)
    return result


def _restarts(ctx: Context, stages: list[StageResult], floor: float, exps: list[str]) -> int:
    """Refine from the start points, then from the next-best runs, while unsettled.

    At most ``max_reruns`` restarts (:class:`~tsid_fmu.search.local.restarts.Restarts`);
    returns how many ran. An answer still a poor fit after the search is recorded
    (``poor_fit``): the warnings then say that the search found no better basin.
    """
    study = ctx.study
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)

    def pick() -> tuple[dict[str, float], tuple[str, str, float]] | None:
        why = _unsettled(stages, floor)
        if why is None:
            return None
        explored = [s.start for s in stages if s.start is not None]
        explored += [s.x for s in stages if s.kind == StageKind.REFINEMENT]
        found = restart_start(stages, space, explored, starts_first=True)
        if found is None:
            return None
        return found[0], (why, found[2], found[1])

    def refine(start: dict[str, float], k: int, why: tuple[str, str, float]) -> StageResult:
        reason, origin, cost = why
        note(ctx, f"{reason}: restart {k} from {origin} (cost {cost:.6g})")
        stage = refinement(ctx, start, exps, f"restart_{k:02d}", f"restart {k} from {origin}")
        stages.append(stage)  # where the next pick judges the answer
        return stage

    loop = Restarts(study.method.max_reruns)
    loop.loop(pick, refine)
    return loop.count


def check(ctx: Context, last: StageResult) -> StageResult:
    """Run the local probe test at an answer no refinement tested (a ``check`` stage)."""
    study = ctx.study
    exps = study.identify_names()
    done = ctx.store.stage("check")
    x = {n: float(last.x[n]) for n in study.parameter_names}
    if done is not None and done.start == x:
        return done
    evaluator = ctx.evaluators.get(study.parameter_names, exps, {})
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    n0 = evaluator.nfev
    step = study.method.leveling.tolerance
    test, best, cost = probe_test(evaluator, space, x, last.cost, step)
    result = StageResult(
        name="stationarity check",
        kind=StageKind.CHECK,
        x=best,
        cost=cost,
        nfev=evaluator.nfev - n0,
        message=test.detail,
        status=0 if test.holds else 1,
        experiments=exps,
        stationarity=test,
        start=x,
    )
    ctx.store.write_stage("check", result)
    return result
