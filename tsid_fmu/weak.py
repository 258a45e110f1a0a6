"""What a person should know about an answer beyond its values: weak parameters, a poor fit.

:func:`weak_parameters` is :attr:`~tsid_fmu.result.IdentificationResult.weak`, the same
reason in every view; :func:`poor_fit` the warning of an answer still far above the
noise after the search's restarts.
"""

from __future__ import annotations

import math
from typing import Any

from tsid_fmu.story import near_zero, weak_reason
from tsid_fmu.study.units import study_units

__all__ = ["WEAK_STD_ERROR", "poor_fit", "weak_parameters"]

WEAK_STD_ERROR = 5.0
"""Relative standard error (percent) above which a parameter is reported as weakly
determined by the data."""


def poor_fit(answer: Any) -> list[str]:
    """Return the warning for an answer still far above the noise after the restarts."""
    poor = answer.poor_fit
    if not poor:
        return []
    if poor.get("horizons_agree"):
        searched = "following the data from their first part reached the same answer"
    else:
        searched = f"{poor['restarts']} restart(s) found no lower basin"
    return [
        f"the answer's cost is {poor['ratio']:.3g} times the noise floor, and {searched}: the"
        " model may not explain these data, the noise may be strongly coloured, or the answer"
        " is a local minimum the search did not leave (try wider first levels, or other start"
        " values)"
    ]


def weak_parameters(result: Any) -> dict[str, str]:
    """Return the parameters the data determine poorly, each with the reason.

    An open end of its interval (:func:`tsid_fmu.story.weak_reason`); a relative
    standard error above :data:`WEAK_STD_ERROR`; or, for a value near zero for its error
    (:func:`tsid_fmu.story.near_zero`), an absolute error above that share of its first
    range.
    """
    weak: dict[str, str] = {}
    u = result.uncertainty
    study = result.study
    levels = study.first_levels() if study is not None else {}
    widths = {n: float(max(v) - min(v)) for n, v in levels.items()}
    units = study_units(study)
    for n, rel in (u.relative if u is not None else {}).items():
        said = weak_reason(u.intervals.get(n, [None, None]))
        if said:
            weak[n] = said
        elif near_zero(rel):  # its error is absolute: weak against its first range
            se, width = float(u.std_error.get(n, math.nan)), widths.get(n, math.nan)
            if not se <= WEAK_STD_ERROR / 100 * width:
                unit = f" {units[n]}" if units.get(n) else ""
                weak[n] = (
                    f"the data determine it only to +/-{se:.2g}{unit} (standard error; "
                    "it is near zero)"
                )
        elif rel > WEAK_STD_ERROR:
            weak[n] = f"the data determine it only to +/-{rel:.2g} % (standard error)"
    return weak
