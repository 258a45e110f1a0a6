"""The stages of a study, run in order, each resumable from what the trail holds.

A single-group study runs one ``taguchi`` stage over all parameters. A phased study
(explicit ``[[phases]]``, or ``[contribution] enabled``) runs the ``contribution``
analyses, one ``phase`` stage per parameter group, and a joint phase over all
parameters on all identification experiments. Then, by ``[method] refine``: the
adaptive local search of :mod:`tsid_fmu.search.adaptive` (``"auto"`` with the ``sse``
cost: refinement, back to the arrays, horizons, restarts), the ``refinement`` alone
(``"least_squares"``), or the ``check`` stage's local probes (otherwise). Every stage
gets its own evaluator spec (its parameters, its experiments, the others held at their
current values) and reports its answer, its cost on its measured inputs, its
simulations and why it stopped.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.search.adaptive import AGREE, HORIZONS, answer_stage, restart_start
from tsid_fmu.search.frame import Frame
from tsid_fmu.search.iteration import ProgressCallback
from tsid_fmu.search.phases import Evaluators, centre_values, joint_levels, plan_phases
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.refine import refine_stage
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.start import start_points
from tsid_fmu.search.taguchi import TaguchiRun, frame_from_run, taguchi_stage
from tsid_fmu.search.verdict import POOR_FIT, noise_floor, probe_test
from tsid_fmu.study.definition import Study
from tsid_fmu.study.schema import Parameter, Phase

__all__ = ["Control", "Evaluators", "StageStore", "run_stages"]


class StageStore(Protocol):
    """Where stages and iterations are kept (the audit trail, or nothing)."""

    def iterations(self, key: str) -> list[IterationRecord]:
        """Return a stage's complete iterations."""

    def override(self, key: str, record: IterationRecord, space: Space) -> Frame | None:
        """Return levels a person edited after ``record``, if any."""

    def stage(self, key: str) -> StageResult | None:
        """Return a finished stage."""

    def write_iteration(self, key: str, record: IterationRecord, space: Space) -> None:
        """Keep a finished iteration."""

    def write_stage(self, key: str, result: StageResult) -> None:
        """Keep a finished stage."""


@dataclass
class Control:
    """How this call runs the study: limits, pauses, a person's choice of run."""

    pause_after: int | None = None
    max_iterations: int | None = None
    continue_from_run: int | None = None


@dataclass
class _Context:
    study: Study
    evaluators: Evaluators
    store: StageStore
    progress: ProgressCallback | None
    control: Control


class _Recorder:
    def __init__(self, store: StageStore, key: str, space: Space) -> None:
        self.store, self.key, self.space = store, key, space

    def iteration(self, record: IterationRecord) -> None:
        self.store.write_iteration(self.key, record, self.space)


def _taguchi(
    ctx: _Context,
    key: str,
    name: str,
    kind: str,
    params: list[Parameter],
    exps: list[str],
    current: Mapping[str, float],
    nfev_before: int,
    max_iterations: int | None,
    handover: bool = False,
    records: list[IterationRecord] | None = None,
) -> StageResult:
    """Run (or continue) one Taguchi-kind stage of ``params`` on ``exps``.

    It scores its start points first (:mod:`tsid_fmu.search.start`): the values the
    earlier stages left where there are some, else the FMU's start values; and the
    centre of the first levels.
    """
    method = ctx.study.method
    levels = {p.name: list(p.levels) for p in params}
    space = Space(levels, {p.name: p.bounds for p in params}, method.leveling)
    names = [p.name for p in params]
    fixed = {k: v for k, v in current.items() if k not in names}
    prior = ctx.store.iterations(key) or list(records or [])
    override, note = None, None
    if prior:
        override = ctx.store.override(key, prior[-1], space)
        note = "levels edited by a person" if override is not None else None
        if ctx.control.continue_from_run is not None:
            run = ctx.control.continue_from_run
            override = frame_from_run(prior[-1], run - 1, space, method)
            note = f"continued from iteration {prior[-1].index}, run {run} (chosen)"
    run = TaguchiRun(
        name=name,
        space=space,
        first=Frame.from_levels(space, levels),
        method=method,
        fixed=fixed,
        prior=prior,
        override=override,
        override_note=note,
        nfev_before=nfev_before,
        max_iterations=max_iterations,
        pause_after=ctx.control.pause_after,
        experiments=list(exps),
        starts=start_points(
            space,
            ctx.study.fmu if method.start == "fmu" else None,
            current if set(names) <= set(current) else None,
        ),
        handover=handover,
    )
    evaluator = ctx.evaluators.get(names, list(exps), fixed)
    if handover:
        run.floor = noise_floor(evaluator, method.weighting == "noise")
    if prior and hasattr(evaluator, "mark_known"):
        # what the interrupted run simulated is not counted again (it was in memory)
        evaluator.mark_known(_simulated_sets(prior))
    result = taguchi_stage(run, evaluator, _Recorder(ctx.store, key, space), ctx.progress)
    result.kind = kind
    if result.status != 2:
        ctx.store.write_stage(key, result)
    return result


