"""Re-leveling: choosing the levels of the next iteration from the S/N response (Step IV).

The SISO paper distinguishes three cases after each iteration:

* **Case 1** - the S/N of a parameter changes significantly across its levels: take the
  best level as the new base. An interior best becomes the centre of a narrower range;
  a best level on the boundary moves the range in that direction.
* **Case 2** - the S/N is flat but the levels are still far apart: narrow the range.
* **Case 3** - every S/N is flat and every range is small: stop, the parameters are found.

The MISO paper adds *selective* re-leveling (its Case II): only the parameters whose S/N
changed significantly get new levels; the flat ones keep theirs until every S/N is flat.

All thresholds live in :class:`LevelingOptions`, with defaults documented there.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from tsid_fmu.errors import StudyError

__all__ = [
    "LevelingDecision",
    "LevelingOptions",
    "ParameterDecision",
    "make_levels",
    "relative_span",
    "relevel",
    "use_log_scale",
]


@dataclass(frozen=True)
class LevelingOptions:
    """Thresholds and rules of re-leveling.

    Parameters
    ----------
    significance_db : float
        A parameter whose S/N main effect spans less than this (max - min of the level
        means, in dB) is *flat*. Default 0.1 dB, i.e. about a 2.3 % change of the RMS cost
        across the levels.
    tolerance : float
        A range is *small* once ``(max - min) / |centre|`` of its levels is at most this.
        Default 0.005 (levels within +/-0.25 % of the centre).
    shrink : float
        Factor applied to the half-width of a range that is narrowed (Case 1 with an
        interior best, Case 2). Default 0.5.
    n_levels : int or None
        Number of levels of later iterations; default: as many as the first iteration.
    refine : bool
        If true, an interior best is refined by the vertex of a parabola through the S/N
        of the best level and its two neighbours (clipped to between them).
    selective : bool
        MISO paper's Case II: flat parameters keep their levels while any parameter is
        still significant. Default false (SISO paper: flat and wide ranges are narrowed).
    scale : {"auto", "linear", "log"}
        Spacing of generated levels. ``auto`` spaces logarithmically when all levels are
        positive and the range spans at least a factor ``log_ratio``.
    log_ratio : float
        Ratio max/min from which ``auto`` uses logarithmic spacing. Default 10 (a range
        spanning a decade or more).
    expand : float
        Factor applied to the half-width when a range moves because its best is on the
        boundary (Case 1, shift): the new range is centred on that boundary level. 1
        keeps the width, below 1 narrows as the SISO paper's Tables I-III do, above 1
        recovers faster from a range narrowed too early. Default 1.
    min_contribution : float
        ANOVA percent contribution below which a parameter is treated as flat when
        choosing new levels, even if its S/N moves by more than ``significance_db``
        (its apparent effect is then mostly other parameters' interactions). With
        ``selective`` such a parameter keeps its range until the dominant ones have
        settled - the MISO paper's reason for identifying parameters in groups.
        Default 0 (off). The stop rule (Case 3) uses ``significance_db`` only.
    """

    significance_db: float = 0.1
    tolerance: float = 0.005
    shrink: float = 0.5
    n_levels: int | None = None
    refine: bool = True
    selective: bool = False
    scale: str = "auto"
    log_ratio: float = 10.0
    min_contribution: float = 0.0
    expand: float = 1.0

    def __post_init__(self) -> None:
        if not self.significance_db >= 0:
            raise StudyError(f"significance_db must be >= 0, got {self.significance_db}")
        if not self.tolerance > 0:
            raise StudyError(f"tolerance must be > 0, got {self.tolerance}")
        if not 0 < self.shrink < 1:
            raise StudyError(f"shrink must be between 0 and 1, got {self.shrink}")
        if self.n_levels is not None and not 2 <= self.n_levels <= 5:
            raise StudyError(
                f"n_levels must be from 2 to 5 (the standard arrays have 2-, 3-, 4- and "
                f"5-level columns), got {self.n_levels}"
            )
        if self.scale not in ("auto", "linear", "log"):
            raise StudyError(f"scale must be 'auto', 'linear' or 'log', got {self.scale!r}")
        if not self.log_ratio > 1:
            raise StudyError(f"log_ratio must be > 1, got {self.log_ratio}")
        if not self.expand > 0:
            raise StudyError(f"expand must be > 0, got {self.expand}")
        if not 0 <= self.min_contribution < 100:
            raise StudyError(
                f"min_contribution must be a percentage in [0, 100), got {self.min_contribution}"
            )


@dataclass
class ParameterDecision:
    """What re-leveling decided for one parameter.

    Attributes
    ----------
    name : str
        Parameter name.
    case : str
        ``"recentre"`` (Case 1, interior best), ``"shift"`` (Case 1, best on the
        boundary), ``"narrow"`` (Case 2), ``"keep"`` (flat, levels kept) or
        ``"converged"`` (flat and small).
    delta_db : float
        Span of the S/N main effect across the levels.
    best_level : int
        0-based index of the level with the largest mean S/N.
    optimum : float
        Predicted best value (the best level, refined if enabled).
    levels : list of float
        Levels proposed for the next iteration.
    reason : str
        One sentence a person can read.
    """

    name: str
    case: str
    delta_db: float
    best_level: int
    optimum: float
    levels: list[float]
    reason: str


@dataclass
class LevelingDecision:
    """The outcome of re-leveling for all parameters of one iteration."""

    parameters: list[ParameterDecision] = field(default_factory=list)
    converged: bool = False
    message: str = ""

    @property
    def case(self) -> int:
        """The paper's case number: 3 if converged, 1 if any S/N is significant, else 2."""
        if self.converged:
            return 3
        if any(p.case in ("recentre", "shift") for p in self.parameters):
            return 1
        return 2

    def next_levels(self) -> dict[str, list[float]]:
        """Return the proposed levels by parameter name."""
        return {p.name: list(p.levels) for p in self.parameters}

    def optimum(self) -> dict[str, float]:
        """Return the predicted optimum by parameter name."""
        return {p.name: p.optimum for p in self.parameters}

    def to_dict(self) -> dict:
        """Return a JSON-serialisable copy."""
        return {
            "case": self.case,
            "converged": self.converged,
            "message": self.message,
            "parameters": [asdict(p) for p in self.parameters],
        }


def use_log_scale(values: Sequence[float], options: LevelingOptions) -> bool:
    """Return True if levels spanning ``values`` should be spaced logarithmically."""
    if options.scale == "linear":
        return False
    lo, hi = float(min(values)), float(max(values))
    if options.scale == "log":
        return lo > 0
    return lo > 0 and hi / lo >= options.log_ratio


def relative_span(levels: Sequence[float]) -> float:
    """Return ``(max - min) / |centre|`` of a set of levels (``inf`` for a centre at 0)."""
    lo, hi = float(min(levels)), float(max(levels))
    centre = 0.5 * (lo + hi)
    if centre == 0:
        return math.inf if hi > lo else 0.0
    return (hi - lo) / abs(centre)


def make_levels(
    lo: float,
    hi: float,
    n: int,
    *,
    log: bool = False,
    bounds: tuple[float, float] = (-math.inf, math.inf),
) -> list[float]:
    """Return ``n`` levels from ``lo`` to ``hi``, clipped to ``bounds``.

    Parameters
    ----------
    lo, hi : float
        Range of the levels (swapped if reversed).
    n : int
        Number of levels, at least 2.
    log : bool
        Space geometrically instead of linearly (requires ``lo > 0``).
    bounds : tuple of float
        Physical bounds ``(min, max)``; the range is clipped into them.

    Returns
    -------
    list of float
        Strictly increasing levels.
    """
    if n < 2:
        raise StudyError(f"a parameter needs at least 2 levels, got {n}")
    lo, hi = min(lo, hi), max(lo, hi)
    bmin, bmax = bounds
    lo, hi = max(lo, bmin), min(hi, bmax)
    if log and lo <= 0:
        log = False
    if hi <= lo:
        width = max(abs(lo), 1.0) * 1e-9
        lo, hi = lo - width, lo + width
    values = np.geomspace(lo, hi, n) if log else np.linspace(lo, hi, n)
    return [float(_round_sig(v)) for v in values]


def _round_sig(v: float, digits: int = 12) -> float:
    """Round to ``digits`` significant figures, so that levels print cleanly."""
    if v == 0 or not math.isfinite(v):
        return v
    return round(v, digits - 1 - math.floor(math.log10(abs(v))))


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


def relevel(
    levels: Mapping[str, Sequence[float]],
    sn_means: Mapping[str, Sequence[float]],
    options: LevelingOptions | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    centre: Mapping[str, float] | None = None,
    shrink: float | None = None,
    contribution: Mapping[str, float] | None = None,
) -> LevelingDecision:
    """Choose the levels of the next iteration from the S/N main effects.

    Parameters
    ----------
    levels : mapping of str to sequence of float
        Current levels of each parameter, in level order (increasing values).
    sn_means : mapping of str to sequence of float
        Mean S/N ratio (dB, larger is better) at each level of each parameter.
    options : LevelingOptions, optional
        Thresholds and rules; defaults documented on :class:`LevelingOptions`.
    bounds : mapping of str to (float, float), optional
        Physical bounds ``(min, max)`` of each parameter.
    centre : mapping of str to float, optional
        Run-based selection: centre the next levels on these values (e.g. the best run
        seen) instead of on each parameter's best S/N level. A value at or beyond the
        lowest or highest level counts as a boundary best. Flatness is still judged from
        the S/N main effects.
    shrink : float, optional
        Override of ``options.shrink`` for interior recentring (1 keeps the width, to move
        a range without narrowing it).
    contribution : mapping of str to float, optional
        ANOVA percent contribution of each parameter, compared with
        ``options.min_contribution``.

    Returns
    -------
    LevelingDecision
        One :class:`ParameterDecision` per parameter and whether the study converged
        (Case 3).

    Examples
    --------
    >>> d = relevel({"k": [1, 2, 3, 4, 5]}, {"k": [-30, -20, -10, -20, -30]})
    >>> d.parameters[0].case, d.parameters[0].levels
    ('recentre', [2.0, 2.5, 3.0, 3.5, 4.0])
    """
    options = options or LevelingOptions()
    bounds = dict(bounds or {})
    names = list(levels)
    missing = [n for n in names if n not in sn_means]
    if missing:
        raise StudyError(f"no S/N response for parameter(s) {', '.join(missing)}")

    flat: dict[str, bool] = {}
    small: dict[str, bool] = {}
    deltas: dict[str, float] = {}
    for name in names:
        sn = np.asarray(sn_means[name], dtype=float)
        finite = sn[np.isfinite(sn)]
        deltas[name] = float(finite.max() - finite.min()) if finite.size else 0.0
        flat[name] = deltas[name] < options.significance_db
        small[name] = relative_span(levels[name]) <= options.tolerance

    converged = all(flat.values()) and all(small.values())
    minor = {
        n: contribution is not None and contribution.get(n, 100.0) < options.min_contribution
        for n in names
    }
    # for choosing levels, a minor contributor counts as flat (its main effect is noise)
    flat = {n: flat[n] or minor[n] for n in names}
    all_flat = all(flat.values())
    any_significant = not all_flat

    decisions = []
    for name in names:
        lv = np.asarray(levels[name], dtype=float)
        order = np.argsort(lv)
        lv = lv[order]
        sn = np.asarray(sn_means[name], dtype=float)[order]
        sn = np.where(np.isfinite(sn), sn, -np.inf)
        best = int(np.argmax(sn))
        n_next = options.n_levels or len(lv)
        bmin, bmax = bounds.get(name, (-math.inf, math.inf))
        log = use_log_scale(lv, options)
        u = np.log10(lv) if log else lv
        half = 0.5 * (u[-1] - u[0])
        optimum_u = u[best]
        interior = 0 < best < len(lv) - 1
        if centre is not None and name in centre:
            c = float(centre[name])
            if log and c <= 0:
                log, u = False, lv
                half = 0.5 * (u[-1] - u[0])
            optimum_u = math.log10(c) if log else c
            best = int(np.argmin(np.abs(u - optimum_u)))
            interior = u[0] < optimum_u < u[-1]
            if not interior:
                best = 0 if optimum_u <= u[0] else len(lv) - 1
        elif options.refine and interior and np.all(np.isfinite(sn[best - 1 : best + 2])):
            vertex = _parabola_vertex(u[best - 1 : best + 2], sn[best - 1 : best + 2])
            if vertex is not None:
                optimum_u = min(max(vertex, u[best - 1]), u[best + 1])

        def to_value(x: float, log: bool = log) -> float:
            return float(10.0**x) if log else float(x)

        optimum = min(max(to_value(optimum_u), bmin), bmax)
        delta = deltas[name]
        if converged or (flat[name] and small[name]):
            case, new = "converged", list(map(float, lv))
            reason = f"S/N flat ({delta:.3g} dB) and levels within the tolerance"
        elif flat[name] and options.selective and any_significant:
            case, new = "keep", list(map(float, lv))
            why = (
                f"ANOVA contribution {contribution[name]:.2g} %"
                if minor[name] and contribution is not None
                else f"S/N flat ({delta:.3g} dB)"
            )
            reason = f"{why}; levels kept while other parameters move"
        elif flat[name]:
            case = "narrow"
            new_half = options.shrink * half
            new = _levels_about(optimum_u, new_half, n_next, log, (bmin, bmax), options)
            reason = f"S/N flat ({delta:.3g} dB) but levels far apart: narrowed about the best"
        elif interior:
            case = "recentre"
            new_half = (options.shrink if shrink is None else shrink) * half
            new = _levels_about(optimum_u, new_half, n_next, log, (bmin, bmax), options)
            reason = (
                f"S/N changes by {delta:.3g} dB with its best at interior level {best + 1}: "
                "narrowed about it"
            )
        else:
            side = "upper" if best == len(lv) - 1 else "lower"
            at_bound = (side == "upper" and lv[-1] >= bmax) or (side == "lower" and lv[0] <= bmin)
            if at_bound:
                case = "narrow"
                new = _levels_about(
                    optimum_u, options.shrink * half, n_next, log, (bmin, bmax), options
                )
                reason = (
                    f"S/N best at the {side} level, which is the physical bound: "
                    "narrowed towards it"
                )
            else:
                case = "shift"
                new_half = options.expand * half
                new = _levels_about(optimum_u, new_half, n_next, log, (bmin, bmax), options)
                reason = (
                    f"S/N changes by {delta:.3g} dB with its best at the {side} level: "
                    f"range moved {'up' if side == 'upper' else 'down'}"
                )
        if centre is not None and name in centre and case != "converged":
            reason = f"centred on the best run ({optimum:.6g}); {reason}"
        decisions.append(
            ParameterDecision(
                name=name,
                case=case,
                delta_db=delta,
                best_level=int(order[best]),
                optimum=_round_sig(optimum),
                levels=new,
                reason=reason,
            )
        )

    if converged:
        message = "Case 3: every S/N is flat and every range is within the tolerance"
    elif any_significant:
        moving = [d.name for d in decisions if d.case in ("recentre", "shift")]
        message = f"Case 1: S/N changes significantly for {', '.join(moving)}"
    else:
        message = "Case 2: every S/N is flat but some levels are still far apart"
    return LevelingDecision(parameters=decisions, converged=converged, message=message)


def _levels_about(
    centre_u: float,
    half_u: float,
    n: int,
    log: bool,
    bounds: tuple[float, float],
    options: LevelingOptions,
) -> list[float]:
    """Levels spanning ``centre +/- half`` in the (possibly log10) domain."""
    lo_u, hi_u = centre_u - half_u, centre_u + half_u
    if log:
        lo, hi = 10.0**lo_u, 10.0**hi_u
        # keep geometric spacing only while the new range still spans decades
        keep_log = options.scale == "log" or hi / lo >= options.log_ratio
        return make_levels(lo, hi, n, log=keep_log, bounds=bounds)
    return make_levels(lo_u, hi_u, n, log=False, bounds=bounds)
