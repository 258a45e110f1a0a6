"""``report.md``: the whole study as text a person reads from top to bottom."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from tsid_fmu.report.figures import MIN_POINTS, points
from tsid_fmu.report.notebook import sampled_note
from tsid_fmu.report.provenance import fmu_label
from tsid_fmu.report.scored import experiment_notes
from tsid_fmu.report.style import (
    cost_name,
    counted,
    fit_text,
    fmt,
    fmt_levels,
    input_contribution,
)
from tsid_fmu.result import STATUS, IdentificationResult
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.story import interval_text, listed_combinations, weak_reason
from tsid_fmu.study.units import study_units
from tsid_fmu.uncertainty.assess import NOISE_SOURCES, mismatch_warning, mismatches

__all__ = ["escape", "markdown_report", "markdown_table"]


_TAG_OPEN = re.compile(r"<(?=[A-Za-z/!?])")
"""A ``<`` that opens an HTML tag, comment, declaration or autolink in Markdown."""
_REFERENCE = re.compile(r"&(?=[A-Za-z][A-Za-z0-9]*;|#[0-9]{1,7};|#[xX][0-9a-fA-F]{1,6};)")
"""An ``&`` that starts an entity or character reference in Markdown."""


def escape(text: Any) -> str:
    r"""Return ``text`` as it may be printed into the report: no control characters, no HTML.

    Names and messages come from study files, data files and FMUs; a terminal escape
    sequence (ESC ``[2J``), a newline or a bidirectional override in one of them is
    shown as its Python escape (``\x1b[2J``) instead of acting on whoever reads the
    report. Markdown viewers render raw HTML, so a study named ``<script>...`` would run
    in them: a ``<`` that would open a tag (``<s``, ``</``, ``<!``, ``<?``) becomes
    ``&lt;`` and an ``&`` that would start a reference (``&gt;``, ``&#62;``) ``&amp;``.
    The rest stays as written, so that the file reads the same as text and rendered:
    an FMU's ``Failed condition: T >= 200``, ``(< 0.015)``, ``R & D``.
    """
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))
    return _TAG_OPEN.sub("&lt;", _REFERENCE.sub("&amp;", text))


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return fmt(v)
    return escape(v).replace("|", "/").replace("\n", " ")


def markdown_table(frame: Any) -> str:
    """Return a DataFrame as a Markdown table (numbers to 5 significant figures)."""
    cols = [_cell(frame.index.name or "")] + [_cell(str(c)) for c in frame.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for idx, row in frame.iterrows():
        lines.append("| " + " | ".join([_cell(idx)] + [_cell(v) for v in row]) + " |")
    return "\n".join(lines)


def _parameters(result: IdentificationResult) -> Any:
    """Return the parameter table, with a standard error at resolution as its bound."""
    frame = result.parameters_frame()
    if "95% low" in frame:  # one cell, as every view shows it (tsid_fmu.story)
        shown = [
            interval_text(result.intervals.get(n), float(frame.loc[n, "value"]), fmt_levels)
            for n in frame.index
        ]
        at = list(frame.columns).index("95% low")
        frame = frame.drop(columns=["95% low", "95% high"])
        frame.insert(at, "95 % interval", shown)
    bounds = result.uncertainty.resolution if result.uncertainty else {}
    if bounds and "std error [%]" in frame:
        frame["std error [%]"] = [
            f"below the profile's resolution (< {fmt(bounds[n], 2)})" if n in bounds else v
            for n, v in frame["std error [%]"].items()
        ]
    return frame


def _stage_folder(stage: StageResult, index: int) -> str:
    if stage.kind == StageKind.TAGUCHI:
        return ""
    if stage.kind == StageKind.PHASE:
        return f"phase_{index:02d}/"
    return f"{stage.kind}/"


def _stages(result: IdentificationResult) -> list[str]:
    lines = [
        "## Stages",
        "",
        "Each stage's answer and its cost on the measured inputs of its experiments; "
        "the cost fall is relative to the stage before (what the stage contributed); "
        "simulations: run by the stage itself.",
        "",
        markdown_table(result.stages_frame()),
        "",
    ]
    if result.account:
        lines += ["## How the study ended", "", *[f"- {escape(a)}" for a in result.account], ""]
    phase = 0
    for st in result.stages:
        if not st.records:
            continue
        phase += st.kind == StageKind.PHASE
        folder = _stage_folder(st, phase)
        lines += [
            f"### {escape(st.name)}",
            "",
            "| iteration | array | factors | case | best cost so far | "
            "found at | next centred on | simulations in the iteration |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for rec in st.records:
            kind = "parameters" if rec.frame.axis_aligned else "rotated"
            lines.append(
                f"| [{rec.index}]({folder}iteration_{rec.index:02d}/) | {rec.array} | {kind} | "
                f"{rec.decision.case} | {fmt(rec.best_cost)} | {rec.best_source} | "
                f"{rec.centre_source} | {rec.nfev} |"
            )
        lines.append("")
    return lines


def _fit(result: IdentificationResult) -> list[str]:
    lines = [
        "## Fit at the identified parameters (measured inputs)",
        "",
        "fit % = 100 (1 - NRMSE), NRMSE = |simulated - measured| / |measured - its mean| "
        "(100 % a perfect fit, 0 % no better than the mean); RMSE and IAE in the output's "
        "unit (IAE times s).",
        "",
    ]
    units = study_units(result.study)
    for exp, per_output in result.fit.items():
        for output, m in per_output.items():
            if not isinstance(m, dict):
                lines.append(f"- {escape(exp)}: {escape(m)}")
                continue
            sigma = result.noise.get(exp, {}).get(output)
            whence = NOISE_SOURCES.get(result.noise_source.get(exp, {}).get(output, ""), "")
            said = f"noise, {whence}" if whence else "noise"
            beside = f" ({said}: {fmt(sigma, 4)})" if sigma is not None else ""
            if sigma:
                beside = f"{beside[:-1]}; RMSE {fmt(m['rmse'] / sigma, 2)} x it)"
            lines.append(
                f"- {escape(exp)} / {escape(output)}: fit {fmt(m['fit_percent'])} %, RMSE "
                f"{fmt(m['rmse'])}{_unit(units.get(output))}{beside}, NRMSE "
                f"{fmt(m['nrmse'])}, IAE {fmt(m['iae'])}"
            )
    notes = [line for note in experiment_notes(result) for line in ("", note)]
    return [*lines, *notes, ""]


def _unit(unit: str | None) -> str:
    """`` unit`` (with its space), or nothing where the output declares none."""
    return f" {escape(unit)}" if unit else ""


def _failed_runs(records: Sequence[IterationRecord]) -> list[str]:
    rows = [
        (escape(rec.stage), rec.index, run + 1, err)
        for rec in records
        for run, err in enumerate(rec.errors)
        if err
    ]
    if not rows:
        return []
    out = [
        f"## Failed runs ({len(rows)}, each scored worst; the study went on)",
        "",
        "| stage | iteration | run | reason |",
        "|---|---|---|---|",
    ]
    out += [f"| {s} | {i} | {r} | {_cell(e)} |" for s, i, r, e in rows]
    return [*out, ""]


def _uncertainty(result: IdentificationResult) -> list[str]:
    u = result.uncertainty
    if u is None:
        return []
    lines = [
        "## What the data determine",
        "",
        f"Intervals: {u.method}. Combinations of "
        "parameters, best determined first (standard error in search units: 1 = the "
        "width of the first levels' range):",
        "",
    ]
    for c in listed_combinations(u.combinations, result.intervals):
        terms = " ".join(f"{w:+.2f} {escape(n)}" for n, w in c["terms"].items())
        state = c["state"] if c["state"] != "not determined" else "**not determined**"
        lines.append(f"- {terms}: standard error {c['std_error']:.3g} ({escape(state)})")
    for g in u.scale_groups:
        ratios = ", ".join(f"{k} to +/-{v:.2g} %" for k, v in g["ratios"].items())
        outside = [n for n in u.values if n not in g["parameters"]]
        lines.append(
            f"- {', '.join(g['parameters'])}: the data fix their ratios ({ratios}) but their "
            f"common scale only to +/-{g['scale_percent']:.2g} % (standard error): only "
            f"what does not scale with them ({', '.join(outside) or 'nothing'}) sets it"
        )
    for name, interval in result.intervals.items():
        said = weak_reason(interval)
        if said:
            lines.append(f"- **{escape(name)}**: {said}")
    if result.sampled is not None:
        lines += ["", escape(sampled_note(result.sampled))]
    mismatch = [mismatch_warning(*m) for m in mismatches(result.fit, result.noise)]
    if mismatch:
        lines += ["", "**These intervals assume that the model explains the data; it does not:**"]
        lines += [f"- {w}" for w in mismatch]
    return [*lines, ""]


def _fidelity(result: IdentificationResult) -> list[str]:
    record = result.fidelity
    if not record:
        return []
    if record.get("checked") is False:  # [method] fidelity = false
        return ["## Solver fidelity", "", f"Not checked: {record.get('reason', '')}.", ""]
    names = {"cs": "Co-Simulation", "me": "Model Exchange"}
    lines = [
        "## Solver fidelity",
        "",
        f"The study's solver against a reference solution; a difference above "
        f"{record['threshold']:g} x an output's noise matters "
        "(see docs/how-to/troubleshooting.md).",
        "",
        f"- Interface: {record['requested']!r} requested, "
        f"**{names.get(record['interface'], record['interface'])}** used",
    ]
    if record.get("cs_tolerance") is not None and record["interface"] == "cs":
        lines.append(f"- The FMU's own solver at tolerance {record['cs_tolerance']:g}")
    for key in ("start", "answer"):
        if record.get(key):
            lines.append(f"- {record[key]['message']}")
    return [*lines, ""]


def _contribution(result: IdentificationResult) -> list[str]:
    lines = []
    for st in result.stages:
        percent = st.contribution.percent if st.contribution is not None else {}
        for exp, values in percent.items():
            if not lines:
                lines = [
                    "## Parameter contribution (MISO paper, eq. 7)",
                    "",
                    "% of error variation = (largest - smallest cost of the parameter's "
                    "one-at-a-time runs) / (mean cost of all its runs) x 100. Each "
                    "parameter is varied alone: the values are not shares of a whole and "
                    "may add up to more than 100 %.",
                    "",
                ]
            row = ", ".join(f"{k} {fmt(v, 4)} %" for k, v in values.items())
            lines.append(f"- {exp}: {row}")
    return ([*lines, ""] if lines else []) + _input_contribution(result)


def _input_contribution(result: IdentificationResult) -> list[str]:
    """Step i of the MISO paper: the experiments by the size of their output."""
    rows = next((r for st in result.stages if (r := input_contribution(st))), [])
    if not rows:
        return []
    lines = ["## Input contribution (MISO paper, step i: main contributor first)", ""]
    for e, acting, rms, span in rows:
        lines.append(
            f"- {escape(e)} (inputs {escape(acting)}): output RMS {fmt(rms)}, range {fmt(span)}"
        )
    return [*lines, ""]


def markdown_report(result: IdentificationResult) -> str:
    """Return the text of ``report.md``."""
    study = result.study
    name = escape(study.name) if study else "study"
    cost = cost_name(study)
    lines = [
        f"# Identification report: {name}",
        "",
        f"- FMU: `{escape(fmu_label(study))}`",
        f"- Result: **{escape(result.message)}** (status {result.status}: {STATUS[result.status]}; "
        f"{counted(result.nit, 'Taguchi iteration')}, {result.nfev} simulations)",
        f"- Cost ({cost}) on the measured inputs of the identification experiments: "
        f"{fmt(result.fun)}",
        "- The whole report with tables and plots: [report.html](report.html)",
        "",
    ]
    if result.warnings:
        lines += ["## Warnings", "", *[f"- {escape(w)}" for w in result.warnings], ""]
    lines += ["## Identified parameters", "", markdown_table(_parameters(result)), ""]
    found = result.structure
    if found:
        lines += [
            "## Structure",
            "",
            f"Chosen: **{escape(found['chosen'])}**: {escape(found['why'])}",
            "",
            markdown_table(result.structures_table()),
            "",
        ]
    if result.weak:
        lines += [
            "## Weakly determined parameters",
            "",
            *[f"- **{escape(k)}**: {escape(v)}" for k, v in result.weak.items()],
            "",
        ]
    lines += _uncertainty(result) + _fit(result) + _fidelity(result) + _stages(result)
    lines += _failed_runs(result.iterations)
    if result.validation:
        phased = any(st.kind in (StageKind.CONTRIBUTION, StageKind.PHASE) for st in result.stages)
        lines += [
            "## Superposition check: validation experiments with all inputs together"
            if phased
            else "## Validation experiments",
            "",
        ]
        units = study_units(result.study)
        for exp, v in result.validation.items():
            lines.append(
                f"- {escape(exp)}: "
                + (
                    f"simulation failed: {escape(v['error'])}"
                    if "error" in v
                    else (f"{fit_text(v['fit'], units)}; " if v.get("fit") else "")
                    + f"cost ({cost}) {fmt(v['cost'])}"
                )
            )
        lines.append("")
    comp = result.comparison
    if comp:
        ph, un = comp["phased"], comp["ungrouped"]
        lines += [
            "## Why grouping: the same study without it",
            "",
            "| | cost (identification experiments) | simulations |",
            "|---|---|---|",
            f"| grouped, in phases | {fmt(ph['cost'])} | {ph['nfev']} |",
            f"| all parameters in one array | {fmt(un['cost'])} | {un['nfev']} |",
            "",
        ]
    lines += _contribution(result)
    lines += ["![fit](fit.png)", ""]
    drawn = points(result)  # the figures render.py draws: none of a single point
    if result.iterations and drawn["convergence.png"] >= MIN_POINTS:
        lines += ["![convergence](convergence.png)", ""]
    if drawn["parameters.png"] >= MIN_POINTS:
        lines += ["![parameters per iteration](parameters.png)", ""]
    return "\n".join(lines)