def _simulated_sets(records: list[IterationRecord]) -> list[dict[str, float]]:
    sets = []
    for rec in records:
        sets += [dict(zip(rec.parameters, map(float, row), strict=True)) for row in rec.sets]
        sets.append({k: float(v) for k, v in rec.prediction["x"].items()})
    return sets


def _polish(
    name: str,
    study: Study,
    start: Mapping[str, float],
    evaluator: Evaluator,
    progress: ProgressCallback | None,
) -> StageResult:
    """Run the refinement from ``start`` (its cost and residuals come from the memo)."""
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    floor = noise_floor(evaluator, study.method.weighting == "noise")
    scored = evaluator.evaluate([dict(start)])
    return refine_stage(
        name,
        space,
        start,
        float(scored.costs[0, 0]),
        evaluator,
        study.method,
        progress=progress,
        start_residuals=scored.residuals[0] if scored.residuals else None,
        floor=floor,
    )


def _refinement(
    ctx: _Context,
    start: Mapping[str, float],
    exps: list[str],
    key: str = "refinement",
    name: str = "refinement",
) -> StageResult:
    """Refine from ``start`` (a finished refinement from the same start is read back)."""
    study = ctx.study
    start = {n: float(start[n]) for n in study.parameter_names}
    done = ctx.store.stage(key)
    if done is not None and done.extra.get("start") == start:
        return done
    evaluator = ctx.evaluators.get(study.parameter_names, exps, {})
    result = _polish(name, study, start, evaluator, ctx.progress)
    result.experiments = list(exps)
    result.extra["start"] = start
    ctx.store.write_stage(key, result)
    return result


def _phases(ctx: _Context, stages: list[StageResult]) -> list[Phase]:
    study = ctx.study
    ident = [e.name for e in study.identify_experiments()]
    if study.phases:
        return [
            Phase(p.parameters, list(p.experiments) or ident, p.name, p.array, p.max_iterations)
            for p in study.phases
        ]
    plan = ctx.store.stage("contribution")
    if plan is None:
        if ctx.progress:
            ctx.progress("stage", {"name": "contribution", "message": "contribution analyses"})
        plan = plan_phases(study, ctx.evaluators)
        ctx.store.write_stage("contribution", plan)
    stages.append(plan)
    return [Phase(**p) for p in plan.extra["phases"]]


def _phase_stage(
    ctx: _Context,
    key: str,
    name: str,
    params: list[Parameter],
    exps: list[str],
    current: dict[str, float],
    nfev: int,
    array: str | None,
    limit: int | None,
) -> StageResult:
    if ctx.progress and not ctx.store.iterations(key):
        ctx.progress("stage", {"name": name, "message": f"{name} on {', '.join(exps)}"})
    sub = ctx
    if array is not None:
        method = dataclasses.replace(ctx.study.method, array=array)
        sub = dataclasses.replace(ctx, study=dataclasses.replace(ctx.study, method=method))
    return _taguchi(
        sub, key, name, "phase", params, exps, current, nfev, ctx.control.max_iterations or limit
    )


def _run_phased(ctx: _Context) -> list[StageResult]:
    study, stages = ctx.study, []
    phases = _phases(ctx, stages)
    missing = sorted(set(study.parameter_names) - {n for p in phases for n in p.parameters})
    if missing:
        raise StudyError(f"no phase identifies {missing}; add them to a [[phases]] entry")
    ident = [e.name for e in study.identify_experiments()]
    current, nfev = centre_values(study), sum(s.nfev for s in stages)
    by_name = {p.name: p for p in study.parameters}
    for i, ph in enumerate(phases):
        result = _phase_stage(
            ctx,
            f"phase_{i + 1:02d}",
            f"{ph.name}: {', '.join(ph.parameters)}",
            [by_name[n] for n in ph.parameters],
            list(ph.experiments),
            current,
            nfev,
            ph.array,
            ph.max_iterations,
        )
        stages.append(result)
        current.update({n: result.x[n] for n in ph.parameters})
        nfev += result.nfev
        if result.status == 2:
            return stages
    if study.contribution.refine_jointly and (len(phases) > 1 or len(ident) > 1):
        key = f"phase_{len(phases) + 1:02d}"
        result = _phase_stage(
            ctx,
            key,
            "joint phase: all parameters",
            joint_levels(study, current),
            ident,
            current,
            nfev,
            None,
            None,
        )
        stages.append(result)
    return stages


