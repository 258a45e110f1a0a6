"""The "Residual diagnostics" section of report.html, written for a reader.

Each quantity of the uncertainty at the answer (:class:`~tsid_fmu.uncertainty.intervals.
Uncertainty`) gets a table with named columns and a sentence that says what it is:
the parameters' standard errors and intervals, the residuals of each output beside
the noise the cost uses (and where that came from), their whiteness, the correlations
and the combinations the data determine. Nothing is shown as a raw key or a dict.
"""

from __future__ import annotations

import math
from typing import Any

from tsid_fmu.report.html_tables import esc, table
from tsid_fmu.report.style import fmt, fmt_levels
from tsid_fmu.result import IdentificationResult
from tsid_fmu.story import interval_text, listed_combinations
from tsid_fmu.uncertainty.assess import NOISE_SOURCES
from tsid_fmu.uncertainty.intervals import Uncertainty

__all__ = ["diagnostics_section"]

RESIDUALS_NOTE = (
    "Residual RMS: of simulated − measured at the answer, in the output's unit. Noise: the "
    "one the cost uses (stated in the study, else estimated from the measured data). "
    "Lag-1 autocorrelation and the Ljung-Box p-value test whether the residuals are white "
    "(p < 0.05: coloured); the HAC covariance averages over the bandwidth's lags."
)


def _span(pair: Any, value: float) -> str:
    """Return the interval as every view shows it (:func:`tsid_fmu.story.interval_text`)."""
    if not isinstance(pair, list | tuple) or len(pair) != 2:
        return "not computed"
    return interval_text(pair, value, fmt_levels)


def _parameters(u: Uncertainty) -> str:
    rows = []
    for name, value in u.values.items():
        bound = u.resolution.get(name)
        se: Any = u.std_error.get(name, math.nan)
        rel: Any = u.relative.get(name, math.nan)
        if bound is not None:  # the profile's resolution, not an estimate
            se, rel = f"< {fmt(se, 2)}", f"< {fmt(bound, 2)} (the profile's resolution)"
        rows.append(
            [
                name,
                value,
                se,
                rel,
                u.cramer_rao.get(name, math.nan),
                _span(u.intervals.get(name), value),
                _span(u.profile.get(name), value) if name in u.profile else "not computed",
            ]
        )
    cols = ["parameter", "value", "std error", "std error [%]", "Cramér-Rao bound [%]"]
    return table([*cols, "95 % interval", "profile interval"], rows)


def _residuals(result: IdentificationResult, u: Uncertainty) -> str:
    rows = []
    for exp, rms in u.noise.items():
        outputs = list(result.noise.get(exp) or u.whiteness.get(exp) or {})
        for k, value in enumerate(rms):
            out = outputs[k] if k < len(outputs) else f"output {k + 1}"
            white = u.whiteness.get(exp, {}).get(out, {})
            source = result.noise_source.get(exp, {}).get(out, "")
            flag = white.get("white")
            rows.append(
                [
                    f"{exp} / {out}",
                    value,
                    result.noise.get(exp, {}).get(out, math.nan),
                    NOISE_SOURCES.get(source, source),
                    white.get("rho1", math.nan),
                    white.get("p_value", math.nan),
                    "" if flag is None else ("white" if flag else "coloured"),
                    white.get("bandwidth", ""),
                ]
            )
    cols = ["experiment / output", "residual RMS", "noise", "noise from"]
    cols += ["lag-1 autocorrelation", "Ljung-Box p", "residuals", "HAC bandwidth"]
    return table(cols, rows) + f'<p class="note">{esc(RESIDUALS_NOTE)}</p>'


def _combinations(u: Uncertainty) -> str:
    rows = []
    for k, c in enumerate(listed_combinations(u.combinations, u.intervals), start=1):
        terms = " ".join(f"{w:+.3g} {n}" for n, w in c["terms"].items())
        rows.append(
            [k, terms, c.get("std_error", math.nan), c.get("percent", math.nan), c["state"]]
        )
    cols = ["#", "combination (search coordinates)", "std error", "[%]", "determined"]
    note = (
        "Eigen-combinations of the Fisher matrix, best determined first (lg: log10 of "
        "the parameter; [%]: relative standard error of the product it stands for)."
    )
    return table(cols, rows) + f'<p class="note">{esc(note)}</p>'


def _groups(u: Uncertainty) -> str:
    rows = []
    for g in u.scale_groups:
        ratios = ", ".join(f"{r} {fmt(p, 3)} %" for r, p in (g.get("ratios") or {}).items())
        rows.append([", ".join(g.get("parameters", [])), ratios, g.get("scale_percent", math.nan)])
    cols = ["parameters", "ratios (std error)", "their common scale, std error [%]"]
    return table(cols, rows)


def _correlation(u: Uncertainty) -> str:
    names = list(u.correlation)
    rows = [[a, *[u.correlation[a].get(b, math.nan) for b in names]] for a in names]
    return table(["", *names], rows)


def diagnostics_section(result: IdentificationResult) -> str:
    """Return the HTML of the diagnostics: uncertainty, residuals, weakly determined."""
    parts = []
    u = result.uncertainty
    if u is not None:
        said = (
            f"Method: {u.method}; the condition number of the Fisher matrix is "
            f"{fmt(u.condition)}. HAC over white-noise standard errors (median over the "
            f"parameters): x{fmt(u.inflation, 3)}."
        )
        parts += ["<h3>Uncertainty at the answer</h3>", f"<p>{esc(said)}</p>", _parameters(u)]
        if u.noise:
            parts += ["<h3>Residuals at the answer</h3>", _residuals(result, u)]
        if u.correlation:
            parts += ["<h3>Correlation of the estimates</h3>", _correlation(u)]
        if u.combinations:
            parts += ["<h3>Combinations the data determine</h3>", _combinations(u)]
        if u.scale_groups:
            parts += ["<h3>Ratios the data fix better than the parameters</h3>", _groups(u)]
    if result.weak:
        rows = [[k, v] for k, v in result.weak.items()]
        parts.append("<h3>Weakly determined parameters</h3>" + table(["parameter", "why"], rows))
    return "\n".join(parts) or "<p>No diagnostics (the study was not assessed).</p>"
