"""Re-leveling: choosing the levels of the next iteration from the S/N response (Step IV).

The SISO paper distinguishes three cases after each iteration:

* **Case 1** - the S/N of a factor changes significantly across its levels: take the
  best level as the new base. An interior best becomes the centre of a narrower range;
  a best level on the boundary moves the range in that direction.
* **Case 2** - the S/N is flat but the levels are still far apart: choose other levels
  (narrower about the best, or moved when the best lies on the boundary of the range).
* **Case 3** - every S/N is flat and every range is small: stop, the values are found.

The MISO paper adds *selective* re-leveling (its Case II): only the factors whose S/N
changed significantly get new levels; the flat ones keep theirs until every S/N is flat.
It also centres the next levels on a *run* (its Table 3, run 7, then run 4) instead of
on each factor's best level: :func:`relevel` takes that run as ``centre``. A run-based
centre on the edge of the levels moves the range that way even when the S/N is flat
there: the best run seen lies at the end of what was explored, so the range must move
(with a flat S/N a narrower range about the edge could never reach past it).

Every decision carries one sentence, ``reason``, that names the level (1-based, as in
the response table), the centre and the next range, so that a person can check it
against the levels written. All thresholds live in :class:`LevelingOptions`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.doe.rules import FactorDecision, FactorState, decide_factor, main_effect_optimum
from tsid_fmu.errors import StudyError

__all__ = [
    "FactorDecision",
    "LevelingDecision",
    "LevelingOptions",
    "ParameterDecision",
    "decide_factor",
    "main_effect_optimum",
    "make_levels",
    "relative_span",
    "relevel",
    "use_log_scale",
]


ParameterDecision = FactorDecision
"""The decision for a parameter (an axis-aligned factor)."""


@dataclass
class LevelingDecision:
    """The outcome of re-leveling for all factors of one iteration."""

    parameters: list[FactorDecision] = field(default_factory=list)
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
        """Return the proposed levels by factor name."""
        return {p.name: list(p.levels) for p in self.parameters}

    def optimum(self) -> dict[str, float]:
        """Return the centre of the next levels by factor name."""
        return {p.name: p.optimum for p in self.parameters}

    def to_dict(self) -> dict:
        """Return a JSON-serialisable copy."""
        return {
            "case": self.case,
            "converged": self.converged,
            "message": self.message,
            "parameters": [asdict(p) for p in self.parameters],
        }

    @classmethod
    def from_dict(cls, data: Mapping) -> LevelingDecision:
        """Re-create a decision written by :meth:`to_dict`."""
        return cls(
            parameters=[FactorDecision(**p) for p in data["parameters"]],
            converged=bool(data["converged"]),
            message=str(data["message"]),
        )


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
    return [float(round_sig(v)) for v in values]


def round_sig(v: float, digits: int = 12) -> float:
    """Round to ``digits`` significant figures, so that levels print cleanly."""
    if v == 0 or not math.isfinite(v):
        return v
    return round(v, digits - 1 - math.floor(math.log10(abs(v))))


def _states(
    levels: Mapping[str, Sequence[float]],
    sn_means: Mapping[str, Sequence[float]],
    options: LevelingOptions,
    contribution: Mapping[str, float] | None,
) -> tuple[dict[str, FactorState], dict[str, str], bool]:
    """Flatness, smallness and minor-contributor flags of every factor."""
    names = list(levels)
    flat, small, minor, texts = {}, {}, {}, {}
    for name in names:
        sn = np.asarray(sn_means[name], dtype=float)
        finite = sn[np.isfinite(sn)]
        delta = float(finite.max() - finite.min()) if finite.size else 0.0
        flat[name] = delta < options.significance_db
        small[name] = relative_span(levels[name]) <= options.tolerance
        share = None if contribution is None else contribution.get(name, 100.0)
        minor[name] = share is not None and share < options.min_contribution
        texts[name] = f"ANOVA contribution {share:.2g} %" if minor[name] else ""
    converged = all(flat.values()) and all(small.values())
    choose_flat = {n: flat[n] or minor[n] for n in names}
    any_significant = not all(choose_flat.values())
    states = {
        n: FactorState(choose_flat[n], small[n], minor[n], any_significant, converged)
        for n in names
    }
    return states, texts, converged


def _fmt_range(values: Sequence[float]) -> str:
    return f"{min(values):.6g} .. {max(values):.6g}"


def relevel(
    levels: Mapping[str, Sequence[float]],
    sn_means: Mapping[str, Sequence[float]],
    options: LevelingOptions | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    centre: Mapping[str, float] | None = None,
    shrink: float | None = None,
    contribution: Mapping[str, float] | None = None,
    centre_label: str = "the best run",
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
        Override of ``options.shrink`` (1 keeps the width, to move a range without
        narrowing it).
    contribution : mapping of str to float, optional
        ANOVA percent contribution of each parameter, compared with
        ``options.min_contribution``.
    centre_label : str
        How the reasons name a run-based centre (e.g. ``"run 7"``).

    Returns
    -------
    LevelingDecision
        One :class:`FactorDecision` per parameter and whether the study converged
        (Case 3).

    Examples
    --------
    >>> d = relevel({"k": [1, 2, 3, 4, 5]}, {"k": [-30, -20, -10, -20, -30]})
    >>> d.parameters[0].case, d.parameters[0].levels
    ('recentre', [2.0, 2.5, 3.0, 3.5, 4.0])
    """
    options = options or LevelingOptions()
    if shrink is not None:
        options = LevelingOptions(**{**asdict(options), "shrink": shrink})
    bounds = dict(bounds or {})
    missing = [n for n in levels if n not in sn_means]
    if missing:
        raise StudyError(f"no S/N response for parameter(s) {', '.join(missing)}")
    states, minor_texts, converged = _states(levels, sn_means, options, contribution)
    decisions = [
        _relevel_one(
            name,
            levels[name],
            sn_means[name],
            states[name],
            options,
            bounds.get(name, (-math.inf, math.inf)),
            None if centre is None or name not in centre else float(centre[name]),
            centre_label,
            minor_texts[name],
        )
        for name in levels
    ]
    if converged:
        message = "Case 3: every S/N is flat and every range is within the tolerance"
    elif any(s.any_significant for s in states.values()):
        moving = [d.name for d in decisions if d.case in ("recentre", "shift")]
        message = "Case 1: S/N changes significantly for " + (", ".join(moving) or "none")
    else:
        message = "Case 2: every S/N is flat but some levels are still far apart"
    return LevelingDecision(parameters=decisions, converged=converged, message=message)


