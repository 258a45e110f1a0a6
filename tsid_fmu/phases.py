"""Phased identification of the MISO paper (Section 3, Steps i-iii, and Section 4).

1. *Input contribution* (Step i): the identification experiments, each driven by one
   input, are ranked by the size of the output they produce; the main contributor's
   subsystem is identified first.
2. *Parameter contribution* (Step ii): on each experiment in that order, the parameters
   not yet assigned are varied one at a time (three values); those that change this
   experiment's cost by at least ``min_percent`` belong to its subsystem and are
   grouped by contribution. Each group becomes a phase, most influential first.
3. *Phases* (Step iii): each phase is an ordinary Taguchi identification of its group on
   its experiment, with every other parameter held at its current value (identified
   ones at their identified values).
4. *Superposition check*: the identified model is simulated against the experiments
   with role ``validate`` (all inputs together) and their cost is reported (Fig. 18).

Phases can also be written explicitly in the study file as ``[[phases]]``. Everything
is written to the output folder as it happens: ``contribution/`` (tables),
``plan.json``, one folder per phase (each a complete single-phase trail that resumes on
its own), ``validation/`` and the report.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.contribution import (
    group_parameters,
    input_contribution,
    oat_values,
    parameter_contribution,
)
from tsid_fmu.errors import StudyError
from tsid_fmu.parallel import make_evaluator
from tsid_fmu.scoring import metrics
from tsid_fmu.study import Parameter, Phase, Study
from tsid_fmu.trail import atomic_write

__all__ = ["identify_phased", "plan_phases"]


def _centre(study: Study) -> dict[str, float]:
    """Centre value of each parameter: its middle one-at-a-time value."""
    out = {}
    for p in study.parameters:
        vals = study.contribution.values.get(p.name) or oat_values(p.levels)
        out[p.name] = float(sorted(vals)[1])
    return out


def _sub_study(
    study: Study,
    names: list[str],
    experiments: list[str],
    fixed: dict[str, float],
    **changes: Any,
) -> Study:
    """Return a study of ``names`` on ``experiments`` with the rest held at ``fixed``."""
    params = [p for p in study.parameters if p.name in names]
    params = [Parameter(p.name, list(p.levels), p.min, p.max, p.unit) for p in params]
    start = dict(study.start_values)
    start.update({k: v for k, v in fixed.items() if k not in names})
    # inside a sub-study every selected experiment is simulated and scored
    exps = [
        dataclasses.replace(e, role="identify") for e in study.experiments if e.name in experiments
    ]
    base = {
        "fmu": study.fmu,
        "parameters": params,
        "experiments": exps,
        "array": None,
        "cost": study.cost,
        "replicates": study.replicates,
        "input_noise": study.input_noise,
        "seed": study.seed,
        "max_iterations": study.max_iterations,
        "selection": study.selection,
        "leveling": study.leveling,
        "start_values": start,
        "interface": study.interface,
        "step_size": study.step_size,
        "name": study.name,
        "source": None,
        "max_reruns": study.max_reruns,
        "weighting": study.weighting,
    }
    base.update(changes)
    return Study(**base)


def _active_inputs(prepared: Any) -> list[str]:
    if prepared.inputs is None:
        return []
    std = np.std(prepared.inputs, axis=0)
    return [n for n, s in zip(prepared.input_names, std, strict=True) if s > 0]


def plan_phases(
    study: Study, out: Path | None = None, runner: dict[str, Any] | None = None
) -> tuple[list[Phase], dict[str, Any]]:
    """Plan the phases from the input and parameter contribution analyses.

    Parameters
    ----------
    study : Study
        The study (its ``contribution`` options apply).
    out : Path, optional
        Folder to write the contribution tables into.
    runner : dict, optional
        ``workers``, ``timeout`` and ``scheduler`` for
        :func:`tsid_fmu.parallel.make_evaluator`.

    Returns
    -------
    phases : list of Phase
        Phases in the order to identify them.
    analysis : dict
        ``input`` (InputContribution or None), ``parameters`` (experiment ->
        ParameterContribution), ``groups`` (experiment -> groups), ``nfev``.
    """
    opts = study.contribution
    ident = [e.name for e in study.experiments if e.role == "identify"]
    centre = _centre(study)
    analysis: dict[str, Any] = {"input": None, "parameters": {}, "groups": {}, "nfev": 0}
    clean = {"replicates": 1, "input_noise": 0.0}
    order = list(ident)
    if len(ident) > 1:
        probe = _sub_study(study, study.parameter_names, ident, centre, **clean)
        with make_evaluator(probe, **(runner or {})) as ev:
            measured = {p.experiment.name: p.measured for p in ev.prepared}
            active = {p.experiment.name: _active_inputs(p) for p in ev.prepared}
        inc = input_contribution(measured, active)
        analysis["input"] = inc
        order = inc.experiments
    remaining = list(study.parameter_names)
    phases: list[Phase] = []
    for k, exp in enumerate(order):
        if not remaining:
            break
        first = {p.name: p.levels for p in study.parameters}
        values = {n: study.contribution.values.get(n) or oat_values(first[n]) for n in remaining}
        sets = []
        for n, vals in values.items():
            for v in vals:
                s = dict(centre)
                s[n] = float(v)
                sets.append({m: s[m] for m in remaining})
        fixed = {m: centre[m] for m in study.parameter_names if m not in remaining}
        sub = _sub_study(study, remaining, [exp], fixed, **clean)
        with make_evaluator(sub, **(runner or {})) as ev:
            result = ev.evaluate(sets)
        analysis["nfev"] += result.nfev
        pc = parameter_contribution(values, {m: centre[m] for m in remaining}, result.mean_costs)
        analysis["parameters"][exp] = pc
        last = k == len(order) - 1
        mine = {n: p for n, p in pc.percent.items() if last or p >= opts.min_percent}
        if not mine:
            continue
        groups = group_parameters(mine, ratio=opts.group_ratio)
        analysis["groups"][exp] = groups
        for g in groups:
            phases.append(Phase(parameters=g, experiments=[exp]))
        remaining = [n for n in remaining if n not in mine]
    for i, ph in enumerate(phases):
        ph.name = f"phase {i + 1}"
    if out is not None:
        _write_analysis(out, analysis, phases)
    return phases, analysis


def _write_analysis(out: Path, analysis: dict[str, Any], phases: list[Phase]) -> None:
    d = out / "contribution"
    if analysis["input"] is not None:
        atomic_write(d / "input_contribution.csv", analysis["input"].to_pandas().to_csv())
    for exp, pc in analysis["parameters"].items():
        atomic_write(d / f"parameter_contribution_{_slug(exp)}.csv", pc.to_pandas().to_csv())
    plan = {
        "phases": [dataclasses.asdict(p) for p in phases],
        "groups": analysis["groups"],
        "input_order": analysis["input"].experiments if analysis["input"] else None,
        "percent": {e: pc.percent for e, pc in analysis["parameters"].items()},
    }
    atomic_write(out / "plan.json", json.dumps(plan, indent=2, default=_json_default) + "\n")


def _json_default(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return str(x)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "x"


def _identification_cost(study: Study, x: dict[str, float]) -> tuple[float, int]:
    """Noise-free cost of ``x`` summed over the identification experiments."""
    ident = [e.name for e in study.experiments if e.role == "identify"]
    sub = _sub_study(study, study.parameter_names, ident, {})
    with make_evaluator(sub, workers=1) as ev:
        res = ev.evaluate([x], clean=True)
    return float(res.mean_costs[0]), res.nfev


def _validate(study: Study, x: dict[str, float], out: Path | None, plots: bool) -> dict:
    """Simulate the validation experiments at ``x``; return cost and fit per experiment."""
    names = [e.name for e in study.experiments if e.role == "validate"]
    if not names:
        return {}
    sub = _sub_study(study, study.parameter_names, names, {})
    report: dict[str, Any] = {}
    with make_evaluator(sub, workers=1) as ev:
        cost = ev.evaluate([x], clean=True)
        simulated = ev.simulate_clean(x)
    for prep, y, err in simulated:
        name = prep.experiment.name
        if y is None:
            report[name] = {"error": err}
            continue
        per = ev.cost.per_output(prep.time, prep.measured, y)
        report[name] = {
            "cost": float(np.sum(per)),
            "cost_kind": study.cost,
            "fit": metrics(prep.time, prep.measured, y, prep.output_names),
        }
    report["_total_cost"] = float(cost.mean_costs[0])
    if out is not None:
        from tsid_fmu.report import fit_plot

        d = out / "validation"
        atomic_write(d / "validation.json", json.dumps(report, indent=2) + "\n")
        if plots:
            fit_plot(simulated, d / "fit.png", title="Superposition check: all inputs together")
    return report


def identify_phased(
    study: Study,
    out: str | Path | None = None,
    *,
    resume: bool = False,
    progress: Any = None,
    plots: bool = True,
    max_iterations: int | None = None,
    runner: dict[str, Any] | None = None,
) -> Any:
    """Identify a study in phases (explicit ``[[phases]]`` or planned by contribution).

    Parameters
    ----------
    study : Study
        The study.
    out : path, optional
        Output folder (contribution tables, plan, one folder per phase, validation).
    resume : bool
        Continue a phased study in ``out``: finished phases are read back, the
        interrupted one resumes.
    progress : callable, optional
        Progress callback (see :func:`tsid_fmu.engine.identify`).
    plots : bool
        Write plots.
    max_iterations : int, optional
        Override the iteration limit of every phase.
    runner : dict, optional
        ``workers``, ``timeout`` and ``scheduler`` (see :func:`tsid_fmu.engine.identify`).

    Returns
    -------
    IdentificationResult
        With the extra keys ``phases``, ``input_contribution``,
        ``parameter_contribution``, ``validation`` and (if asked) ``comparison``.
    """
    from tsid_fmu.engine import IdentificationResult, identify

    out_dir = Path(out) if out is not None else None
    if out_dir is not None:
        if (out_dir / "plan.json").exists() and not resume:
            raise StudyError(
                f"{out_dir} already holds a phased study; continue it with --resume, or "
                "choose another --out folder"
            )
        out_dir.mkdir(parents=True, exist_ok=True)
        if study.source is not None and not (out_dir / "study.toml").exists():
            atomic_write(out_dir / "study.toml", Path(study.source).read_bytes())

    analysis: dict[str, Any] = {"input": None, "parameters": {}, "groups": {}, "nfev": 0}
    if study.phases:
        ident = [e.name for e in study.experiments if e.role == "identify"]
        phases = [
            dataclasses.replace(p, experiments=list(p.experiments) or ident) for p in study.phases
        ]
        if out_dir is not None:
            _write_analysis(out_dir, analysis, phases)
    else:
        if progress:
            progress("phase", {"message": "contribution analysis (inputs and parameters)"})
        phases, analysis = plan_phases(study, out_dir, runner)
    covered = {n for p in phases for n in p.parameters}
    missing = [n for n in study.parameter_names if n not in covered]
    if missing:
        raise StudyError(f"no phase identifies {missing}; add them to a [[phases]] entry")

    current = _centre(study)
    results = []
    nfev = analysis["nfev"]
    for i, ph in enumerate(phases):
        if progress:
            what = f"{', '.join(ph.parameters)} on {', '.join(ph.experiments)}"
            progress("phase", {"message": f"{ph.name}: {what}"})
        sub = _sub_study(
            study,
            ph.parameters,
            ph.experiments,
            current,
            array=ph.array,
            max_iterations=max_iterations or ph.max_iterations or study.max_iterations,
            name=f"{study.name} - {ph.name}",
        )
        pdir = out_dir / f"phase_{i + 1:02d}" if out_dir is not None else None
        again = pdir is not None and any(pdir.glob("iteration_*/record.json"))
        res = identify(sub, pdir, resume=again, progress=progress, plots=plots, **(runner or {}))
        current.update(res.x)
        nfev += res.nfev
        results.append((ph, res))

    ident = [e.name for e in study.experiments if e.role == "identify"]
    if study.contribution.refine_jointly and (len(phases) > 1 or len(ident) > 1):
        ph = Phase(parameters=study.parameter_names, experiments=ident, name="joint refinement")
        if progress:
            progress("phase", {"message": f"{ph.name}: all parameters on {', '.join(ident)}"})
        span = study.contribution.refine_span
        params = []
        for p in study.parameters:
            lo = max(current[p.name] * (1 - span), p.min)
            hi = min(current[p.name] * (1 + span), p.max)
            mid = min(max(current[p.name], p.min), p.max)
            lv = sorted({lo, mid, hi})
            if len(lv) < 3:  # a value at zero or on a bound: spread from the bound instead
                # (by the span of a tenth of the largest first level when the value is 0)
                typical = 0.1 * max(abs(v) for v in p.levels)
                width = max(abs(current[p.name]), typical, 1e-9) * span
                lv = [mid, mid + width, mid + 2 * width] if mid == p.min else lv
                lv = [mid - 2 * width, mid - width, mid] if mid == p.max else lv
            params.append(Parameter(p.name, lv, p.min, p.max, p.unit))
        sub = _sub_study(
            study,
            study.parameter_names,
            ident,
            current,
            max_iterations=max_iterations or study.max_iterations,
            name=f"{study.name} - {ph.name}",
            canonical=study.canonical,
        )
        sub.parameters = params
        pdir = out_dir / f"phase_{len(phases) + 1:02d}" if out_dir is not None else None
        again = pdir is not None and any(pdir.glob("iteration_*/record.json"))
        res = identify(sub, pdir, resume=again, progress=progress, plots=plots, **(runner or {}))
        current.update(res.x)
        nfev += res.nfev
        phases = [*phases, ph]
        results.append((ph, res))

    cost, n_extra = _identification_cost(study, current)
    nfev += n_extra
    validation = _validate(study, current, out_dir, plots)
    comparison = None
    if study.contribution.compare_ungrouped:
        comparison = _compare_ungrouped(
            study, out_dir, current, cost, nfev, validation, progress, plots, runner or {}
        )

    records = [rec for _, r in results for rec in r.iterations]
    # the verdict on each parameter comes from the last phase that identified it (the
    # joint refinement, when it ran, sees every parameter on every experiment)
    last_phase = {n: (ph, r) for ph, r in results for n in ph.parameters}
    weak = {n: f"{ph.name}: {r.weak[n]}" for n, (ph, r) in last_phase.items() if n in r.weak}
    final = results[-1][1] if results else None
    contribution = {k: v for _, r in results for k, v in r.contribution.items()}
    success = all(r.success for _, r in results)
    message = f"{len(phases)} phases identified" + (
        "" if success else " (some hit the iteration limit)"
    )
    if validation:
        message += f"; validation cost {validation['_total_cost']:.6g}"
    result = IdentificationResult(
        x=dict(current),
        fun=cost,
        success=success,
        status=0 if success else 1,
        message=message,
        nfev=nfev,
        nit=len(records),
        iterations=records,
        weak=weak,
        contribution=contribution,
        fit={name: r.fit for (ph, r) in results for name in [ph.name]},
        best_source="phases",
        sensitivity=final.get("sensitivity", {}) if final is not None else {},
        identifiability=final.get("identifiability") if final is not None else None,
        study=study,
        out_dir=out_dir,
        phases=[
            {
                "name": ph.name,
                "parameters": ph.parameters,
                "experiments": ph.experiments,
                "x": r.x,
                "fun": r.fun,
                "nit": r.nit,
                "nfev": r.nfev,
                "message": r.message,
            }
            for ph, r in results
        ],
        input_contribution=analysis["input"],
        parameter_contribution=analysis["parameters"],
        groups=analysis["groups"],
        validation=validation,
        comparison=comparison,
    )
    if out_dir is not None:
        from tsid_fmu.report import write_phased_outputs

        write_phased_outputs(result, out_dir)
    if progress:
        progress("done", {"result": result})
    return result


def _compare_ungrouped(
    study: Study,
    out: Path | None,
    x_phased: dict[str, float],
    cost_phased: float,
    nfev_phased: int,
    validation: dict,
    progress: Any,
    plots: bool,
    runner: dict[str, Any],
) -> dict[str, Any]:
    """Identify all parameters in one array on all experiments; compare with the phases."""
    from tsid_fmu.engine import identify

    ident = [e.name for e in study.experiments if e.role == "identify"]
    # like for like: the same end stage on canonical factors as the joint refinement
    sub = _sub_study(
        study,
        study.parameter_names,
        ident,
        {},
        name=f"{study.name} - ungrouped",
        canonical=study.canonical,
    )
    if progress:
        progress("phase", {"message": "comparison: all parameters in one array (no grouping)"})
    udir = out / "ungrouped" if out is not None else None
    again = udir is not None and any(udir.glob("iteration_*/record.json"))
    res = identify(sub, udir, resume=again, progress=progress, plots=plots, **runner)
    cost, _ = _identification_cost(study, res.x)
    val = _validate(study, res.x, None, False)
    return {
        "phased": {
            "x": x_phased,
            "cost": cost_phased,
            "nfev": nfev_phased,
            "validation_cost": validation.get("_total_cost"),
        },
        "ungrouped": {
            "x": res.x,
            "cost": cost,
            "nfev": res.nfev,
            "nit": res.nit,
            "validation_cost": val.get("_total_cost"),
            "message": res.message,
        },
    }
