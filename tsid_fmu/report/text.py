"""The text reports of a result: what ``tsid identify`` prints, and lmfit's ``fit_report``.

:func:`text_report` is :meth:`IdentificationResult.text_report`, the console's table and
one-line verdict (with ``verbose``, the account of how the study got there and the fit
statistics). :func:`fit_report` is :meth:`IdentificationResult.fit_report`, in the
sections of lmfit's ``printfuncs.fit_report``: ``[[Fit Statistics]]``,
``[[Variables]]`` and ``[[Correlations]]``.
"""

from __future__ import annotations

import math
from typing import Any

from tsid_fmu.report.notebook import parameter_columns, parameter_rows, sampled_note
from tsid_fmu.report.style import cost_name, fit_text, fmt, fmt_levels
from tsid_fmu.result import register_views
from tsid_fmu.search.stage import StageKind
from tsid_fmu.story import determination, interval_text, near_zero

__all__ = ["MIN_CORREL", "fit_report", "fit_statistics", "text_report"]

MIN_CORREL = 0.1
"""Smallest absolute correlation :func:`fit_report` lists (lmfit's default)."""


def text_report(result: Any, verbose: bool = False) -> str:
    """Return the answer as ``tsid identify`` prints it, rounded to 5 significant figures.

    Parameters
    ----------
    result : IdentificationResult
        The result to report.
    verbose : bool, optional
        Also say how the study got there (:attr:`IdentificationResult.account`, each
        clause once) and the fit statistics (``tsid identify --verbose``).

    Returns
    -------
    str
        The parameter table (value, unit, 95 % interval, standard error, flags), the
        stages, the structure chosen, the one-line verdict with the exit status, the
        cost, the fit of each identification experiment (RMSE in the outputs' units,
        NRMSE, fit %), the warnings, the weakly determined parameters and the
        validation experiments (the same figures beside their cost), one finding a
        line.
    """
    rows = [[fmt(v) if not isinstance(v, str) else v for v in r] for r in parameter_rows(result)]
    shown = {r[0] for r in rows if r[-1]}  # rows whose "weakly determined" cell is filled
    columns = parameter_columns(result)
    widths = [max(len(str(x)) for x in col) for col in zip(columns, *rows, strict=True)]
    lines = [
        "  ".join(str(x).ljust(w) for x, w in zip(r, widths, strict=True)).rstrip()
        for r in [columns, *rows]
    ]
    if result.sampled is not None:
        lines.append(sampled_note(result.sampled))
    lines.append("")
    lines += [
        f"stage {s.name} ({s.kind}): cost {fmt(s.cost)}, {s.nfev} simulations"
        for s in result.stages
    ]
    structure = result.structure
    if structure:
        lines.append(f"structure: {structure['chosen']}: {structure['why']}")
    lines.append("")
    lines.append(f"{result.message} (exit status {result.status})")
    cost = cost_name(result.study)
    lines.append(f"cost ({cost}) {fmt(result.fun)} on the measured inputs")
    units = _output_units(result)
    lines += [f"fit {name}: {fit_text(f, units)}" for name, f in result.fit.items() if f]
    lines += [f"warning: {w}" for w in result.warnings]
    # the table's last column says why a parameter is weak; each finding is said once
    lines += [f"weakly determined: {n}: {why}" for n, why in result.weak.items() if n not in shown]
    lines += [
        f"validation {name}: "
        + (f"{fit_text(v['fit'], units)}; " if v.get("fit") else "")
        + f"cost ({cost}) {fmt(v['cost'])}"
        for name, v in result.validation.items()
        if "cost" in v
    ]
    if verbose:
        lines += ["", "how the study got there:", *[f"  {line}" for line in result.account]]
        lines += ["", *_statistics_lines(result)]
    return "\n".join(lines)


def _output_units(result: Any) -> dict[str, str]:
    """Units of the outputs by name (the FMU's declared ones); ``{}`` without a study."""
    from tsid_fmu.study.units import study_units

    return study_units(getattr(result, "study", None))


def fit_statistics(result: Any) -> dict[str, Any]:
    """Return lmfit's fit statistics of a result.

    ``nfev``, ``ndata`` (residuals: samples times outputs of the identification
    experiments), ``nvarys`` (parameters varied), ``nfree``, ``chisqr`` (the cost, where
    it is a sum of squares: with ``weighting = "noise"`` a chi-square), ``redchi``,
    ``aic`` and ``bic`` in lmfit's definitions: ``n ln(chisqr / n) + 2 k`` and
    ``n ln(chisqr / n) + ln(n) k``. A figure that cannot be computed (no Jacobian: a
    paused study; a cost that is not a sum of squares) is ``nan``.
    """
    jac = getattr(result, "jac", None)
    n = int(jac.shape[0]) if jac is not None else 0
    k = sum(1 for p in result.params.values() if getattr(p, "vary", True))
    study = result.study
    squares = study is None or str(study.method.cost).lower() == "sse"
    chisqr = float(result.fun) if squares else math.nan
    out = {"nfev": int(result.nfev), "ndata": n, "nvarys": k, "nfree": n - k, "chisqr": chisqr}
    ok = n > k and math.isfinite(chisqr) and chisqr > 0
    out["redchi"] = chisqr / (n - k) if ok else math.nan
    out["aic"] = n * math.log(chisqr / n) + 2 * k if ok else math.nan
    out["bic"] = n * math.log(chisqr / n) + math.log(n) * k if ok else math.nan
    return out


