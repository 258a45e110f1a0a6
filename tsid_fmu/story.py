"""One parameter, one story: how every view says a parameter's interval and flag.

The console, the HTML and markdown reports, ``parameters.csv``, ``--json`` and the
design all show a parameter's 95 % interval and whether the data determine it. They
draw both from here, so that a parameter is never "not determined" in one view and
"determined" in another (issue 64):

- :func:`interval_text`: ``"88.47 .. 88.53"``; an open end is ``open``
  (``"open .. 5.012"``, half-open); ``"not determined"`` where both ends are open;
- :func:`determination`: ``"determined"``, ``"open below"``, ``"open above"`` or
  ``"not determined"``, and :func:`weak_reason`, the sentence the "weakly determined"
  column gives;
- :func:`listed_combinations`: the combinations of parameters, best determined first,
  with a combination the Jacobian calls determined but whose leading parameter's
  interval is open said to be determined only locally.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

__all__ = [
    "LEADING",
    "NEAR_ZERO",
    "determination",
    "interval_text",
    "listed_combinations",
    "near_zero",
    "weak_reason",
]

LEADING = 0.9
"""Share of a combination's norm above which one parameter leads it (a combination
that is that parameter alone, for practical purposes)."""


NEAR_ZERO = 100.0
"""Relative standard error (percent) above which a value is near zero for its
uncertainty: its error is said in the parameter's units, not as a share of the value."""


def near_zero(relative: float) -> bool:
    """Return True where a relative standard error says the value is near zero.

    An error above :data:`NEAR_ZERO` % of the value (an offset of 0.002 known to
    +/-0.004) reads as "+/-210 %" but is an absolute figure: every view says it in the
    parameter's units instead.
    """
    return math.isfinite(relative) and relative > NEAR_ZERO


def _end(v: Any) -> float | None:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def determination(interval: Sequence[Any] | None) -> str:
    """Return how far the data determine a parameter from its 95 % interval.

    ``"determined"`` (both ends finite), ``"open below"``, ``"open above"``,
    ``"not determined"`` (both open) or ``"not computed"`` (no interval).
    """
    if not interval:
        return "not computed"
    low, high = _end(interval[0]), _end(interval[1])
    if low is not None and high is not None:
        return "determined"
    if low is None and high is None:
        return "not determined"
    return "open below" if low is None else "open above"


def interval_text(
    interval: Sequence[Any] | None, value: float, fmt_pair: Callable[[list[float]], list[str]]
) -> str:
    """Return the 95 % interval as every view shows it.

    Parameters
    ----------
    interval : sequence or None
        ``[low, high]``; ``None`` (or a non-finite number) is an open end.
    value : float
        The identified value (the formatter shows the ends with as many figures as
        tell them apart from it).
    fmt_pair : callable
        Formats ``[low, value, high]`` (or ``[end, value]``) to strings.

    Returns
    -------
    str
        ``"low .. high"``, ``"open .. high"``, ``"low .. open"``, ``"not determined"``,
        or ``"not computed"`` where there is no interval.
    """
    state = determination(interval)
    if state in ("not determined", "not computed"):
        return state
    low, high = _end(interval[0]), _end(interval[1])  # type: ignore[index]
    if state == "determined":
        if low < high:  # type: ignore[operator]
            lo, _, hi = fmt_pair([low, value, high])  # type: ignore[list-item]
        else:
            lo, hi = fmt_pair([low])[0], fmt_pair([high])[0]  # type: ignore[list-item]
        return f"{lo} .. {hi}"
    end = low if low is not None else high
    shown = fmt_pair([end, value])[0]  # type: ignore[list-item]
    return f"open .. {shown}" if low is None else f"{shown} .. open"


def weak_reason(interval: Sequence[Any] | None) -> str | None:
    """Return the "weakly determined" sentence of an interval with an open end, or None."""
    state = determination(interval)
    if state == "not determined":
        return "the data do not determine it (open 95 % interval)"
    if state == "open below":
        return "the data bound it only from above (95 % interval open below)"
    if state == "open above":
        return "the data bound it only from below (95 % interval open above)"
    return None


def _parameter(term: str) -> str:
    """Return the parameter of a combination's term: ``lg B_s`` (its log10) is ``B_s``."""
    return term[3:] if term.startswith("lg ") else term


def listed_combinations(
    combinations: Sequence[Mapping[str, Any]], intervals: Mapping[str, Sequence[Any] | None]
) -> list[dict[str, Any]]:
    """Return the combinations as the reports list them, best determined first.

    Each is a copy with ``state``: ``"determined"``, ``"not determined"``, or, where
    the Jacobian calls it determined but the parameter that leads it
    (:data:`LEADING`) has an open interval, ``"determined only locally (the profile
    leaves NAME's interval open)"``: the linearisation at the answer fixes it, the
    cost further out does not.
    """
    out = []
    for c in combinations:
        terms = {str(k): float(w) for k, w in (c.get("terms") or {}).items()}
        norm = math.sqrt(sum(w * w for w in terms.values())) or 1.0
        lead = max(terms, key=lambda k: abs(terms[k])) if terms else None
        state = "determined" if c.get("determined") else "not determined"
        name = _parameter(lead) if lead is not None else None
        if (
            state == "determined"
            and name is not None
            and abs(terms[lead]) / norm >= LEADING  # type: ignore[index]
            and determination(intervals.get(name)) not in ("determined", "not computed")
        ):
            state = f"determined only locally (the profile leaves {name}'s interval open)"
        out.append({**c, "terms": terms, "state": state})
    se = [float(c.get("std_error", math.inf)) for c in out]
    order = sorted(range(len(out)), key=lambda i: se[i] if math.isfinite(se[i]) else math.inf)
    return [out[i] for i in order]
