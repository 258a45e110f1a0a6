"""``report.md``: the whole study as text a person reads from top to bottom."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from tsid_fmu.result import STATUS, IdentificationResult
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageResult

__all__ = ["escape", "markdown_report", "markdown_table"]


def escape(text: Any) -> str:
    r"""Return ``text`` as it may be printed into the report: no control characters.

    Names and messages come from study files, data files and FMUs; a terminal escape
    sequence (ESC ``[2J``), a newline or a bidirectional override in one of them is
    shown as its Python escape (``\x1b[2J``) instead of acting on whoever reads the
    report.
    """
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return "-" if math.isnan(v) else f"{v:.5g}"
    return escape(v).replace("|", "/")


def markdown_table(frame: Any) -> str:
    """Return a DataFrame as a Markdown table (numbers to 5 significant figures)."""
    cols = [_cell(frame.index.name or "")] + [_cell(str(c)) for c in frame.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for idx, row in frame.iterrows():
        lines.append("| " + " | ".join([_cell(idx)] + [_cell(v) for v in row]) + " |")
    return "\n".join(lines)


def _stage_folder(stage: StageResult, index: int) -> str:
    if stage.kind == "taguchi":
        return ""
    if stage.kind == "phase":
        return f"phase_{index:02d}/"
    return f"{stage.kind}/"


def _stages(result: IdentificationResult) -> list[str]:
    lines = [
        "## Stages",
        "",
        "Each stage's answer and its cost on the measured inputs of its experiments; "
        "the cost fall is relative to the stage before.",
        "",
        markdown_table(result.stages_frame()),
        "",
    ]
    phase = 0
    for st in result.stages:
        if not st.records:
            continue
        phase += st.kind == "phase"
        folder = _stage_folder(st, phase)
        lines += [
            f"### {escape(st.name)}",
            "",
            "| iteration | array | factors | case | best cost | "
            "found at | next centred on | simulations |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for rec in st.records:
            kind = "parameters" if rec.frame.axis_aligned else "rotated"
            lines.append(
                f"| [{rec.index}]({folder}iteration_{rec.index:02d}/) | {rec.array} | {kind} | "
                f"{rec.decision.case} | {rec.best_cost:.6g} | {rec.best_source} | "
                f"{rec.centre_source} | {rec.nfev} |"
            )
        lines.append("")
    return lines


def _fit(result: IdentificationResult) -> list[str]:
    lines = [
        "## Fit at the identified parameters (measured inputs)",
        "",
        "fit % = 100 (1 - NRMSE), NRMSE = |error| / |measured - its mean|.",
        "",
    ]
    for exp, per_output in result.fit.items():
        for output, m in per_output.items():
            if not isinstance(m, dict):
                lines.append(f"- {escape(exp)}: {escape(m)}")
                continue
            sigma = result.noise.get(exp, {}).get(output)
            beside = f" (noise in the data: {sigma:.3g})" if sigma is not None else ""
            if sigma:
                beside = f"{beside[:-1]}; RMSE {m['rmse'] / sigma:.2g} x it)"
            lines.append(
                f"- {escape(exp)} / {escape(output)}: fit {m['fit_percent']:.3f} %, RMSE "
                f"{m['rmse']:.5g}{beside}, IAE {m['iae']:.5g}"
            )
    return [*lines, ""]


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
    for c in u.combinations:
        terms = " ".join(f"{w:+.2f} {escape(n)}" for n, w in c["terms"].items())
        state = "determined" if c["determined"] else "**not determined**"
        lines.append(f"- {terms}: standard error {c['std_error']:.3g} ({state})")
    for g in u.scale_groups:
        ratios = ", ".join(f"{k} to +/-{v:.2g} %" for k, v in g["ratios"].items())
        outside = [n for n in u.values if n not in g["parameters"]]
        lines.append(
            f"- {', '.join(g['parameters'])}: the data fix their ratios ({ratios}) but their "
            f"common scale only to +/-{g['scale_percent']:.2g} % (standard error): only "
            f"what does not scale with them ({', '.join(outside) or 'nothing'}) sets it"
        )
    for name, (low, high) in result.intervals.items():
        if low is None or high is None:
            lines.append(f"- **{name}**: the data do not determine it: its 95 % interval is open")
    mismatch = [w for w in result.warnings if "model or solver mismatch" in w]
    if mismatch:
        lines += ["", "**These intervals assume that the model explains the data; it does not:**"]
        lines += [f"- {w}" for w in mismatch]
    return [*lines, ""]


def _fidelity(result: IdentificationResult) -> list[str]:
    record = result.extra.get("fidelity")
    if not record:
        return []
    names = {"cs": "Co-Simulation", "me": "Model Exchange"}
    lines = [
        "## Solver fidelity",
        "",
        f"The study's solver against a reference solution; a difference above "
        f"{record['threshold']:g} x an output's noise matters (see docs/troubleshooting.md).",
        "",
        f"- Interface: {record['requested']!r} requested, "
        f"**{names.get(record['interface'], record['interface'])}** used",
    ]
    for key in ("start", "answer"):
        if record.get(key):
            lines.append(f"- {record[key]['message']}")
    return [*lines, ""]


def markdown_report(result: IdentificationResult) -> str:
    """Return the text of ``report.md``."""
    study = result.study
    name = escape(study.name) if study else "study"
    cost = study.method.cost if study else "cost"
    lines = [
        f"# Identification report: {name}",
        "",
        f"- FMU: `{escape(study.fmu) if study else '-'}`",
        f"- Result: **{escape(result.message)}** (status {result.status}: {STATUS[result.status]}; "
        f"{result.nit} Taguchi iterations, {result.nfev} simulations)",
        f"- Cost ({cost}, measured inputs of the identification experiments): {result.fun:.6g}",
        "",
    ]
    if result.warnings:
        lines += ["## Warnings", "", *[f"- {escape(w)}" for w in result.warnings], ""]
    lines += ["## Identified parameters", "", markdown_table(result.parameters_frame()), ""]
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
        lines += ["## Validation experiments (all inputs together)", ""]
        for exp, v in result.validation.items():
            lines.append(
                f"- {escape(exp)}: "
                + (
                    f"simulation failed: {escape(v['error'])}"
                    if "error" in v
                    else f"{cost} cost {v['cost']:.6g}"
                )
            )
        lines.append("")
    comp = result.extra.get("comparison")
    if comp:
        ph, un = comp["phased"], comp["ungrouped"]
        lines += [
            "## Why grouping: the same study without it",
            "",
            "| | cost (identification experiments) | simulations |",
            "|---|---|---|",
            f"| grouped, in phases | {ph['cost']:.6g} | {ph['nfev']} |",
            f"| all parameters in one array | {un['cost']:.6g} | {un['nfev']} |",
            "",
        ]
    lines += ["![fit](fit.png)", "", "![convergence](convergence.png)", ""]
    return "\n".join(lines)
