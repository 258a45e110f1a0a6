"""Identify a study: its stages in order, then the evidence for the answer.

``identify`` is the whole data flow in one call: the study (:mod:`tsid_fmu.study`)
gives the evaluators of each sub-problem (:mod:`tsid_fmu.evaluate`, over the FMU
runtime :mod:`tsid_fmu.fmu`); the stages (:mod:`tsid_fmu.search`) run the orthogonal
arrays and re-level; the answer is assessed (:mod:`tsid_fmu.uncertainty`), kept on
disk as it happens (:mod:`tsid_fmu.trail`) and reported (:mod:`tsid_fmu.report`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.conformance import check_conformance, record_conformance
from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.conformance import problem
from tsid_fmu.evaluate.protocol import Evaluator, Simulated
from tsid_fmu.evaluators import StudyEvaluators
from tsid_fmu.fmu.compiled import CompileNotice, warm_up
from tsid_fmu.report.console import COMPILING, ConsoleProgress
from tsid_fmu.report.files import write_result_files
from tsid_fmu.report.html import write_html
from tsid_fmu.report.markdown import markdown_report
from tsid_fmu.report.render import draw_study
from tsid_fmu.report.ssp import write_model_ssp
from tsid_fmu.result import PAUSED, IdentificationResult
from tsid_fmu.search.context import Context
from tsid_fmu.search.local.adaptive import answer_stage
from tsid_fmu.search.pipeline import Control, run_stages
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.structure.compare import StructureResult, run_structure
from tsid_fmu.search.taguchi.iteration import ProgressCallback
from tsid_fmu.status import study_status
from tsid_fmu.study.definition import Study
from tsid_fmu.study.unitcheck import check_units
from tsid_fmu.study.units import fmu_units, study_units
from tsid_fmu.trail.folder import NullStore, Trail
from tsid_fmu.uncertainty.assess import answer_space, assess, validate
from tsid_fmu.uncertainty.bounds import (
    bound_warnings,
    inert_parameters,
    on_bounds,
    unshown_warnings,
)
from tsid_fmu.uncertainty.fidelity import (
    Fidelity,
    check_fidelity,
    fidelity_record,
    fidelity_warnings,
    start_point,
    study_noise,
)
from tsid_fmu.uncertainty.sampled import for_study
from tsid_fmu.uncertainty.sensitivity import Sensitivities, residual_jacobian
from tsid_fmu.weak import WEAK_STD_ERROR, poor_fit, weak_parameters

__all__ = ["WEAK_STD_ERROR", "identify"]


def _progress(
    progress: bool | ProgressCallback, evaluators: StudyEvaluators
) -> tuple[ProgressCallback | None, CompileNotice | None]:
    """Return the study's progress callback and, with one, the compile notice (to close).

    ``"row"`` events get ``nfev``, the simulations run so far. With a callback, the
    simulation loop is compiled (or loaded from Numba's cache) here, before the first
    run: a first compile is announced (``"compiling"``) instead of a silent pause,
    and worker processes started later load it from the cache.
    """
    given = ConsoleProgress() if progress is True else (progress or None)
    if not given:
        return None, None

    def callback(event: str, info: dict[str, Any]) -> None:
        if event == "row" and "nfev" not in info:
            info = {**info, "nfev": evaluators.nfev}
        given(event, info)

    notice = CompileNotice(lambda: callback("compiling", {"message": COMPILING}))
    try:
        warm_up()
    except BaseException:
        notice.close()
        raise
    return callback, notice


def _annotate(folder: Path, record: IterationRecord, space: Space) -> None:
    """Keep what each rotated factor moves in its record (the plots are drawn at the end)."""
    describe = {
        f.name: record.frame.describe(space, f) for f in record.frame.factors if f.values is None
    }
    if describe:
        record.describe = describe


def _compare_ungrouped(
    study: Study,
    evaluators: StudyEvaluators,
    store: Trail | NullStore,
    result: IdentificationResult,
) -> dict[str, Any]:
    """Run the same study without grouping, to set beside the phased one."""
    alone = run_stages(study, evaluators, store, ungrouped=True)[0]
    return {
        "phased": {"cost": result.fun, "nfev": result.nfev, "x": dict(result.params)},
        "ungrouped": {
            "cost": alone.cost,
            "nfev": alone.nfev,
            "x": dict(alone.x),
            "message": alone.message,
        },
    }


def _fidelity(
    study: Study,
    evaluators: StudyEvaluators,
    x: Mapping[str, float],
    where: str,
    callback: ProgressCallback | None,
    sens: Sensitivities | None = None,
) -> Fidelity | None:
    """Check the solver at ``x``; from the start point on, use the interface it chose."""
    if evaluators.given is not None or not study.method.fidelity:
        return None
    exps = study.identify_names()
    spec = evaluators.spec(study.parameter_names, exps, {})
    check = check_fidelity(
        spec,
        x,
        where=where,
        noise=study_noise(study),
        sensitivities=sens,
        adopt=where == "start point",  # the answer was found with the old tolerance
        **evaluators.check_limit(evaluators.pool.get(evaluators.key(study, exps))),
    )
    evaluators.use(check.interface)
    evaluators.use_cs_tolerance(check.cs_tolerance)
    if callback:
        callback("fidelity", {"message": check.message, "check": check})
    return check


def _record(
    result: IdentificationResult, start: Fidelity | None, answer: Fidelity | None
) -> IdentificationResult:
    """Put the fidelity checks into ``result.fidelity``, and their warnings first."""
    if start is not None:
        result.fidelity = fidelity_record(start, answer)
        result.warnings[:0] = fidelity_warnings(start, answer)
    elif result.study is not None and not result.study.method.fidelity:
        result.fidelity = {"checked": False, "reason": "[method] fidelity = false"}
    return result


def _report(
    result: IdentificationResult,
    store: Trail,
    evaluators: StudyEvaluators,
    plots: bool,
    simulated: list[Simulated] | None,
    callback: ProgressCallback | None,
) -> None:
    """Write the report files; draw the figures (at the end, off the arrays' path)."""
    study = result.study
    if study is None:  # pragma: no cover - _finish always attaches the study
        return
    t0 = time.perf_counter()
    if result.status != PAUSED:
        write_result_files(result, store.out)
        write_model_ssp(result, store.out)
        store.write_text("report.md", markdown_report(result))
    figures = None
    if plots and evaluators.given is None:
        exps = study.identify_names()
        spec = evaluators.spec(study.parameter_names, exps, {})
        ev = evaluators.get(study.parameter_names, exps, {})
        figures = draw_study(
            result,
            store.out,
            spec=spec,
            simulated=simulated,
            simulate=lambda sets: ev.simulate(sets, count=False),
            units=study_units(study),
        )
    write_html(result, store.out, figures)
    if callback:
        callback(
            "report done",
            {
                "plots_seconds": figures.seconds if figures else 0.0,
                "plots_timings": dict(figures.timings) if figures else {},
                "seconds": time.perf_counter() - t0,
            },
        )


def _finish(
    study: Study,
    stages: list[StageResult],
    evaluators: StudyEvaluators,
    store: Trail | NullStore,
    plots: bool,
    fidelity: tuple[Fidelity | None, ProgressCallback | None] = (None, None),
    structure: StructureResult | None = None,
) -> IdentificationResult:
    status, _, message, told = study_status(stages, problem(evaluators.conformance))
    answer = answer_stage(stages)
    x = {n: answer.x.get(n, math.nan) for n in study.parameter_names}
    nit = sum(len(s.records) for s in stages)
    nfev = sum(s.nfev for s in stages)
    result = IdentificationResult(
        params=x,
        fun=answer.cost,
        nfev=nfev,
        success=status == 0,
        status=status,
        message=message,
        nit=nit,
        stages=stages,
        study=study,
        account=told,
    )
    result.warnings = list(store.notes)  # files in the output folder tsid did not write
    record_conformance(result, evaluators.conformance)
    rounds = {str(w): evaluators.rounds(w) for w in (1, 4, 16)}
    if None not in rounds.values():  # the wall time on 1, 4, 16 workers, in simulations
        result.rounds = rounds
    result.contribution = {
        n: [float(r.anova.contribution[n]) for r in result.iterations if n in r.names]
        for n in study.parameter_names
    }
    start, callback = fidelity
    if status == PAUSED or evaluators.given is not None:
        _with_structure(result, structure)
        if isinstance(store, Trail) and status == PAUSED and evaluators.given is None:
            _report(result, store, evaluators, plots, None, callback)  # for the review
        return _record(result, start, None)
    exps = study.identify_names()
    spec = evaluators.spec(study.parameter_names, exps, {})
    ev = evaluators.get(study.parameter_names, exps, {})
    found = assess(
        ev, spec, answer_space(study.first_levels(), study.bounds(), study.method.leveling), x,
        study_noise(study),
    )  # fmt: skip
    space = found.space
    for key in ("fun", "fit", "noise", "noise_source"):  # the noise the cost uses, and whence
        setattr(result, key, getattr(found, key))
    result.uncertainty = found.uncertainty
    if found.uncertainty is not None and found.sensitivities is not None:
        jac = residual_jacobian(found.sensitivities, spec, space, x)
        result.jac = jac[:, [found.sensitivities.names.index(n) for n in result.names]]
    result.intervals = dict(found.uncertainty.intervals) if found.uncertainty else {}
    result.sampled = for_study(study.method, ev, (spec, space, x), found, callback)
    result.on_bound = on_bounds(x, study.bounds(), study.first_levels())
    stopped = [(s.name, s.message, s.status) for s in stages]
    result.warnings = [
        *poor_fit(answer),
        *bound_warnings(result.on_bound, x, study.bounds(), _inert(found, spec)),
        *found.warnings,
        *unshown_warnings(stopped, status, result.intervals),
        *result.warnings,
        *evaluators.retried(),
    ]
    checked = _fidelity(study, evaluators, x, "answer", callback, found.sensitivities)
    _record(result, start, checked)
    result.weak = weak_parameters(result)
    if study.contribution.enabled and study.contribution.compare_ungrouped:
        result.comparison = _compare_ungrouped(study, evaluators, store, result)
    checks = [e.name for e in study.experiments if e.role == "validate"]
    if checks:
        vspec = evaluators.spec(study.parameter_names, checks, {})
        result.validation = validate(evaluators.get(study.parameter_names, checks, {}), vspec, x)
    _with_structure(result, structure)
    if isinstance(store, Trail):
        _report(result, store, evaluators, plots, found.simulated, callback)
    return result


def _inert(found: Any, spec: Any) -> list[str]:
    """Return the parameters with no effect on the outputs at the answer (none: no Jacobian)."""
    if found.sensitivities is None:
        return []
    return inert_parameters(residual_jacobian(found.sensitivities, spec), found.sensitivities.names)


def _with_structure(result: IdentificationResult, structure: StructureResult | None) -> None:
    """Put the chosen structure into the result, then describe each parameter.

    The structure's values follow the Real parameters in ``params``, with a ``nan``
    column each in ``jac`` (a discrete choice has no derivative), so that ``x``,
    ``cov`` and ``jac`` keep one order; then :meth:`describe_parameters`.
    """
    if structure is not None:
        result.params.update(structure.values)
        result.structures = structure.table()
        result.structure = structure.summary()
        if structure.tied:
            result.warnings.insert(0, f"structure: {structure.summary()['why']}")
        if result.jac is not None and result.jac.shape[1] < len(result.params):
            missing = len(result.params) - result.jac.shape[1]
            pad = np.full((result.jac.shape[0], missing), np.nan)
            result.jac = np.hstack([result.jac, pad])
    result.describe_parameters()


def _stages(
    study: Study,
    evaluators: StudyEvaluators,
    store: Trail | NullStore,
    callback: ProgressCallback | None,
    control: Control,
) -> tuple[Study, list[StageResult], StudyEvaluators, StructureResult | None]:
    """Run the stages; with choices, structure identification (its chosen study)."""
    if not study.choices:
        return study, run_stages(study, evaluators, store, callback, control), evaluators, None

    def make(sub: Study) -> StudyEvaluators:
        made = StudyEvaluators(sub, evaluators.runner, evaluators.given)
        if evaluators.interface is not None:
            made.use(evaluators.interface)
        if evaluators.fresh:
            made.use_fresh()
        made.conformance = evaluators.conformance
        evaluators.children.append(made)
        return made

    found = run_structure(Context(study, evaluators, store, callback, control), make)
    final = dataclasses.replace(
        study,
        choices=[],
        parameters=_of_structure(study, found),
        start_values={**study.start_values, **found.values},
    )
    return final, found.stages, found.evaluators, found


def _of_structure(study: Study, found: StructureResult) -> list:
    """Return the Real parameters of the chosen structure: those that change its outputs.

    A parameter with no effect there (a Stribeck velocity under Coulomb friction, or one
    the chosen FMU file does not have) is no parameter of the answer: it gets no value,
    no interval and no row in the report. One that changes them at the arrays' best
    point (``free``) stays, though it has none at the answer: a viscous coefficient on
    its bound 0, which logarithmic coordinates cannot move off. A paused search keeps
    them all.
    """
    if found.paused or not found.candidates:
        return list(study.parameters)
    pick = found.candidates[found.chosen]
    active = set(pick.active) | set(pick.free)
    return [p for p in study.parameters if p.name in active] or list(study.parameters)


def identify(
    study: Study | str | Path,
    out: str | Path | None = None,
    *,
    resume: bool = False,
    workers: int | None = None,
    timeout: float | None = None,
    scheduler: Any = None,
    progress: bool | ProgressCallback = False,
    plots: bool = True,
    max_iterations: int | None = None,
    pause_after: int | None = None,
    continue_from_run: int | None = None,
    evaluator: Evaluator | None = None,
) -> IdentificationResult:
    """Identify the parameters of a study's FMU from its measured data.

    Parameters
    ----------
    study : Study or path
        The study, or the path of its TOML file.
    out : path, optional
        Folder for the audit trail, plots and report, written as each iteration ends.
    resume : bool
        Continue the study already in ``out`` (after an interruption, or after a person
        edited the last ``next_levels.toml``).
    workers : int, optional
        Worker processes for the runs (default: the available cores). One worker is one
        worker process, under the time limit, so that a crashing FMU fails only its
        row; with ``timeout=0`` one worker runs in this process instead. The result is
        the same for any number.
    timeout : float, optional
        Time limit per simulation in seconds (default: derived from the first runs; 0:
        none). The solver-fidelity checks simulate in a child process under it too.
    scheduler : str or distributed.Client, optional
        A ``dask.distributed`` scheduler to send the runs to.
    progress : bool or callable
        True prints progress to stderr; a callable receives ``(event, info)``.
    plots : bool
        Draw the plots (main effects and fit per iteration, fit, convergence and
        parameter trajectories), at the end of the study, into ``out`` and
        ``report.html``.
    max_iterations : int, optional
        Override the Taguchi iteration limit of each stage.
    pause_after : int, optional
        Pause after this many iterations run by this call (review, edit
        ``next_levels.toml``, then ``resume``); counted from where the call starts, so
        ``resume=True, pause_after=1`` steps one iteration at a time.
    continue_from_run : int, optional
        With ``resume``: centre the next levels on this (1-based) run of the last
        iteration, as the MISO paper continued from its runs 7 and 4.
    evaluator : Evaluator, optional
        Score parameter sets with this instead (not closed here; no fit, intervals or
        report files are computed).

    Returns
    -------
    IdentificationResult
        ``x``, ``fun``, ``nfev``, ``success``, ``status``, ``message``, the ``stages``
        and the ``intervals``, with ``to_pandas()`` and ``to_dict()``.
    """
    if not isinstance(study, Study):
        study = Study.from_toml(study)
    if resume and out is None:
        raise StudyError("resume needs the output folder of the study (out=...)")
    if continue_from_run is not None and not resume:
        raise StudyError("continue_from_run needs resume=True and the study's folder")
    evaluators = StudyEvaluators(
        study, {"workers": workers, "timeout": timeout, "scheduler": scheduler}, evaluator
    )
    control = Control(pause_after, max_iterations, continue_from_run)
    if control.pause_after is not None and study.choices:  # its arrays do not pause
        raise StudyError("pause_after: a study with choices runs whole; it cannot pause yet")
    return _run(study, out, resume, evaluators, control, progress, plots)


def _run(
    study: Study,
    out: str | Path | None,
    resume: bool,
    evaluators: StudyEvaluators,
    control: Control,
    progress: bool | ProgressCallback,
    plots: bool,
) -> IdentificationResult:
    """Run the stages into ``out`` and assess the answer; close what it opened."""
    # before any simulation: a unit that disagrees with the FMU's is a value off by its factor
    check_units(study.parameters, fmu_units(study.fmu), Path(study.fmu).name)
    callback, notice = _progress(progress, evaluators)
    store: Trail | NullStore = NullStore()
    try:
        if out is not None:
            store = Trail(out, study, resume=resume, on_iteration=_annotate)
        start = _fidelity(study, evaluators, start_point(study), "start point", callback)
        check_conformance(study, evaluators, callback)  # a broken reset: fresh instances
        final, stages, used, found = _stages(study, evaluators, store, callback, control)
        result = _finish(final, stages, used, store, plots, (start, callback), found)
        result.study = study
        result.out_dir = Path(out) if out is not None else None
    finally:
        evaluators.close()
        store.close()  # the output folder's lock
        if notice is not None:
            notice.close()
    if callback:
        callback("done", {"result": result})
    return result