def run_stages(
    study: Study,
    evaluators: Evaluators,
    store: StageStore,
    progress: ProgressCallback | None = None,
    control: Control | None = None,
    *,
    ungrouped: bool = False,
) -> list[StageResult]:
    """Run every stage of a study in order; return their results.

    Stages the store already holds as finished are read back, not run again; an
    interrupted Taguchi stage continues from its last complete iteration. A paused
    stage (status 2) ends the list.

    With ``ungrouped=True``, instead, the one stage of :func:`_run_ungrouped`: the
    study's parameters all at once, for comparison with its phases.
    """
    ctx = _Context(study, evaluators, store, progress, control or Control())
    if ungrouped:
        return [_run_ungrouped(ctx)]
    adaptive = study.method.refine == "auto" and study.method.cost == "sse"
    if study.phases or study.contribution.enabled:
        stages = _run_phased(ctx)
    else:
        stages = [_single(ctx, handover=adaptive)]
    if stages[-1].status == 2:
        return stages
    if adaptive or study.method.refine == "least_squares":
        return _local_search(ctx, stages, adaptive)
    return [*stages, _check(ctx, answer_stage(stages))]


def _single(
    ctx: _Context, handover: bool, records: list[IterationRecord] | None = None
) -> StageResult:
    """Run the one Taguchi stage of an ungrouped study (continued from the trail, if any).

    A Taguchi stage always continues from its iterations on disk: finished, it returns
    at once; stopped at a limit, it goes on if the limit now allows.
    """
    exps = [e.name for e in ctx.study.identify_experiments()]
    params = list(ctx.study.parameters)
    limit = ctx.control.max_iterations
    return _taguchi(ctx, "", "taguchi", "taguchi", params, exps, {}, 0, limit, handover, records)


def _unsettled(stages: list[StageResult], floor: float) -> str | None:
    """Why the answer so far needs more search: no stationarity shown, or a poor fit."""
    answer = answer_stage(stages)
    test = answer.extra.get("stationarity") or {}
    if not test.get("holds", False):
        return f"the refined answer is not shown to be an optimum ({test.get('detail', '')})"
    if answer.cost > POOR_FIT * floor:
        return (
            f"the refined answer is a poor fit (cost {answer.cost:.6g}, "
            f"{answer.cost / floor:.3g} times the noise floor)"
        )
    return None


def _collapsed(refined: StageResult) -> str | None:
    """Whether the refinement stopped because its trust region collapsed (SciPy's xtol).

    A collapsed trust region means the steps its Jacobian proposed kept failing: on a
    rough cost (dry friction's stick-slip) or in a sharply curved valley the local model
    does not hold, and the arrays, which need no derivative, are the better judge.
    """
    if refined.kind == "refinement" and refined.extra.get("stop") == "xtol":
        return "the refinement's trust region collapsed (xtol): its local model did not hold"
    return None


def _local_search(ctx: _Context, stages: list[StageResult], adaptive: bool) -> list[StageResult]:
    """Refine the best set; with ``adaptive``, go on where it is not settled.

    See :mod:`tsid_fmu.search.adaptive` for the order of the steps.
    """
    study = ctx.study
    exps = [e.name for e in study.identify_experiments()]
    stages.append(_refinement(ctx, answer_stage(stages).x, exps))
    if not adaptive:
        return stages
    evaluator = ctx.evaluators.get(study.parameter_names, exps, {})
    floor = noise_floor(evaluator, study.method.weighting == "noise")
    first = stages[0]
    why = _unsettled(stages, floor) or _collapsed(stages[-1])
    if why and first.kind == "taguchi" and first.records[-1].extra.get("handover"):
        _note(ctx, f"{why}: the Taguchi stage goes on")
        stages[0] = _single(ctx, handover=False, records=first.records)
        stages[0].extra["resumed"] = why
        if stages[0].status == 2:
            return stages
        if stages[0].cost < stages[-1].cost:
            name = "refinement after the Taguchi stage went on"
            stages.append(_refinement(ctx, stages[0].x, exps, "refinement_02", name))
    restarts = _restarts(ctx, stages, floor, exps) if _horizons(ctx, stages, floor, exps) else 0
    answer = answer_stage(stages)
    if floor > 0 and answer.cost > POOR_FIT * floor:
        ratio = answer.cost / floor
        agreed = any(s.extra.get("agrees") for s in stages)
        answer.extra["poor_fit"] = {
            "floor": floor,
            "ratio": ratio,
            "restarts": restarts,
            "horizons_agree": agreed,
        }
    return stages