def _statistics_lines(result: Any) -> list[str]:
    st = fit_statistics(result)
    kinds = [s.kind for s in result.stages]
    method = (
        "Taguchi arrays, then least squares" if StageKind.REFINEMENT in kinds else "Taguchi arrays"
    )
    weighted = cost_name(result.study)
    if math.isfinite(st["chisqr"]):
        chi = f"{fmt(st['chisqr'], 7)}  ({weighted})"
    else:
        chi = f"not a sum of squares ({weighted})"
    return [
        "[[Fit Statistics]]",
        f"    # fitting method   = {method}",
        f"    # function evals   = {st['nfev']}",
        f"    # data points      = {st['ndata'] or 'not computed'}",
        f"    # variables        = {st['nvarys']}",
        f"    chi-square         = {chi}",
        f"    reduced chi-square = {fmt(st['redchi'], 7)}",
        f"    Akaike info crit   = {fmt(st['aic'], 7)}",
        f"    Bayesian info crit = {fmt(st['bic'], 7)}",
    ]


def fit_report(result: Any, min_correl: float = MIN_CORREL) -> str:
    """Return the report in lmfit's sections: fit statistics, variables, correlations.

    Parameters
    ----------
    result : IdentificationResult
        The result to report.
    min_correl : float, optional
        Smallest absolute correlation listed (default :data:`MIN_CORREL`, lmfit's).

    Returns
    -------
    str
        ``[[Fit Statistics]]`` (method, evaluations, data points, variables,
        chi-square, reduced chi-square, AIC, BIC), ``[[Variables]]`` (value, standard
        error and its share of the value, 95 % interval as every view shows it, and
        whether the data determine it) and ``[[Correlations]]`` (pairs of determined
        parameters above ``min_correl``, largest first), then the verdict.
    """
    lines = _statistics_lines(result)
    lines.append("[[Variables]]")
    width = max((len(n) for n in result.params), default=0) + 1
    for name, p in result.params.items():
        value, se = float(p), float(getattr(p, "stderr", math.nan))
        unit = f" {p.unit}" if getattr(p, "unit", "") else ""
        # the interval as every view shows it (the value keeps lmfit's 7 figures)
        interval = interval_text(result.intervals.get(name), value, fmt_levels)
        state = determination(result.intervals.get(name))
        if not getattr(p, "vary", True):
            lines.append(
                f"    {(name + ':').ljust(width)} {fmt(value, 7)} (fixed: chosen structure)"
            )
            continue
        at_resolution = name in getattr(result.uncertainty, "resolution", {})
        if math.isfinite(se) and at_resolution:  # a bound, as every view says it
            err = f" +/- < {fmt(se, 3)} (below the profile's resolution)"
        elif math.isfinite(se):
            share = 100 * se / abs(value) if value else math.inf
            rel = "" if near_zero(share) else f" ({share:.2f}%)"  # near zero: absolute
            err = f" +/- {fmt(se, 7)}{rel}"
        else:
            err = " +/- inf" if math.isinf(se) else " +/- not computed"
        lines.append(
            f"    {(name + ':').ljust(width)} {fmt(value, 7)}{err}{unit} "
            f"[95 %: {interval}] ({state})"
        )
    pairs = []
    seen = set()
    for a, p in result.params.items():
        for b, c in (getattr(p, "correl", None) or {}).items():
            key = tuple(sorted((a, b)))
            if key in seen or abs(c) < min_correl:
                continue
            seen.add(key)
            pairs.append((abs(c), a, b, c))
    lines.append(f"[[Correlations]] (unreported correlations are < {min_correl:.3f})")
    if not pairs:
        lines.append("    none above the threshold, or none computed")
    width = max((len(f"C({a}, {b})") for _, a, b, _ in pairs), default=0)
    for _, a, b, c in sorted(pairs, reverse=True):
        lines.append(f"    {f'C({a}, {b})'.ljust(width)} = {c:+.4f}")
    lines.append(f"{result.message} (exit status {result.status})")
    return "\n".join(lines)


register_views(fit_report=fit_report, text_report=text_report)
