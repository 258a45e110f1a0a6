"""The re-leveling decision for one factor: case, centre and half-width (Step IV).

:func:`decide_factor` works in a factor's *working domain* (log10 of the values, or the
values, or a rotated factor's coordinate) and knows nothing of bounds beyond the two
numbers it is given, so the same rules serve the papers' per-parameter re-leveling
(:func:`tsid_fmu.doe.leveling.relevel`) and the search's rotated factors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tsid_fmu.doe.options import LevelingOptions

__all__ = ["FactorDecision", "FactorState", "decide_factor", "main_effect_optimum"]


@dataclass
class FactorDecision:
    """What re-leveling decided for one factor (a parameter, or a rotated factor).

    Attributes
    ----------
    name : str
        Factor name.
    case : str
        ``"recentre"`` (Case 1, interior best), ``"shift"`` (best on the boundary:
        the range moves), ``"narrow"`` (Case 2), ``"keep"`` (flat, levels kept) or
        ``"converged"`` (flat and small).
    delta_db : float
        Span of the S/N main effect across the levels.
    best_level : int
        0-based index of the level with the largest mean S/N (``reason`` counts from 1,
        as the response table does).
    optimum : float
        The value the next levels are centred on: the best S/N level (refined by a
        parabola if enabled), or the run-based centre when one was given.
    levels : list of float
        Levels proposed for the next iteration.
    reason : str
        One sentence a person can read: the S/N evidence, the centre, and the next range.
    centre_source : str
        Where the centre came from (``"S/N level 3 of 5"``, ``"run 7"``, ...).
    """

    name: str
    case: str
    delta_db: float
    best_level: int
    optimum: float
    levels: list[float]
    reason: str
    centre_source: str = ""


ParameterDecision = FactorDecision
"""The decision for a parameter (an axis-aligned factor)."""


def _parabola_vertex(x: np.ndarray, y: np.ndarray) -> float | None:
    """Vertex of the parabola through three points, or None if it opens upwards."""
    (x0, x1, x2), (y0, y1, y2) = x, y
    denom = (x0 - x1) * (x0 - x2) * (x1 - x2)
    if denom == 0:
        return None
    a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / denom
    b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / denom
    if a >= 0:
        return None
    return float(-b / (2 * a))


def main_effect_optimum(u: np.ndarray, sn: np.ndarray, refine: bool) -> tuple[int, float, str]:
    """Return the best S/N level, the predicted optimum and a phrase saying which.

    Parameters
    ----------
    u : numpy.ndarray
        Increasing level values (in the working domain: log10 or linear).
    sn : numpy.ndarray
        Mean S/N of each level (``-inf`` or NaN for levels without a valid run).
    refine : bool
        Refine an interior best by the vertex of the parabola through it and its two
        neighbours (clipped to between them).

    Returns
    -------
    best : int
        0-based index of the largest mean S/N.
    optimum : float
        Predicted optimum in the working domain.
    source : str
        ``"S/N level 3 of 5"`` or ``"S/N peak between levels 2 and 4"`` (1-based).
    """
    sn = np.where(np.isfinite(sn), sn, -np.inf)
    best = int(np.argmax(sn))
    n = len(u)
    source = f"S/N level {best + 1} of {n}"
    if refine and 0 < best < n - 1 and np.all(np.isfinite(sn[best - 1 : best + 2])):
        vertex = _parabola_vertex(u[best - 1 : best + 2], sn[best - 1 : best + 2])
        if vertex is not None and vertex != u[best]:
            lo, hi = (best - 1, best) if vertex < u[best] else (best, best + 1)
            return (
                best,
                min(max(vertex, u[lo]), u[hi]),
                (f"S/N peak between levels {lo + 1} and {hi + 1} of {n}"),
            )
    return best, float(u[best]), source


@dataclass(frozen=True)
class FactorState:
    """Flags of one factor that :func:`decide_factor` combines into a case."""

    flat: bool
    small: bool
    minor: bool = False
    any_significant: bool = True
    converged: bool = False


def _case(
    state: FactorState, interior: bool, side: str, at_bound: bool, run_centre: bool, opts
) -> tuple[str, float]:
    """Return the case and the factor applied to the half-width."""
    if state.converged or (state.flat and state.small):
        return "converged", 1.0
    if state.flat and opts.selective and state.any_significant:
        return "keep", 1.0
    if not interior and at_bound:
        return "narrow", opts.shrink
    if not interior and (not state.flat or run_centre):
        return "shift", opts.expand
    return ("narrow" if state.flat else "recentre"), opts.shrink


def _describe(
    case: str,
    state: FactorState,
    delta: float,
    best: int,
    n: int,
    side: str,
    at_bound: bool,
    minor_text: str,
) -> str:
    evidence = (
        f"{minor_text}"
        if state.minor and minor_text
        else f"S/N {'flat' if state.flat else 'changes by'} {delta:.3g} dB"
        + ("" if state.flat else f", best at level {best + 1} of {n}")
    )
    return {
        "converged": f"{evidence}; levels within the tolerance: kept",
        "keep": f"{evidence}; levels kept while other factors move",
        "narrow": f"{evidence}; narrowed"
        + (f" towards the {side} level, which is the physical bound" if at_bound else ""),
        "shift": f"{evidence}; centre on the {side} edge of the levels: range moved "
        + ("up" if side == "upper" else "down"),
        "recentre": f"{evidence}; recentred and narrowed",
    }[case]


def decide_factor(
    name: str,
    u: np.ndarray,
    sn: np.ndarray,
    state: FactorState,
    options: LevelingOptions,
    *,
    centre: tuple[float, str] | None = None,
    bounds: tuple[float, float] = (-math.inf, math.inf),
    minor_text: str = "",
) -> tuple[FactorDecision, float, float]:
    """Decide one factor's case, centre and half-width in its working domain.

    Parameters
    ----------
    name : str
        Factor name.
    u : numpy.ndarray
        Its increasing levels in the working domain (log10 of the values, or the values).
    sn : numpy.ndarray
        Mean S/N of each level.
    state : FactorState
        Flatness and smallness of this factor and of the whole iteration.
    options : LevelingOptions
        Thresholds and rules.
    centre : tuple of (float, str), optional
        Run-based centre in the working domain and a label (``"run 7"``) saying where
        it comes from; default the main-effects optimum.
    bounds : tuple of float
        Physical bounds in the working domain.
    minor_text : str
        Why a minor contributor counts as flat (ANOVA contribution), for the reason.

    Returns
    -------
    decision : FactorDecision
        With ``levels`` left empty and ``reason`` without the next range: the caller
        makes the levels (in its own units) and appends them.
    centre_u : float
        Centre of the next levels in the working domain.
    half : float
        Half-width of the next levels in the working domain.
    """
    best, optimum_u, source = main_effect_optimum(u, sn, options.refine)
    sn_finite = sn[np.isfinite(sn)]
    delta = float(sn_finite.max() - sn_finite.min()) if sn_finite.size else 0.0
    if centre is not None:
        optimum_u, source = float(centre[0]), centre[1]
    # a run-based centre that is a boundary level up to rounding (it may have gone through
    # the search coordinates and back) counts as on the boundary
    eps = 1e-9 * float(u[-1] - u[0])
    inside = u[0] + eps < optimum_u < u[-1] - eps
    interior = inside if centre is not None else 0 < best < len(u) - 1
    if not interior:
        optimum_u = min(max(optimum_u, u[0]), u[-1]) if centre is None else optimum_u
    # a boundary centre is within eps of one end: the nearer end is its side (comparing
    # with u[-1] alone sent a centre just under the top level, by rounding, downwards)
    side = "" if interior else ("upper" if optimum_u > 0.5 * (u[0] + u[-1]) else "lower")
    at_bound = (side == "upper" and u[-1] >= bounds[1]) or (side == "lower" and u[0] <= bounds[0])
    case, factor = _case(state, interior, side, at_bound, centre is not None, options)
    half = 0.5 * (u[-1] - u[0]) * factor
    text = _describe(case, state, delta, best, len(u), side, at_bound, minor_text)
    if case in ("converged", "keep"):
        centre_u, reason = 0.5 * (u[0] + u[-1]), text
    else:
        centre_u, reason = optimum_u, f"{text} about {source}"
    decision = FactorDecision(
        name=name,
        case=case,
        delta_db=delta,
        best_level=best,
        optimum=float("nan"),
        levels=[],
        reason=reason,
        centre_source=source,
    )
    return decision, centre_u, half
