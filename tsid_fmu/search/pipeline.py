"""The stages of a study, run in order, each resumable from what the trail holds.

A single-group study runs one ``taguchi`` stage over all parameters. A phased study
(explicit ``[[phases]]``, or ``[contribution] enabled``) runs the ``contribution``
analyses, one ``phase`` stage per parameter group, and a joint phase over all
parameters on all identification experiments. Then, by ``[method] refine``: the
adaptive local search of :mod:`tsid_fmu.search.local.adaptive` (``"auto"`` with the ``sse``
cost: refinement, back to the arrays, horizons, restarts), the ``refinement`` alone
(``"least_squares"``), or the ``check`` stage's local probes (otherwise). Every stage
gets its own evaluator spec (its parameters, its experiments, the others held at their
current values) and reports its answer, its cost on its measured inputs, its
simulations and why it stopped.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from tsid_fmu.errors import StudyError
from tsid_fmu.search.context import Context, Control, StageStore, polish
from tsid_fmu.search.local.adaptive import answer_stage
from tsid_fmu.search.local.flow import check, local_search
from tsid_fmu.search.phases.stage import Evaluators, centre_values, joint_levels, plan_phases
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.taguchi.iteration import ProgressCallback
from tsid_fmu.search.taguchi.stage import TaguchiRun, frame_from_run, taguchi_stage
from tsid_fmu.search.taguchi.start import start_points
from tsid_fmu.study.definition import Study
from tsid_fmu.study.schema import Parameter, Phase

__all__ = ["Control", "Evaluators", "StageStore", "held_copies", "run_stages"]


class _Recorder:
    def __init__(self, store: StageStore, key: str, space: Space) -> None:
        self.store, self.key, self.space = store, key, space

    def iteration(self, record: IterationRecord) -> None:
        self.store.write_iteration(self.key, record, self.space)


def _pause_left(ctx: Context) -> int | None:
    """Return the iterations a stage may run before ``--pause-after`` pauses it.

    The pause counts the iterations of this call, over every stage: arrays that go on
    after a refinement was not settled count from where they handed over.
    """
    pause = ctx.control.pause_after
    return None if pause is None else max(pause - ctx.ran, 1)


def _taguchi(
    ctx: Context,
    key: str,
    name: str,
    kind: StageKind,
    params: list[Parameter],
    exps: list[str],
    current: Mapping[str, float],
    nfev_before: int,
    max_iterations: int | None,
    handover: bool = False,
    records: list[IterationRecord] | None = None,
    hand_back_below: float | None = None,
) -> StageResult:
    """Run (or continue) one Taguchi-kind stage of ``params`` on ``exps``.

    It scores its start points first (:mod:`tsid_fmu.search.taguchi.start`): the values the
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
        pause_after=_pause_left(ctx),
        experiments=list(exps),
        starts=start_points(
            space,
            ctx.study.simulated_fmu if method.start == "fmu" else None,
            current if set(names) <= set(current) else None,
        ),
        handover=handover,
        hand_back_below=hand_back_below,
    )
    evaluator = ctx.evaluators.get(names, list(exps), fixed)
    if prior and hasattr(evaluator, "mark_known"):
        # what the interrupted run simulated is not counted again (it was in memory)
        evaluator.mark_known(_simulated_sets(prior))
    before = len(prior)
    result = taguchi_stage(run, evaluator, _Recorder(ctx.store, key, space), ctx.progress)
    ctx.ran += max(len(result.records) - before, 0)
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


def _phases(ctx: Context, stages: list[StageResult]) -> list[Phase]:
    study = ctx.study
    ident = study.identify_names()
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
    return [Phase(**dataclasses.asdict(p)) for p in plan.phases or []]


def _phase_stage(
    ctx: Context,
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
        sub,
        key,
        name,
        StageKind.PHASE,
        params,
        exps,
        current,
        nfev,
        ctx.control.max_iterations or limit,
    )


def _run_phased(ctx: Context) -> list[StageResult]:
    study, stages = ctx.study, []
    phases = _phases(ctx, stages)
    missing = sorted(set(study.parameter_names) - {n for p in phases for n in p.parameters})
    if missing:
        raise StudyError(f"no phase identifies {missing}; add them to a [[phases]] entry")
    ident = study.identify_names()
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
    ctx = Context(study, evaluators, store, progress, control or Control())
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

        def resume(records: list[IterationRecord], below: float) -> StageResult:
            return _single(ctx, handover=False, records=records, below=below)

        return local_search(ctx, stages, adaptive, resume)
    return [*stages, check(ctx, answer_stage(stages))]


def held_copies(study: Study) -> dict[str, float]:
    """Return the values the arrays hold the per-experiment parameters' copies at.

    The centre of their first levels, as the shared parameters' centre start point: the
    arrays run over the shared parameters only, and the refinement after them moves the
    copies with the shared ones (:mod:`tsid_fmu.study.copies`).
    """
    names = [c.name for c in study.copies]
    if not names:
        return {}
    levels, bounds = study.first_levels(), study.bounds()
    space = Space(
        {n: levels[n] for n in names}, {n: bounds[n] for n in names}, study.method.leveling
    )
    return space.to_x(space.clip(np.zeros(space.dim)))


def _single(
    ctx: Context,
    handover: bool,
    records: list[IterationRecord] | None = None,
    below: float | None = None,
) -> StageResult:
    """Run the one Taguchi stage of an ungrouped study (continued from the trail, if any).

    A Taguchi stage always continues from its iterations on disk: finished, it returns
    at once; stopped at a limit, it goes on if the limit now allows. Its arrays run over
    the shared parameters, the per-experiment copies held (:func:`held_copies`).
    """
    exps = ctx.study.identify_names()
    params = list(ctx.study.shared_parameters)
    held = held_copies(ctx.study)
    limit = ctx.control.max_iterations
    return _taguchi(
        ctx,
        "",
        "taguchi",
        StageKind.TAGUCHI,
        params,
        exps,
        held,
        0,
        limit,
        handover,
        records,
        below,
    )


def _run_ungrouped(ctx: Context) -> StageResult:
    """Identify every parameter in one Taguchi stage on every identification experiment.

    The MISO paper groups parameters and identifies them in phases; this runs the same
    study without grouping (from the first levels, with the same refinement), kept in
    the trail as ``ungrouped/``, so the report can show what grouping gained or cost.
    The simulations are not part of the study's ``nfev``.
    """
    study, progress = ctx.study, ctx.progress
    exps = study.identify_names()
    if progress:
        progress("stage", {"name": "ungrouped", "message": "comparison: all parameters at once"})
    stage = _taguchi(
        ctx,
        "ungrouped",
        "ungrouped comparison",
        StageKind.TAGUCHI,
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
    polished = polish("ungrouped refinement", study, start, evaluator, None)
    polished.nfev += stage.nfev
    polished.records = stage.records
    return polished
