"""``report.html``: the whole study in one self-contained page (no script, no network).

From top to bottom: the headline and warnings; the identified parameters with their
intervals; the stages and what each contributed; the fit and residual plots per
experiment and output; the residual diagnostics; the validation experiments; the MISO
contribution analyses; the failed runs; then every Taguchi iteration with its levels,
array, response tables, ANOVA, prediction and confirmation, re-leveling decisions and
main-effects plots. Images are PNG at 2x, embedded as ``data:`` URIs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

from tsid_fmu.report.html_diagnostics import diagnostics_section
from tsid_fmu.report.html_iteration import iteration_section
from tsid_fmu.report.html_tables import CSS, esc, image, table, table_from_frame
from tsid_fmu.report.notebook import parameter_columns, parameter_rows, sampled_note
from tsid_fmu.report.provenance import fmu_label
from tsid_fmu.report.render import Figures, iteration_folders
from tsid_fmu.report.scored import experiment_notes
from tsid_fmu.report.style import cost_name, counted, fmt, input_contribution
from tsid_fmu.result import PAUSED, STATUS, IdentificationResult
from tsid_fmu.search.stage import StageKind
from tsid_fmu.study.units import study_units
from tsid_fmu.trail.files import atomic_write
from tsid_fmu.uncertainty.assess import NOISE_SOURCES

__all__ = ["FIT_NOTE", "STAGES_NOTE", "html_report", "verdict_tone", "write_html"]

FIT_NOTE = (
    "fit % = 100 (1 − NRMSE) with NRMSE = ‖simulated − measured‖ / ‖measured − its mean‖ "
    "(100 % is a perfect fit, 0 % no better than the mean). RMSE and IAE in the output's "
    "unit (IAE: integral of |error| over time, unit × s). Noise: the one the cost weights "
    "by, the sensor noise the study states (noise = {...}), else the estimate from the "
    "measured data (tsid_fmu.evaluate.cost.noise_level); the next column says which."
)
STRUCTURES_NOTE = (
    "Each candidate structure refined to its own optimum. k: the Real parameters that "
    "change the outputs in it. AIC = n ln(chi2/n) + 2(k+1), BIC = n ln(chi2/n) + (k+1) ln n, "
    "with chi2 the sum of squares of the noise-weighted residuals (as the cost weights "
    "them) over n residuals, from a Gaussian likelihood with one unknown common noise "
    "scale. LRT p: likelihood-ratio test n ln(chi2_simple/chi2_rich) against chi-square "
    "with the difference of k as degrees of freedom, for nested structures (the richer "
    "reproduces the simpler's fit). A richer structure wins only where the data support "
    "it: the lowest BIC, or for nested structures LRT p < 0.05."
)

STAGES_NOTE = (
    "Cost: the study's cost on the measured inputs of the stage's experiments. "
    "Cost fall: the share by which the stage lowered the cost of the stage before it "
    "(what the stage contributed). Simulations: run by the stage itself."
)
CONTRIBUTION_NOTE = (
    "Parameter contribution, the MISO paper's eq. (7): % of error variation = (largest − "
    "smallest cost of the parameter's one-at-a-time runs) / (mean cost of all runs) × 100. "
    "Each parameter is varied alone, so the percentages are not shares of a whole and may "
    "add up to more than 100 %."
)


def _section(title: str, body: str, anchor: str) -> str:
    return f'<h2 id="{esc(anchor)}">{esc(title)}</h2>\n{body}'


def verdict_tone(result: IdentificationResult) -> str:
    """Return the colour of the headline: that of the worst finding of the report.

    ``"good"`` (green) only for a converged study with no warning and no weakly
    determined parameter; ``"caution"`` (amber) for a converged study with either, or
    one stopped at a limit (exit status 1) without warnings; ``"bad"`` (red) for exit
    status 1 with warnings; ``"paused"`` (blue) for a study paused for review.
    """
    if result.status == PAUSED:
        return "paused"
    findings = bool(result.warnings) or bool(result.weak)
    if result.status == 0:
        return "caution" if findings else "good"
    return "bad" if result.warnings else "caution"


def _headline(result: IdentificationResult, cost: str) -> str:
    exit_status = result.status
    tone = verdict_tone(result)
    said = [f"{len(result.warnings)} warning(s)"] if result.warnings else []
    said += [f"{len(result.weak)} weakly determined parameter(s)"] if result.weak else []
    findings = f"; {', '.join(said)}: see below" if said else ""
    lines = [
        f'<p class="headline status-{result.status} verdict-{tone}">'
        f"<b>{esc(STATUS[result.status])}</b> "
        f"(exit status {exit_status} of <code>tsid identify</code>{esc(findings)})</p>",
        f'<p class="note">{esc(result.message)}</p>',
        "<ul>",
        f"<li>FMU: <code>{esc(fmu_label(result.study))}</code></li>",
        f"<li>Cost ({esc(cost)}) on the measured inputs of the identification experiments: "
        f"<b>{fmt(result.fun)}</b></li>",
        f"<li>{counted(result.nit, 'Taguchi iteration')}; {result.nfev} simulations by the stages "
        "(the fit, interval and plot simulations not counted)</li>",
        "</ul>",
    ]
    lines += [f'<div class="warn">{esc(w)}</div>' for w in result.warnings]
    return "\n".join(lines)


def _parameters(result: IdentificationResult, images: Mapping[str, bytes]) -> str:
    body = table(parameter_columns(result), parameter_rows(result))
    note = (
        '<p class="note">95 % interval and standard error: '
        f"{esc(result.uncertainty.method if result.uncertainty else 'not computed')}.</p>"
    )
    if result.sampled is not None:
        note += f'<p class="note">{esc(sampled_note(result.sampled))}</p>'
    if "parameters.png" in images:
        note += image(images["parameters.png"], "parameter values per iteration")
        note += (
            '<p class="note">Best value of each parameter after each iteration (over all '
            "stages, in order); grey bars: the level window of iterations whose factors are "
            "the parameters; dotted: the identified value.</p>"
        )
    return body + note


def _fit(result: IdentificationResult, units: Mapping[str, str], images: Mapping) -> str:
    rows = []
    for exp, outputs in result.fit.items():
        for name, m in outputs.items():
            if not isinstance(m, dict):
                rows.append([f"{exp} / {name}", str(m), "", "", "", "", "", ""])
                continue
            sigma = result.noise.get(exp, {}).get(name, math.nan)
            whence = result.noise_source.get(exp, {}).get(name, "")
            rows.append(
                [
                    f"{exp} / {name}",
                    units.get(name, ""),
                    m["fit_percent"],
                    m["rmse"],
                    sigma,
                    NOISE_SOURCES.get(whence, whence),
                    m["rmse"] / sigma if sigma else math.nan,
                    m["iae"],
                ]
            )
    cols = ["experiment / output", "unit", "fit %", "RMSE", "noise", "noise from"]
    cols += ["RMSE / noise", "IAE"]
    body = table(cols, rows) + f'<p class="note">{esc(FIT_NOTE)}</p>' + _windows(result)
    if "fit.png" in images:
        body += image(images["fit.png"], "identified model against the measured data")
    return body


def _windows(result: IdentificationResult) -> str:
    return "".join(f'<p class="note">{esc(note)}</p>' for note in experiment_notes(result))


def _validation(result: IdentificationResult, cost: str) -> str:
    rows = []
    units = study_units(result.study)
    for exp, v in result.validation.items():
        if "error" in v:
            rows.append([exp, f"simulation failed: {v['error']}", "", "", ""])
            continue
        metrics = [(o, m) for o, m in v["fit"].items() if isinstance(m, dict)]
        rmse = "; ".join(
            f"{o} {fmt(m['rmse'], 4)}" + (f" {units[o]}" if units.get(o) else "")
            for o, m in metrics
        )
        nrmse = "; ".join(f"{o} {fmt(m['nrmse'], 4)}" for o, m in metrics)
        fits = "; ".join(f"{o} {fmt(m['fit_percent'], 4)} %" for o, m in metrics)
        rows.append([exp, v["cost"], rmse, nrmse, fits])
    return table(["experiment", f"cost ({cost})", "RMSE", "NRMSE", "fit %"], rows) + (
        '<p class="note">Simulated at the identified parameters and never fitted: no stage '
        "uses them (with all inputs together, the MISO paper's superposition check). RMSE "
        "in the output's unit; NRMSE = RMSE / the measured output's standard deviation; "
        "fit % = 100 (1 - NRMSE).</p>"
    )


def _contribution(result: IdentificationResult) -> str:
    parts = []
    for st in result.stages:
        if st.kind != StageKind.CONTRIBUTION:
            continue
        percent = st.contribution.percent if st.contribution is not None else {}
        if percent:
            names = list(dict.fromkeys(n for v in percent.values() for n in v))
            rows = [[n, *[percent[e].get(n, math.nan) for e in percent]] for n in names]
            parts.append(
                "<h3>Parameter contribution: % of error variation, eq. (7)</h3>"
                + table(["parameter", *[f"{e} [%]" for e in percent]], rows)
            )
        rows = input_contribution(st)
        if rows:
            parts.append(
                "<h3>Input contribution (main contributor first)</h3>"
                + table(["experiment", "inputs acting", "output RMS", "output range"], rows)
            )
        parts.append(f'<p class="note">{esc(CONTRIBUTION_NOTE)} {esc(st.message)}</p>')
    return "\n".join(parts)


def _structure(result: IdentificationResult) -> str:
    """Return the structures side by side, the choice and why, the discrete factors' responses."""
    found = result.structure or {}
    frame = result.structures_table()
    parts = [
        f"<p><b>Chosen: {esc(found.get('chosen', ''))}</b>: {esc(found.get('why', ''))}</p>",
        table_from_frame(frame) if len(frame) else "",
        f'<p class="note">{esc(STRUCTURES_NOTE)}</p>',
    ]
    rows = []
    for rec in result.iterations:
        for name, t in (rec.discrete or {}).items():
            for level, label in enumerate(t["labels"]):
                rows.append([rec.index, name, label, t["sn"][level], t["cost"][level],
                             t["f"], t["p"], "yes" if t["significant"] else "no",
                             "best" if level == t["best"] else ""])  # fmt: skip
    if rows:
        head = ["iteration", "factor", "level", "mean S/N [dB]", "mean cost", "F", "p"]
        parts.append(
            "<h3>Discrete factors: response per level (structure stage)</h3>"
            + table([*head, "significant", ""], rows)
        )
    return "\n".join(parts)


