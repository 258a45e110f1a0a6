"""Notebook display of a result and its ``plot_*`` figures.

:class:`~tsid_fmu.result.IdentificationResult` delegates here (``_repr_html_``,
``plot_fit``, ...): this module registers its functions with
:func:`~tsid_fmu.result.register_views` when imported, so that the report reads the
result and the result module never imports the reports (they sit above it).
"""

from __future__ import annotations

import math
from typing import Any

from tsid_fmu.errors import StudyError
from tsid_fmu.report.html_tables import esc, table
from tsid_fmu.report.style import fmt, fmt_levels
from tsid_fmu.result import STATUS, register_views
from tsid_fmu.story import interval_text, near_zero
from tsid_fmu.study.units import study_units

__all__ = [
    "parameter_columns",
    "parameter_rows",
    "plot_convergence",
    "plot_fit",
    "plot_main_effects",
    "plot_parameters",
    "result_html",
    "sampled_note",
]

PARAMETER_COLUMNS = [
    "parameter",
    "value",
    "unit",
    "95 % interval",
    "std error [%]",
    "first levels",
    "weakly determined",
]


def _interval(low: float | None, value: float, high: float | None) -> str:
    """Return the interval as every view shows it (:func:`tsid_fmu.story.interval_text`)."""
    return interval_text([low, high], value, fmt_levels)


def _std_error(u: Any, name: str, unit: str = "") -> float | str:
    """Return the relative standard error, or the bound where it is below resolution.

    A value near zero for its error (:func:`tsid_fmu.story.near_zero`) gets its error in
    its own units: ``+/-0.0042 m (absolute)``.
    """
    if u is None:
        return math.nan
    rel = float(u.relative.get(name, math.nan))
    absolute = float(getattr(u, "std_error", {}).get(name, math.nan))
    bound = getattr(u, "resolution", {}).get(name)
    if near_zero(rel) and math.isfinite(absolute):
        below = "< " if bound is not None else "+/-"
        return f"{below}{fmt(absolute, 2)}{' ' + unit if unit else ''} (absolute)"
    if bound is not None:
        return f"below the profile's resolution (< {fmt(bound, 2)})"
    return rel


def _sampled_label(result: Any) -> str:
    return f"{result.sampled.kind.replace('_', ' ')} 95 % interval"


def sampled_note(sampled: Any) -> str:
    """Return what the sampled intervals are and what they cost, in one paragraph."""
    kind = sampled.kind.replace("_", " ")
    noise = "; ".join(
        f"{exp}: block length {how['block_length']}"
        if "block_length" in how
        else f"{exp}: AR order " + ", ".join(f"{o} {p}" for o, p in how["ar_order"].items())
        for exp, how in sampled.noise.items()
    )
    reasons = sorted(set(getattr(sampled, "withheld", {}).values()))
    withheld = (
        f" Withheld for {', '.join(sampled.withheld)}: {'; '.join(reasons)}." if reasons else ""
    )
    return (
        f"{kind.capitalize()} {100 * sampled.level:g} % intervals, beside the primary ones "
        f"(a check that does not linearise the model): {sampled.method}. {sampled.replicates} "
        f"replicates ({sampled.failed} failed, {sampled.unfinished} stopped at the step "
        f"limit), {sampled.nfev} simulations; {noise}.{withheld}"
    )


MARKS = {"mismatch": " (does not hold: model mismatch)", "coloured": " (may not hold)"}
"""What an interval cell says after its numbers when the verdict on the fit is against it
(:mod:`tsid_fmu.uncertainty.discrepancy`)."""


def interval_mark(u: Any) -> str:
    """Return the mark of every interval of an analysis ``u`` (empty when they hold)."""
    verdict = getattr(getattr(u, "discrepancy", None), "verdict", "consistent")
    return MARKS.get(verdict, "")


def parameter_columns(result: Any) -> list[str]:
    """Columns of the parameter table: :data:`PARAMETER_COLUMNS`, and a sampled interval's."""
    if getattr(result, "sampled", None) is None:
        return list(PARAMETER_COLUMNS)
    return [*PARAMETER_COLUMNS[:4], _sampled_label(result), *PARAMETER_COLUMNS[4:]]