def _horizons(ctx: _Context, stages: list[StageResult], floor: float, exps: list[str]) -> bool:
    """Follow a minimum from the first part of the data to all of it, while unsettled.

    The refinement runs on the first :data:`HORIZONS` fractions of each experiment's
    samples in turn, each from the last one's answer, starting at the arrays' best set;
    then on the full data. Over a short horizon the simulated and measured signals
    cannot drift a whole period apart, so a lightly damped or swinging model's cost has
    few valleys there: the classic continuation for oscillators.

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
    arrays = [s for s in stages if s.kind == "taguchi" and math.isfinite(s.cost)]
    x = dict((min(arrays, key=lambda s: s.cost) if arrays else answer_stage(stages)).x)
    _note(ctx, f"{why}: the refinement follows the data's first part to its end")
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
    last = _refinement(ctx, x, exps, "horizon_full", "refinement after the horizons")
    stages.append(last)
    held = (last.extra.get("stationarity") or {}).get("holds", False)
    if held and abs(last.cost - before.cost) <= AGREE * before.cost:
        _note(ctx, "the horizons reached the same answer: no restart")
        last.extra["agrees"] = before.name
        return False
    return True


def _horizon_stage(
    ctx: _Context, evaluator: Evaluator, start: Mapping[str, float], key: str, fraction: float
) -> StageResult:
    """The refinement on a shortened record (a finished one from the same start is read back)."""
    start = {n: float(start[n]) for n in ctx.study.parameter_names}
    done = ctx.store.stage(key)
    if done is not None and done.extra.get("start") == start:
        return done
    share = f"{100 * fraction:.3g} %"
    name = f"refinement on the first {share} of the data"
    result = _polish(name, ctx.study, start, evaluator, ctx.progress)
    result.kind = "horizon"
    result.message = f"cost over the first {share} of each experiment's samples; {result.message}"
    result.extra.update(start=start, fraction=fraction)
    ctx.store.write_stage(key, result)
    return result


def _restarts(ctx: _Context, stages: list[StageResult], floor: float, exps: list[str]) -> int:
    """Refine from the start points, then from the next-best runs, while unsettled.

    At most ``max_reruns`` restarts; returns how many ran. An answer still a poor fit
    after the search is recorded (``extra["poor_fit"]``): the warnings then say that
    the search found no better basin.
    """
    study = ctx.study
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    k = 0
    while k < study.method.max_reruns:
        why = _unsettled(stages, floor)
        if why is None:
            break
        explored = [s.extra["start"] for s in stages if "start" in s.extra]
        explored += [s.x for s in stages if s.kind == "refinement"]
        found = restart_start(stages, space, explored, starts_first=True)
        if found is None:
            break
        k += 1
        _note(ctx, f"{why}: restart {k} from {found[2]} (cost {found[1]:.6g})")
        name = f"restart {k} from {found[2]}"
        stages.append(_refinement(ctx, found[0], exps, f"restart_{k:02d}", name))
    return k


def _note(ctx: _Context, message: str) -> None:
    if ctx.progress:
        ctx.progress("rerun", {"message": message})


def _check(ctx: _Context, last: StageResult) -> StageResult:
    """Run the local probe test at an answer no refinement tested (a ``check`` stage)."""
    study = ctx.study
    exps = [e.name for e in study.identify_experiments()]
    done = ctx.store.stage("check")
    x = {n: float(last.x[n]) for n in study.parameter_names}
    if done is not None and done.extra.get("start") == x:
        return done
    evaluator = ctx.evaluators.get(study.parameter_names, exps, {})
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    n0 = evaluator.nfev
    step = study.method.leveling.tolerance
    test, best, cost = probe_test(evaluator, space, x, last.cost, step)
    result = StageResult(
        name="stationarity check",
        kind="check",
        x=best,
        cost=cost,
        nfev=evaluator.nfev - n0,
        message=test.detail,
        status=0 if test.holds else 1,
        experiments=exps,
        extra={"start": x, "stationarity": test.to_dict()},
    )
    ctx.store.write_stage("check", result)
    return result


def _run_ungrouped(ctx: _Context) -> StageResult:
    """Identify every parameter in one Taguchi stage on every identification experiment.

    The MISO paper groups parameters and identifies them in phases; this runs the same
    study without grouping (from the first levels, with the same refinement), kept in
    the trail as ``ungrouped/``, so the report can show what grouping gained or cost.
    The simulations are not part of the study's ``nfev``.
    """
    study, progress = ctx.study, ctx.progress
    exps = [e.name for e in study.identify_experiments()]
    if progress:
        progress("stage", {"name": "ungrouped", "message": "comparison: all parameters at once"})
    stage = _taguchi(
        ctx,
        "ungrouped",
        "ungrouped comparison",
        "taguchi",
        list(study.parameters),
        exps,
        {},
        0,
        None,
    )
    if study.method.refine == "none" or stage.status == 2:
        return stage
    evaluator = ctx.evaluators.get(study.parameter_names, exps, {})
    start = {n: stage.x[n] for n in study.parameter_names}
    polished = _polish("ungrouped refinement", study, start, evaluator, None)
    polished.nfev += stage.nfev
    polished.records = stage.records
    return polished
