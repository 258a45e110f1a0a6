"""Whether the answer sits on a bound of its range, and what that means for the user.

A parameter pushed onto its bound (``min = 0`` that ``tsid init`` or the user wrote, a
declared ``max``) is where the data would take it further if they could: its best value
may lie beyond, and its interval is cut at the bound. An answer there must say so
(issue 43: ``add.k2`` was returned as 1.8e-18 on a ``min = 0`` for a true -0.4, with
exit 0 and no word of it).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from tsid_fmu.numerics.rank import unseen_columns
from tsid_fmu.numerics.tuning import ON_BOUND, TOWARD_ZERO

__all__ = ["ON_BOUND", "bound_warnings", "inert_parameters", "on_bounds", "unshown_warnings"]


def on_bounds(
    x: Mapping[str, float],
    bounds: Mapping[str, tuple[float, float]],
    levels: Mapping[str, Sequence[float]],
) -> dict[str, str]:
    """Return ``{name: "min" or "max"}`` for each parameter of ``x`` on a bound.

    Parameters
    ----------
    x : mapping
        The answer.
    bounds : mapping
        ``(min, max)`` by name (infinite where there is none).
    levels : mapping
        The first levels by name: their span sets the distance that counts as on, and a
        positive value under :data:`TOWARD_ZERO` of the smallest one is on ``min = 0``.
    """
    out: dict[str, str] = {}
    for name, value in x.items():
        if name not in bounds or name not in levels:
            continue
        low, high = bounds[name]
        span = max(levels[name]) - min(levels[name]) or abs(float(value)) or 1.0
        tol = ON_BOUND * span
        toward_zero = low == 0 and min(levels[name]) > 0 and value < TOWARD_ZERO * min(levels[name])
        if value - low <= tol or toward_zero:
            out[name] = "min"
        elif high - value <= tol:
            out[name] = "max"
    return out


def bound_warnings(
    on: Mapping[str, str],
    x: Mapping[str, float],
    bounds: Mapping[str, tuple[float, float]],
    inert: Sequence[str] = (),
) -> list[str]:
    """Return one warning per parameter on a bound, naming the bound and what follows.

    ``inert`` are the parameters with no effect on the outputs at the answer
    (:func:`inert_parameters`): the data do not push those anywhere, and the warning
    says what holds them there instead (Parker's valve: two such parameters were said
    to be pushed onto their bounds by the data).
    """
    out = []
    for name, side in on.items():
        bound = bounds[name][0 if side == "min" else 1]
        head = f"{name} = {x[name]:.4g} sits on its bound {side} = {bound:g}: "
        if name in inert:
            out.append(
                head + "it has no effect on the outputs there, so the data cannot place it; "
                "fix it at a known value, or excite what it acts on"
            )
            continue
        out.append(
            head + "the data push it there, so its best value may lie beyond (widen the "
            "bound if the physics allow) and its interval is cut at the bound"
        )
    return out


def inert_parameters(jacobian: np.ndarray, names: Sequence[str]) -> list[str]:
    """Return the parameters whose column of the residuals' Jacobian is zero to rank.

    A column at most ``sqrt(UNSEEN)`` of the largest (the rank rule every interval
    uses, :data:`tsid_fmu.numerics.rank.UNSEEN`) is one the outputs do not depend on.
    """
    unseen = unseen_columns(jacobian)
    return [n for n, u in zip(names, unseen, strict=True) if u]


def unshown_warnings(
    messages: Sequence[tuple[str, str, int]],
    status: int,
    intervals: Mapping[str, Sequence[float | None]],
) -> list[str]:
    """Return the warnings of an answer not shown to be an optimum.

    ``messages`` holds each stage's ``(name, message, status)``: every stage that
    stopped short (status 1) is quoted. Where the study's own status is 1, one more
    says that the intervals (of parameters, and of named combinations) were computed
    there: they describe the cost around a point that is not its minimum, and may miss
    the truth (modestpy's ``Simple2R1C``, stopped at a limit 1.1 % off along R1 C, gave
    R1 C an interval of 200.96 .. 203.22 around a true 200).
    """
    # at exit 0 the answer was shown stationary after them: the account says why they
    # stopped, and a warning beside "converged" would contradict it
    out = [f"{name}: {message}" for name, message, stage in messages if stage == 1 and status]
    finite = [n for n, iv in intervals.items() if iv and None not in iv]
    if status == 1:
        which = f"of {', '.join(finite)} and " if finite else ""
        out.append(
            "the answer is not shown to be an optimum (exit status 1), and the 95 % "
            f"intervals {which}of any combination named were computed there: they may "
            "not hold the truth; continue the study (--resume with higher limits) or read "
            "the warnings above before using them"
        )
    return out
