"""Choosing among candidate structures, each refined to its own optimum.

Each structure ``s`` has its noise-weighted residuals at its optimum, ``r_i = e_i /
sigma_i`` (the residuals the study's cost already uses: each output divided by its
noise, or by its weight's scale), their sum of squares ``chi2_s`` over ``n`` residuals,
and ``k_s`` free Real parameters (those that change the outputs in that structure).

The likelihood is Gaussian with those relative weights and one common, unknown scale
``s^2`` (the noise levels may be off by a common factor; its estimate is ``chi2/n``)::

    -2 ln L = n ln(chi2 / n) + n (1 + ln 2 pi) + 2 sum ln sigma_i

The last two terms are the same for every structure and are left out:

    AIC = n ln(chi2 / n) + 2 (k + 1)
    BIC = n ln(chi2 / n) + (k + 1) ln n

For a structure ``S`` nested in a richer ``R`` (``R`` reproduces ``S`` with its extra
parameters at some value), the likelihood-ratio statistic is ``n ln(chi2_S / chi2_R)``,
chi-square with ``k_R - k_S`` degrees of freedom under ``S``.

The decision (:func:`decide`): the structure with the lowest BIC, except that between
nested structures the likelihood-ratio test decides (the richer one only where ``p <``
:data:`LRT_ALPHA`). Two structures whose BIC differ by less than :data:`BIC_CLOSE` and
whose ``chi2`` differ by less than their noise (``sqrt(2 n)`` in units of ``chi2 / n``)
are **indistinguishable**: the result says so, and reports the simpler one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.numerics.tuning import BIC_CLOSE, LRT_ALPHA

__all__ = [
    "BIC_CLOSE",
    "LRT_ALPHA",
    "Candidate",
    "decide",
    "information",
    "likelihood_ratio",
]


def information(chi2: float, n: int, k: int) -> tuple[float, float]:
    """Return (AIC, BIC) of a fit with ``chi2`` over ``n`` residuals and ``k`` parameters."""
    if n <= 0 or not chi2 > 0 or not math.isfinite(chi2):
        return math.inf, math.inf
    base = n * math.log(chi2 / n)
    return base + 2 * (k + 1), base + (k + 1) * math.log(n)


def likelihood_ratio(chi2_small: float, chi2_big: float, n: int, dof: int) -> tuple[float, float]:
    """Return the statistic and p-value of the LRT of a nested structure against a richer."""
    from scipy import stats

    if dof <= 0 or not (chi2_small > 0 and chi2_big > 0):
        return math.nan, math.nan
    stat = max(n * math.log(chi2_small / chi2_big), 0.0)
    return stat, float(stats.chi2.sf(stat, dof))


@dataclass
class Candidate:
    """One candidate structure at its own optimum.

    Attributes
    ----------
    label : str
        The structure, e.g. ``"friction=stribeck, damping=true"``.
    values : dict
        The number of each discrete factor.
    x : dict
        Its Real parameters at its optimum.
    cost : float
        The study's cost there.
    chi2, n, k : float, int, int
        Sum of squares of the noise-weighted residuals, their number, and the free
        Real parameters (``active``).
    active : list of str
        The Real parameters that change the outputs in this structure.
    nfev : int
        Simulations spent on it (its stages and the checks).
    origin : str
        Why it is a candidate (the arrays' choice, a runner-up, an open combination).
    validation : float or None
        Its cost on the validation experiments, where the study has some.
    aic, bic, lrt_p, lrt_against, chosen, why
        Filled by :func:`decide`.
    free : list of str
        The Real parameters free at the arrays' best point, off any bound.
    folder : str
        Its folder in the trail (``structure_NN``).
    tried : list of dict
        The start points it was refined from (a restart from one of them is not run
        again).
    residuals : numpy.ndarray or None
        Its noise-weighted residuals at ``x`` (None until measured).
    """

    label: str
    values: dict[str, float]
    x: dict[str, float]
    cost: float
    chi2: float
    n: int
    k: int
    active: list[str]
    nfev: int = 0
    origin: str = ""
    validation: float | None = None
    aic: float = math.nan
    bic: float = math.nan
    lrt_p: float = math.nan
    lrt_against: str = ""
    chosen: bool = False
    why: str = ""
    free: list[str] = field(default_factory=list)
    folder: str = ""
    tried: list[dict[str, float]] = field(default_factory=list)
    residuals: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def parameters(self) -> list[str]:
        """The Real parameters of its structure: free where the arrays saw it, or acting.

        ``active`` holds those that change the outputs at the answer; a parameter that
        ended at the value that switches its term off (a coefficient of 0 reached in
        logarithmic coordinates, 2e-16) changes nothing there, yet the structure has it.
        Nesting is judged on these (:mod:`~tsid_fmu.search.structure.nesting`).
        """
        free = list(self.free)
        return free + [n for n in self.active if n not in free]

    def row(self) -> dict[str, Any]:
        """Return the row of the structures table."""
        return {
            "structure": self.label,
            "cost": self.cost,
            "k": self.k,
            "AIC": self.aic,
            "BIC": self.bic,
            "LRT p": self.lrt_p,
            "LRT against": self.lrt_against,
            "validation cost": math.nan if self.validation is None else self.validation,
            "simulations": self.nfev,
            "chosen": self.chosen,
            "why": self.why,
            # the structure's choices and its own optimum, for tsid design's discrimination
            "values": dict(self.values),
            "x": dict(self.x),
        }


def _close(a: Candidate, b: Candidate) -> bool:
    """Whether two structures are indistinguishable: BIC within 2, costs within noise."""
    n = max(a.n, b.n, 1)
    noise = math.sqrt(2.0 * n) * min(a.chi2, b.chi2) / n
    return abs(a.bic - b.bic) < BIC_CLOSE and abs(a.chi2 - b.chi2) <= noise


def _lrt(small: Candidate, big: Candidate) -> float:
    """Return the p-value of a nested pair's LRT: never of 0 degrees of freedom.

    ``k`` counts the parameters each structure may move (not those that happen to act at
    its answer), so the richer one has more; a nested pair has at least one extra.
    """
    return likelihood_ratio(small.chi2, big.chi2, small.n, max(big.k - small.k, 1))[1]


def _nested_step(
    pick: int,
    cands: Sequence[Candidate],
    nested: set[tuple[int, int]],
    degenerate: set[tuple[int, int]],
) -> tuple[int, str] | None:
    """One application of the LRT rule to the current pick; None when it stands."""
    barred = {r for _, r in degenerate}
    for s, r in sorted(nested):
        small, big = cands[s], cands[r]
        p = 1.0 if (s, r) in degenerate else _lrt(small, big)
        extra = ", ".join(sorted(set(big.parameters) - set(small.active)))
        if r in barred and pick != r:
            continue  # never chosen: it is a simpler structure's point
        if pick == r and not p < LRT_ALPHA:
            return s, (
                f"nested in {big.label}, whose extra parameter(s) {extra} the data do not "
                f"support (LRT p = {p:.3g} >= {LRT_ALPHA:g})"
            )
        if pick == s and p < LRT_ALPHA:
            return r, (
                f"the data support its extra parameter(s) {extra} over {small.label}, which "
                f"it nests (LRT p = {p:.3g} < {LRT_ALPHA:g})"
            )
    return None


def decide(
    cands: Sequence[Candidate],
    nested: set[tuple[int, int]] | None = None,
    degenerate: set[tuple[int, int]] | None = None,
) -> tuple[int, list[int]]:
    """Choose a structure; fill each candidate's AIC, BIC, LRT and ``why``.

    Parameters
    ----------
    cands : sequence of Candidate
        The candidates (``chi2``, ``n``, ``k`` filled).
    nested : set of (int, int)
        Pairs ``(s, r)``: structure ``s`` is nested in the richer ``r``.
    degenerate : set of (int, int)
        Nested pairs whose richer answer sits at the nesting point (its extra
        parameters where they make it ``s``): the richer one does not win there, whatever
        its cost (a model not smooth at that point can fit a little better there).

    Returns
    -------
    chosen : int
        Index of the chosen structure.
    tied : list of int
        The structures indistinguishable from it (BIC within :data:`BIC_CLOSE`, costs
        within noise).
    """
    nested, degenerate = set(nested or ()), set(degenerate or ()) & set(nested or ())

    def lrt(s: int, r: int) -> float:
        return 1.0 if (s, r) in degenerate else _lrt(cands[s], cands[r])

    for c in cands:
        c.aic, c.bic = information(c.chi2, c.n, c.k)
        c.lrt_p, c.lrt_against = math.nan, ""  # a decision made again starts afresh
    barred = {r for _, r in degenerate}
    for s, r in nested:
        if r in barred and (s, r) not in degenerate:
            continue  # a barred answer is a simpler structure's point: no test against it
        p = lrt(s, r)
        for c, other in ((cands[s], cands[r]), (cands[r], cands[s])):
            if math.isnan(c.lrt_p) or p < c.lrt_p:
                c.lrt_p, c.lrt_against = p, other.label
    pool = [i for i in range(len(cands)) if i not in barred] or list(range(len(cands)))
    pick = min(pool, key=lambda i: (cands[i].bic, cands[i].k))
    others = sorted(c.bic for i, c in enumerate(cands) if i != pick and i not in barred)
    why = "the lowest BIC" + (
        f" ({others[0] - cands[pick].bic:.3g} below the next)" if others else ""
    )
    for _ in range(len(cands) * len(cands) + 1):
        step = _nested_step(pick, cands, nested, degenerate)
        if step is None:
            break
        pick, why = step
    for s, r in sorted(nested, key=lambda pair: (pair in degenerate, pair)):
        p = lrt(s, r)
        if s == pick and not p < LRT_ALPHA and "nested" not in why:
            extra = ", ".join(sorted(set(cands[r].parameters) - set(cands[s].active)))
            why += f"; nested in {cands[r].label}, whose extra parameter(s) {extra} " + (
                f"stay where they make it {cands[s].label}"
                if (s, r) in degenerate
                else f"the data do not support (LRT p = {p:.3g} >= {LRT_ALPHA:g})"
            )
    decided = {a if b == pick else b for a, b in nested if pick in (a, b) and lrt(a, b) < LRT_ALPHA}
    close = [
        i
        for i, c in enumerate(cands)
        if i != pick and i not in decided and i not in barred and _close(c, cands[pick])
    ]
    pick, tied, tie = _simplest(cands, [pick, *close])
    _explain(cands, pick, why, tied, barred, degenerate, tie)
    return pick, tied


def _simplest(cands: Sequence[Candidate], group: list[int]) -> tuple[int, list[int], str]:
    """Choose among indistinguishable structures; return it, the others, and why.

    One ranking decides and explains: fewer free parameters, then fewer parameters of
    the structure (:attr:`Candidate.parameters`: a term switched off at the answer
    still counts), then the lower BIC.
    """

    def size(i: int) -> tuple[int, int]:
        return cands[i].k, len(cands[i].parameters)

    pick = min(group, key=lambda i: (*size(i), cands[i].bic))
    tied = [i for i in group if i != pick]
    if all(size(pick) < size(j) for j in tied):
        return pick, tied, "the simpler is reported"
    simple = f"as simple ({cands[pick].k} free parameters each or fewer)"
    return pick, tied, f"{simple}: the lowest BIC is reported"


def _explain(
    cands: Sequence[Candidate],
    pick: int,
    why: str,
    tied: list[int],
    barred: set[int],
    degenerate: set[tuple[int, int]],
    tie: str = "the simpler is reported",
) -> None:
    """Mark the chosen candidate and write each candidate's ``why``.

    ``tie`` says what chose among the indistinguishable ones.
    """
    for i, c in enumerate(cands):
        c.chosen = i == pick
        if i == pick:
            c.why = (
                why
                if not tied
                else (
                    "indistinguishable from "
                    + ", ".join(cands[j].label for j in tied)
                    + f" (BIC within {BIC_CLOSE:g}, costs within noise): the data do not decide; "
                    + tie
                )
            )
        elif i in tied:
            c.why = f"indistinguishable from {cands[pick].label}: the data do not decide"
        elif i in barred:
            s = min(a for a, b in degenerate if b == i)
            c.why = (
                f"its extra parameter(s) stay where they make it {cands[s].label} (BIC "
                f"{c.bic - cands[pick].bic:+.4g} against {cands[pick].label}): its lower "
                "cost there is not theirs"
            )
        else:
            c.why = f"BIC {c.bic - cands[pick].bic:+.4g} against {cands[pick].label}"


def structures_frame(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Return the structures table as a :class:`pandas.DataFrame` indexed by structure."""
    import pandas as pd

    return pd.DataFrame(list(rows)).set_index("structure") if rows else pd.DataFrame()