def _relevel_one(
    name: str,
    values: Sequence[float],
    sn_values: Sequence[float],
    state: FactorState,
    options: LevelingOptions,
    bounds: tuple[float, float],
    centre: float | None,
    centre_label: str,
    minor_text: str,
) -> FactorDecision:
    """:func:`relevel` for one parameter: work in log10 or linear units, make levels."""
    lv = np.asarray(values, dtype=float)
    order = np.argsort(lv)
    lv = lv[order]
    sn = np.asarray(sn_values, dtype=float)[order]
    log = use_log_scale(lv, options)
    if log and centre is not None and centre <= 0:
        log = False
    u = np.log10(lv) if log else lv
    bmin, bmax = bounds
    bu = (math.log10(bmin) if bmin > 0 else -math.inf, math.log10(bmax)) if log else bounds
    run_centre = None
    if centre is not None:
        value_u = math.log10(centre) if log else centre
        run_centre = (value_u, f"{centre_label} ({centre:.6g})")
    decision, centre_u, half = decide_factor(
        name, u, sn, state, options, centre=run_centre, bounds=bu, minor_text=minor_text
    )
    decision.best_level = int(order[decision.best_level])
    n_next = options.n_levels or len(lv)
    if decision.case in ("converged", "keep"):
        new = [float(v) for v in lv]
    else:
        new = _levels_about(centre_u, half, n_next, log, (bmin, bmax), options)
    to_value = (lambda x: float(10.0**x)) if log else float
    decision.optimum = round_sig(min(max(to_value(centre_u), bmin), bmax))
    decision.levels = new
    decision.reason = f"{decision.reason}; next levels {_fmt_range(new)}"
    return decision


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
        with np.errstate(over="ignore", under="ignore"):  # beyond float range: bounds clip
            lo, hi = np.power(10.0, lo_u), np.power(10.0, hi_u)
        # keep geometric spacing only while the new range still spans decades (compared
        # in decades: lo may underflow to 0, and hi / lo was a division by zero)
        keep_log = options.scale == "log" or hi_u - lo_u >= np.log10(options.log_ratio)
        return make_levels(float(lo), float(hi), n, log=keep_log, bounds=bounds)
    return make_levels(lo_u, hi_u, n, log=False, bounds=bounds)