def _failed(result: IdentificationResult) -> str:
    rows = [
        [rec.stage, rec.index, run + 1, err]
        for rec in result.iterations
        for run, err in enumerate(rec.errors)
        if err
    ]
    if not rows:
        return "<p>No run failed.</p>"
    return table(["stage", "iteration", "run", "reason"], rows) + (
        '<p class="note">Each failed run is scored worst; the study went on.</p>'
    )


def _iterations(result: IdentificationResult, images: Mapping, units: Mapping, cost: str) -> str:
    parts, last = [], {}
    items = iteration_folders(result.stages)
    for folder, rec in items:
        last[rec.stage] = folder
    for folder, rec in items:
        parts.append(iteration_section(rec, folder, images, units, cost, last[rec.stage] == folder))
    return "\n".join(parts) or "<p>No Taguchi iteration.</p>"


def _account(result: IdentificationResult) -> str:
    """Each stage's reasons, said once, then the stationarity test (``result.account``)."""
    return "<ul>" + "".join(f"<li>{esc(line)}</li>" for line in result.account) + "</ul>"


def html_report(result: IdentificationResult, figures: Figures | None = None) -> str:
    """Return the text of ``report.html``."""
    study = result.study
    images = figures.images if figures else {}
    units = study_units(study)
    cost = cost_name(study)
    stages = result.stages_frame()
    if len(stages):
        stages = stages.rename(columns={"cost": f"cost ({cost})"})
    body = [
        f"<h1>Identification report: {esc(study.name if study else 'study')}</h1>",
        _headline(result, cost),
        _section("Identified parameters", _parameters(result, images), "parameters"),
        *([_section("Structure", _structure(result), "structure")] if result.structure else []),
        _section(
            "Stages",
            (table_from_frame(stages) if len(stages) else "")
            + f'<p class="note">{esc(STAGES_NOTE)}</p>'
            + (
                image(images["convergence.png"], "convergence")
                if "convergence.png" in images
                else ""
            ),
            "stages",
        ),
        *([_section("How the study ended", _account(result), "account")] if result.account else []),
        _section("Fit and residuals", _fit(result, units, images), "fit"),
        _section("Residual diagnostics", diagnostics_section(result), "diagnostics"),
    ]
    if result.validation:
        body.append(_section("Validation experiments", _validation(result, cost), "validation"))
    contribution = _contribution(result)
    if contribution:
        body.append(_section("Contribution analyses", contribution, "contribution"))
    body.append(_section("Failed runs", _failed(result), "failed"))
    body.append(_section("Iterations", _iterations(result, images, units, cost), "iterations"))
    title = esc(f"tsid report: {study.name if study else 'study'}")
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{title}</title><style>{CSS}</style></head>\n<body>\n"
        + "\n".join(body)
        + "\n</body></html>\n"
    )


def write_html(result: IdentificationResult, out: Path, figures: Figures | None = None) -> Path:
    """Write ``report.html`` into ``out``; return its path."""
    path = Path(out) / "report.html"
    atomic_write(path, html_report(result, figures))
    return path
