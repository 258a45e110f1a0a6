"""The text report of a result, as lmfit's ``fit_report``: what ``tsid identify`` prints.

:func:`fit_report` is :meth:`IdentificationResult.fit_report`; the command line prints
it, then where the report files are.
"""

from __future__ import annotations

from typing import Any

from tsid_fmu.report.notebook import parameter_columns, parameter_rows, sampled_note
from tsid_fmu.report.style import cost_name, fmt
from tsid_fmu.result import STATUS, register_views

__all__ = ["fit_report"]


def fit_report(result: Any) -> str:
    """Return the answer as text, rounded to 5 significant figures.

    Parameters
    ----------
    result : IdentificationResult
        The result to report.

    Returns
    -------
    str
        The parameter table (value, unit, 95 % interval, standard error, flags), the
        stages, the structure chosen, the verdict with the exit status, the cost, the
        warnings, the weakly determined parameters and the validation experiments, one
        finding a line.
    """
    rows = [[fmt(v) if not isinstance(v, str) else v for v in r] for r in parameter_rows(result)]
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
    structure = result.extra.get("structure")
    if structure:
        lines.append(f"structure: {structure['chosen']}: {structure['why']}")
    lines.append("")
    status = STATUS.get(result.status, str(result.status))
    lines.append(f"{status} (exit status {result.status}): {result.message}")
    cost = cost_name(result.study)
    lines.append(
        f"cost ({cost}) {fmt(result.fun)} on the measured inputs; {result.nfev} simulations"
    )
    lines += [f"warning: {w}" for w in result.warnings]
    lines += [f"weakly determined: {n}: {why}" for n, why in result.weak.items()]
    lines += [
        f"validation {name}: cost ({cost}) {fmt(v['cost'])}"
        for name, v in result.validation.items()
        if "cost" in v
    ]
    return "\n".join(lines)


register_views(fit_report=fit_report)
