"""One Taguchi iteration in ``report.html``.

Its levels, array, response tables, ANOVA, prediction and confirmation, re-leveling
decisions and main-effects plots.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from tsid_fmu.report.html_tables import esc, image, table
from tsid_fmu.report.prediction import prediction
from tsid_fmu.report.style import fmt, fmt_levels
from tsid_fmu.search.record import IterationRecord

__all__ = ["ANOVA_NOTE", "iteration_section"]

ANOVA_NOTE = (
    "ANOVA of the S/N ratios. DOF: degrees of freedom; SS: sum of squares; V = SS/DOF; "
    "F = V/V<sub>e</sub>; S′ = SS − DOF·V<sub>e</sub> (pure sum of squares); "
    "P % = 100 S′/SS<sub>T</sub> (percent contribution). Pooling rule: the factors "
    "with the smallest SS are pooled into the error (rows in italics, marked pooled) "
    "until the error has at least half of the total degrees of freedom."
)


def _levels(rec: IterationRecord, units: Mapping[str, str]) -> str:
    n = max(rec.n_levels)
    describe = rec.describe or {}
    rows = []
    for f in rec.frame.factors:
        if f.values is not None:
            what, unit, labels = "parameter", units.get(f.name, ""), fmt_levels(f.values)
        else:
            what = f"rotated: {describe.get(f.name, 'a combination of the parameters')}"
            unit, labels = "offset", fmt_levels(list(f.offsets))
        rows.append([f.name, what, unit, *labels, *[""] * (n - len(labels))])
    columns = ["factor", "what it moves", "unit", *[f"level {j + 1}" for j in range(n)]]
    return table(columns, rows)


def _runs(rec: IterationRecord, cost: str) -> str:
    frame = rec.runs_frame()
    drop = ["stage", "iteration"]
    frame = frame.drop(columns=[c for c in drop if c in frame.columns])
    rename = {"cost": f"cost ({cost})", "S/N [dB]": "S/N [dB]"}
    frame = frame.rename(columns=rename)
    rows = [list(r) for r in frame.itertuples(index=False)]
    classes = ["failed" if e else "" for e in rec.errors]
    return table([str(c) for c in frame.columns], rows, row_classes=classes)


def _response(table_: Any, title: str, unit: str) -> str:
    n = max(len(v) for v in table_.means.values())
    rows = [
        [
            name,
            *list(table_.means[name]),
            *[""] * (n - len(table_.means[name])),
            table_.delta[name],
            table_.rank[name],
        ]
        for name in table_.factor_names
    ]
    columns = ["factor", *[f"level {j + 1}" for j in range(n)], "Delta", "Rank"]
    head = f"<h4>{esc(title)}</h4>"
    note = (
        f'<p class="note">Mean {esc(unit)} of the runs at each level; Delta = largest − '
        f"smallest level mean; Rank 1 = largest Delta. Grand mean {fmt(table_.grand_mean)}."
        "</p>"
    )
    return head + table(columns, rows) + note


def _anova(rec: IterationRecord) -> str:
    an = rec.anova
    rows, classes = [], []
    for n in an.factor_names:
        pooled = n in an.pooled
        pure = an.ss[n] - an.dof[n] * an.error_ms if not pooled else math.nan
        rows.append(
            [
                f"{n} (pooled)" if pooled else n,
                an.dof[n],
                an.ss[n],
                an.ms[n],
                an.f[n],
                max(pure, 0.0) if not pooled else math.nan,
                an.pure_contribution[n],
            ]
        )
        classes.append("pooled" if pooled else "")
    pure_e = an.ss_total * an.error_pure_contribution / 100
    rows.append(
        [
            "error (pooled)" if an.pooled else "error",
            an.error_dof,
            an.error_ss,
            an.error_ms,
            math.nan,
            pure_e,
            an.error_pure_contribution,
        ]
    )
    rows.append(["total", an.dof_total, an.ss_total, math.nan, math.nan, an.ss_total, 100.0])
    classes += ["", "total"]
    columns = ["source", "DOF", "SS", "V", "F", "S′", "P %"]
    return (
        "<h4>ANOVA of S/N</h4>"
        + table(columns, rows, row_classes=classes)
        + (f'<p class="note">{ANOVA_NOTE}</p>')
    )


def _prediction(rec: IterationRecord, cost: str) -> str:
    p = prediction(rec)
    ci = (
        "undetermined (no error degrees of freedom)"
        if not math.isfinite(p["ci"])
        else (f"± {fmt(p['ci'], 4)} dB (mean), ± {fmt(p['ci_confirmation'], 4)} dB (one run)")
    )
    where = (
        "at the chosen levels"
        if p["at_chosen_levels"]
        else "at the main-effects optimum between the levels"
    )
    verdict = {True: "inside the interval", False: "outside the interval", None: "-"}[p["within"]]
    rows = [
        ["predicted S/N at the chosen levels [dB]", p["predicted"]],
        ["95 % confidence interval", ci],
        [f"confirmation run ({where}): cost ({cost})", p["confirmation_cost"]],
        ["confirmation run: S/N = −20 lg cost [dB]", p["confirmation_sn"]],
        ["confirmation against the prediction", verdict],
    ]
    used = ", ".join(p["factors"]) or "-"
    return (
        "<h4>Prediction and confirmation</h4>"
        + table(["", "value"], rows)
        + f'<p class="note">Additive model over the factors not pooled ({esc(used)}); '
        "the confirmation run is one simulation on the measured inputs.</p>"
    )


def _decisions(rec: IterationRecord) -> str:
    rows = [[d.name, d.case, d.reason] for d in rec.decision.parameters]
    return (
        "<h4>Re-leveling decisions</h4>"
        + table(["factor", "case", "reason"], rows)
        + f'<p class="note">{esc(rec.decision.message.rstrip("."))}. Next levels centred on '
        f"{esc(rec.centre_source)}.</p>"
    )


def iteration_section(
    rec: IterationRecord,
    folder: str,
    images: Mapping[str, bytes],
    units: Mapping[str, str],
    cost: str,
    open_: bool = False,
) -> str:
    """Return the ``<details>`` block of one iteration."""
    failed = sum(e is not None for e in rec.errors)
    summary = (
        f"{esc(rec.stage)}, iteration {rec.index} — {esc(rec.array)}, "
        f"{'parameters' if rec.frame.axis_aligned else 'rotated factors'}, best {esc(cost)} "
        f"{fmt(rec.best_cost)}, case {rec.decision.case}, {rec.nfev} simulations"
        + (f", {failed} failed runs" if failed else "")
    )
    parts = [
        f"<details{' open' if open_ else ''}><summary>{summary}</summary>",
        f'<p class="note">Folder <code>{esc(folder)}/</code>. Best set so far found in '
        f"{esc(rec.best_source)}.</p>",
        "<h4>Factors and levels</h4>",
        _levels(rec, units),
        "<h4>Array, costs and S/N</h4>",
        _runs(rec, cost),
        _response(rec.response, "Response table for S/N ratios [dB]", "S/N [dB]"),
        _response(rec.response_means, f"Response table for means ({cost})", f"cost ({cost})"),
        _anova(rec),
        _prediction(rec, cost),
        _decisions(rec),
    ]
    key = f"{folder}/main_effects.svg"
    if key in images:
        parts += ["<h4>Main effects</h4>", image(images[key], f"main effects, {folder}")]
    parts.append("</details>")
    return "\n".join(parts)