def parameter_rows(result: Any) -> list[list[Any]]:
    """Rows of the parameter table: value, unit, 95 % interval, standard error, flags.

    With sampled intervals (``result.sampled``), theirs follows the primary interval
    (:func:`parameter_columns`).
    """
    rows = []
    params = result.study.identified_parameters() if result.study else []
    # a parameter with no effect in the chosen structure is not in the answer: no row
    names = [p.name for p in params if p.name in result.params] or result.names
    structure = result.structure or {}
    factors = structure.get("factors", [])
    names = [n for n in names if n not in {f["name"] for f in factors}]  # rows of their own
    units = study_units(result.study)  # the study's, else the FMU's declared ones
    first = {p.name: f"{fmt(min(p.levels))} .. {fmt(max(p.levels))}" for p in params}
    mark = interval_mark(result.uncertainty)
    for name in names:
        value = result.params.get(name, math.nan)
        se = _std_error(result.uncertainty, name, units.get(name, ""))
        # no interval at all (a paused study): "not computed", never "not determined"
        shown = interval_text(result.intervals.get(name), value, fmt_levels)
        rows.append(
            [
                name,
                value,
                units.get(name, ""),
                shown + (mark if shown not in ("not determined", "not computed") else ""),
                se,
                first.get(name, ""),
                result.weak.get(name, ""),
            ]
        )
    for f in factors:  # discrete factors: the chosen choice
        chosen = structure.get("choices", {}).get(f["name"], "")
        rows.append(
            [f["name"], chosen, "", "chosen structure", math.nan, " | ".join(f["labels"]), ""]
        )
    sampled = getattr(result, "sampled", None)
    if sampled is not None:
        for row in rows:
            low, high = sampled.intervals.get(row[0]) or [None, None]
            value = row[1] if isinstance(row[1], float | int) else math.nan
            shown = _interval(low, value, high) if row[0] in sampled.intervals else ""
            row.insert(4, "withheld" if row[0] in sampled.withheld else shown)
    return rows


def result_html(result: Any) -> str:
    """Return the notebook view of a result: headline, parameters, stages."""
    status = STATUS.get(result.status, str(result.status))
    parts = [
        f"<div><p><b>{esc(status)}</b>: {esc(result.message)}</p>",
        f"<p>cost {esc(fmt(result.fun))} on the measured inputs; {result.nit} Taguchi "
        f"iterations; {result.nfev} simulations</p>",
        table(parameter_columns(result), parameter_rows(result)),
    ]
    stages = result.stages_frame()
    if len(stages):
        rows = [
            [name, row["kind"], row["cost"], int(row["simulations"]), row["cost fall [%]"]]
            for name, row in stages.iterrows()
        ]
        parts.append(table(["stage", "kind", "cost", "simulations", "cost fall [%]"], rows))
    parts += [f"<p>warning: {esc(w)}</p>" for w in result.warnings]
    if result.out_dir is not None:
        parts.append(f"<p>report: <code>{esc(result.out_dir)}/report.html</code></p>")
    return "\n".join([*parts, "</div>"])


def _study(result: Any) -> Any:
    if result.study is None:
        raise StudyError("this result has no study: the plot needs its FMU and data")
    return result.study


def plot_fit(result: Any) -> Any:
    """Simulate the identified parameters once; return the fit and residual figure."""
    from tsid_fmu.evaluate.serial import SerialEvaluator
    from tsid_fmu.report.fitfig import FitFigure
    from tsid_fmu.report.style import cost_name
    from tsid_fmu.study.prepare import prepare
    from tsid_fmu.study.units import study_units

    study = _study(result)
    exps = study.identify_names()
    spec = prepare(study, exps, study.parameter_names)
    with SerialEvaluator(spec) as ev:
        sims = ev.simulate([dict(result.params)], count=False)[0]
    title = f"Identified model against the measured data ({cost_name(study)})"
    return FitFigure(spec.experiments, study_units(study)).draw(sims, title)


def plot_convergence(result: Any) -> Any:
    """Return the best cost per iteration, one axis per set of experiments."""
    from tsid_fmu.report.figures import convergence_figure
    from tsid_fmu.report.style import cost_name

    return convergence_figure(result.stages, cost_name(result.study))


def plot_main_effects(result: Any, iteration: Any = -1) -> Any:
    """Return the S/N and mean-cost main effects of one iteration.

    ``iteration`` is an :class:`~tsid_fmu.search.record.IterationRecord`, or its position
    in ``result.iterations`` (1-based; negative counts from the end).
    """
    from tsid_fmu.report.figures import MainEffects
    from tsid_fmu.report.style import cost_name
    from tsid_fmu.study.units import study_units

    records = result.iterations
    if isinstance(iteration, int):
        if not records or iteration == 0 or abs(iteration) > len(records):
            raise StudyError(
                f"iteration {iteration}: the result has {len(records)} iterations "
                "(1-based, or negative from the end)"
            )
        rec = records[iteration - 1 if iteration > 0 else iteration]
    else:
        rec = iteration
    units = study_units(result.study)
    return MainEffects(cost_name(result.study)).draw(rec, rec.describe, units)


def plot_parameters(result: Any) -> Any:
    """Return each parameter's best value per iteration with its level window."""
    from tsid_fmu.report.figures import trajectory_figure
    from tsid_fmu.study.units import study_units

    return trajectory_figure(
        result.iterations, result.names, study_units(result.study), result.params
    )


register_views(
    result_html=result_html,
    plot_fit=plot_fit,
    plot_convergence=plot_convergence,
    plot_main_effects=plot_main_effects,
    plot_parameters=plot_parameters,
)
