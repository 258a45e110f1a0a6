"""Nesting: whether a richer structure reproduces a simpler one's fit, and where.

Structure ``s`` is nested in ``r`` where ``r``'s parameters include ``s``'s
(:attr:`~tsid_fmu.search.structure.selection.Candidate.parameters`) and
``r``'s extra parameters reproduce ``s``'s fit; the fit that reproduces it is ``s``'s
answer **embedded** in ``r`` (:func:`embed` before ``r`` is refined, to start from;
:func:`nesting` at the answers). The extra parameters are first tried at values that
often nest (their lower bounds: a viscous coefficient of 0, which logarithmic search
coordinates reach only at minus infinity; and, before a refinement, a simpler
parameter's value in the same unit), then fitted by least squares, stopped at the first
point that reproduces the fit. A richer answer whose extra parameters sit where they
make it the simpler structure is that structure (:func:`at_nesting_point`).
:mod:`tsid_fmu.search.structure.optima` uses these to keep every candidate at its optimum.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.numerics.fdstep import forward_jacobian, relative_steps
from tsid_fmu.numerics.lsq import trust_region
from tsid_fmu.numerics.tuning import FAR_BETTER, NESTING_POINT, REPRODUCE
from tsid_fmu.search.space import Space
from tsid_fmu.search.structure.selection import Candidate
from tsid_fmu.study.definition import Study
from tsid_fmu.study.units import study_units

__all__ = [
    "FAR_BETTER",
    "NESTING_POINT",
    "REPRODUCE",
    "at_nesting_point",
    "embed",
    "known",
    "nesting",
    "slack",
]


def _space(study: Study) -> Space:
    return Space(study.first_levels(), study.bounds(), study.method.leveling)


def _reproduce(
    ev: Any, study: Study, small: Candidate, big: Candidate, anywhere: bool = False
) -> tuple[bool, dict[str, float]]:
    """Whether ``big`` reproduces ``small``'s fit with its extra parameters; the embedding.

    The nesting values nearest ``big``'s answer: each extra parameter that lies near its
    lower bound (:func:`_near_bounds`) moved onto it where that comes closer
    (:func:`_at_bounds`, one run each), the others fitted by least squares from
    ``big``'s values; where that does not reproduce it, all of them fitted from there.
    A fit of them all first walked a viscous coefficient of 0.006 towards its bound, 0,
    for 79 runs (law 3's answer at law 1's, SISO friction laws, dev seed 102). Moving
    every extra parameter that came closer, not only those near it, put the Stribeck
    velocity on its bound too, far from the answer's, and law 3 was chosen on law-1 data
    (dev seed 101).

    With ``anywhere`` (any nesting values will do), every extra parameter on its lower
    bound is tried first, in one run: a term switched off by a coefficient of 0 nests
    there (measured on the SISO friction laws: law 1 in law 2 at ``F_vm = 0``, where the
    least squares in logarithmic coordinates took 20 to 60 runs). Then each extra
    parameter is moved to the nesting value that reproduces best (:func:`_at_values`:
    its lower bound, or a simpler parameter's value in the same unit), the others
    fitted from there; where that does not reproduce it, all of them fitted from the
    start.
    """
    extra = [n for n in big.parameters if n not in small.active]
    base = {**big.x, **{n: small.x[n] for n in small.active}}
    tol = REPRODUCE * small.chi2 / max(small.n, 1)
    if not anywhere:  # the nesting values nearest the answer
        moved = dict(base)
        near = _near_bounds(study, base, extra)
        if near:
            rest, gap = _at_bounds(ev, study, moved, near, small.residuals)
            if gap <= tol:
                return True, moved
            free = [n for n in extra if n not in near or n in rest]
            if free != extra:
                ok, point = _fit_extra(ev, study, small, moved, free, tol)
                if ok:
                    return True, point
        return _fit_extra(ev, study, small, base, extra, tol)
    bounds = study.bounds()
    low = {**base, **{n: float(bounds[n][0]) for n in extra}}
    finite = all(math.isfinite(low[n]) for n in extra)
    if finite and _gap(ev, low, small.residuals) <= tol:
        return True, low
    moved = dict(base)
    rest, gap = _at_values(ev, study, small, moved, extra)
    if gap <= tol:
        return True, moved
    if rest and rest != extra:
        ok, point = _fit_extra(ev, study, small, moved, rest, tol)
        if ok:
            return True, point
    return _fit_extra(ev, study, small, base, extra, tol)


def _nesting_values(
    study: Study, small: Candidate, name: str, units: Mapping[str, str]
) -> list[float]:
    """Return the values of extra parameter ``name`` that often make a structure a simpler one.

    Its finite lower bound (a coefficient of 0 switches a term off), and the simpler
    answer's values of its parameters in the same unit (``units``), within ``name``'s
    bounds (a static friction force equal to the Coulomb force switches the Stribeck
    effect off; a second time constant equal to the first adds nothing).
    """
    lo, hi = study.bounds()[name]
    out = [float(lo)] if math.isfinite(lo) else []
    unit = units.get(name)
    for m in small.active:
        v = float(small.x[m])
        if unit and units.get(m) == unit and lo <= v <= hi and v not in out:
            out.append(v)
    return out


def _at_values(
    ev: Any, study: Study, small: Candidate, base: dict[str, float], extra: list[str]
) -> tuple[list[str], float]:
    """Move each extra parameter to the nesting value that reproduces best, if any does.

    Each extra parameter in turn is set (in ``base``, in place) to the one of its
    :func:`_nesting_values` at which the outputs come closest to ``small``'s, where
    that is closer than before (one run a value). Measured on the SISO friction laws
    (law-1 data): law 1's answer embedded in law 3 (``F_vm = 0``, ``F_sm = F_cm``),
    exactly, in 7 runs (dev seeds 102 and 107); a least-squares fit of the three extra
    parameters took 82 and 163 runs (dev seeds 101 and 102), and failed after 121 (107).
    Returns the parameters not moved and the sum of squares of the outputs' difference
    at ``base``.
    """
    units = study_units(study)  # the FMU's model description, read once
    values = {n: _nesting_values(study, small, n, units) for n in extra}
    return _move(ev, base, values, small.residuals)


def _near_bounds(study: Study, x: Mapping[str, float], names: list[str]) -> list[str]:
    """Return those of ``names`` that lie near a finite lower bound at ``x``.

    Within :data:`NESTING_POINT` of their first levels' range: moved onto the bound,
    they stay at the nesting point.
    """
    levels, bounds = study.first_levels(), study.bounds()
    return [
        n
        for n in names
        if math.isfinite(bounds[n][0]) and _apart(levels[n], x[n], bounds[n][0]) < NESTING_POINT
    ]


def _apart(levels: Sequence[float], a: float, b: float) -> float:
    """Return ``|a - b|`` as a fraction of the first levels' range (linear: a value may be 0)."""
    return abs(a - b) / max(max(levels) - min(levels), 1e-300)


class _Reproduced(Exception):
    """Raised inside the least-squares fit once the gap is within the tolerance."""


def _fit_extra(
    ev: Any,
    study: Study,
    small: Candidate,
    base: dict[str, float],
    extra: list[str],
    tol: float,
) -> tuple[bool, dict[str, float]]:
    """Fit ``extra`` (from ``base``) to reproduce ``small``'s outputs.

    Returns whether the gap (sum of squares of the outputs' difference) came within
    ``tol``, and the point. The fit stops at the first point within ``tol``: a nesting
    value on a bound that logarithmic coordinates reach only at minus infinity is
    approached without end, and measured on the SISO friction laws a fit run to its
    limit cost 40 to 80 runs where the gap was within ``tol`` after a few.
    """
    r_small = small.residuals
    space = _space(study)
    bad = np.full(r_small.shape, 1e6)
    idx = [space.names.index(n) for n in extra]

    def at(s: np.ndarray) -> dict[str, float]:
        return {
            **base,
            **{n: space.value(j, float(v)) for n, j, v in zip(extra, idx, s, strict=True)},
        }

    def gaps(points: list[np.ndarray]) -> list[np.ndarray]:
        rs = ev.evaluate([at(s) for s in points]).residuals or [None] * len(points)
        out = []
        for s, r in zip(points, rs, strict=True):
            d = bad if r is None else r - r_small
            if float(d @ d) <= tol:
                raise _Reproduced(s)
            out.append(d)
        return out

    last: list[tuple[np.ndarray, np.ndarray]] = []

    def diff(s: np.ndarray) -> np.ndarray:
        last[:] = [(np.array(s, dtype=float), gaps([s])[0])]
        return last[0][1]

    def jac(s: np.ndarray) -> np.ndarray:
        d = last[0][1] if last and np.array_equal(last[0][0], s) else diff(s)
        return forward_jacobian(gaps, s, d, relative_steps(s), upper=hi, lower=lo)

    start = np.array([space.coordinate(j, base[n]) for n, j in zip(extra, idx, strict=True)])
    lo = np.array([space.s_lower[j] for j in idx])
    hi = np.array([space.s_upper[j] for j in idx])
    fit = trust_region(
        diff,
        np.clip(start, lo, hi),
        jac,
        bounds=(lo, hi),
        stops=(_Reproduced,),
        max_nfev=20 * (len(extra) + 1),
    )
    if isinstance(fit.raised, _Reproduced):
        return True, at(np.asarray(fit.raised.args[0]))
    if fit.x is None or fit.fun is None:  # SciPy could not go on: not reproduced
        return False, at(np.clip(start, lo, hi))
    return float(fit.fun @ fit.fun) <= tol, at(fit.x)


def _gap(ev: Any, x: Mapping[str, float], r_small: np.ndarray) -> float:
    """Return the sum of squares of the outputs' difference from ``r_small`` at ``x`` (one run)."""
    r = ev.evaluate([dict(x)]).residuals
    return math.inf if not r or r[0] is None else float(np.sum((r[0] - r_small) ** 2))


def _at_bounds(
    ev: Any, study: Study, base: dict[str, float], extra: list[str], r_small: np.ndarray
) -> tuple[list[str], float]:
    """Move each extra parameter to its lower bound where that reproduces better.

    A nesting value often sits on a bound (a viscous coefficient of 0), which search
    coordinates spaced logarithmically reach only at minus infinity. Each extra
    parameter in turn is set to its finite lower bound in ``base`` (in place) where the
    outputs come closer to ``small``'s there (one run each). Returns the others and the
    sum of squares of the outputs' difference at ``base``.
    """
    bounds = study.bounds()
    values = {n: [float(bounds[n][0])] if math.isfinite(bounds[n][0]) else [] for n in extra}
    return _move(ev, base, values, r_small)


def _move(
    ev: Any, base: dict[str, float], values: Mapping[str, list[float]], r_small: np.ndarray
) -> tuple[list[str], float]:
    """Set each parameter of ``values``, in turn, to its value that reproduces best.

    In ``base`` (in place), where the outputs come closer to ``r_small``'s than before
    (one run a value, and one at ``base``). Returns the parameters not moved and the sum
    of squares of the outputs' difference at ``base``.
    """
    now, rest = _gap(ev, base, r_small), []
    for n, candidates in values.items():
        best = None
        for v in candidates:
            g = _gap(ev, {**base, n: v}, r_small) if v != base[n] else math.inf
            if g < now:
                now, best = g, v
        if best is None:
            rest.append(n)
        else:
            base[n] = best
    return rest, now


def embed(
    ev: Any, study: Study, small: Candidate, active: Sequence[str], x: Mapping[str, float]
) -> tuple[bool, dict[str, float]]:
    """Embed ``small``'s answer in a richer structure not yet refined (its free ``active``).

    As :func:`nesting` checks a pair, from ``x`` (the richer structure's start) instead of
    its answer: whether its extra parameters reproduce ``small``'s fit, and the point
    that does (``small``'s answer embedded: a start whose cost is ``small``'s). Any
    nesting values will do: every extra parameter on its lower bound is tried first.
    """
    big = Candidate("", {}, dict(x), math.inf, math.inf, 1, len(active), list(active))
    return _reproduce(ev, study, small, big, anywhere=True)


def nesting(
    cands: Sequence[Candidate],
    studies: Sequence[Study],
    evs: Sequence[Any],
    cache: dict | None = None,
    settled: set[int] | frozenset[int] = frozenset(),
) -> dict[tuple[int, int], dict[str, float]]:
    """Return the nested pairs, each with the simpler answer embedded in the richer.

    A pair ``(s, r)``: ``r``'s free parameters include ``s``'s and ``r`` reproduces
    ``s``'s fit; its value is ``s``'s answer embedded in ``r``.

    ``cache`` keeps the checks already made (keyed by both answers), for the rounds of
    :func:`consistent`, and the embeddings found of each simpler answer (keyed by the
    pair and that answer alone: :func:`known`). Where the richer answer fits far better
    (:data:`FAR_BETTER`), such an embedding is the pair's, with no fit at the richer
    answer: the embedding nearest it matters only at a nesting point
    (:func:`at_nesting_point`). Where no such embedding is known and the simpler
    answer is ``settled`` (shown to be an optimum), the pair is not checked: nothing
    turns on it. The richer answer is not above the simpler one, the simpler one is
    not followed from it, and the likelihood-ratio test and BIC both prefer the richer
    one (its statistic is at least ``n ln 2``).
    """
    cache = {} if cache is None else cache
    pairs = {}
    for s, r in ((s, r) for s in range(len(cands)) for r in range(len(cands)) if s != r):
        small, big = cands[s], cands[r]
        # on the structures' parameters, not on those acting at the answers: a richer
        # answer whose extra term ended switched off acts as the simpler structure
        if not _richer(small, big) or not small.n or not big.n:
            continue
        answer = tuple(sorted(small.x.items()))
        key = (s, r, answer, tuple(sorted(big.x.items())))
        found = cache.get((s, r, answer))
        if key not in cache and big.chi2 < FAR_BETTER * small.chi2:
            if found is None and s in settled:
                continue
            if found is not None:
                cache[key] = (True, found)
        if key not in cache:
            ev = evs[r].get(studies[r].parameter_names, studies[r].identify_names(), {})
            n0 = ev.nfev
            cache[key] = _reproduce(ev, studies[r], small, big)
            big.nfev += ev.nfev - n0
        ok, embedded = cache[key]
        if ok:
            pairs[(s, r)] = embedded
            cache.setdefault((s, r, answer), embedded)
    return pairs


def _richer(small: Candidate, big: Candidate) -> bool:
    """Whether ``big``'s structure has ``small``'s acting parameters and more."""
    return set(small.active) <= set(big.parameters) and set(small.parameters) < set(big.parameters)


def known(cache: dict, s: int, r: int, small: Candidate, embedded: Mapping[str, float]) -> None:
    """Keep in a :func:`nesting` cache an embedding of ``s``'s answer in ``r`` found before."""
    cache[(s, r, tuple(sorted(small.x.items())))] = dict(embedded)


def at_nesting_point(study: Study, small: Candidate, big: Candidate, embedded: Mapping) -> bool:
    """Whether ``big``'s extra parameters sit where they make it ``small``'s structure.

    Each within :data:`NESTING_POINT` of its first levels' range (linear: a nesting value
    may be 0) of the embedding: the richer answer is then the simpler structure, and a
    lower cost there comes from the model's non-smoothness at that point (event timings),
    not from what the extra parameters add.
    """
    levels = study.first_levels()
    extra = [n for n in big.parameters if n not in small.active]
    gaps = [_apart(levels[n], big.x[n], embedded[n]) for n in extra]
    return bool(gaps) and max(gaps) < NESTING_POINT


def slack(small: Candidate) -> float:
    """How far above ``small``'s chi-square an embedding of its answer may lie.

    An embedding reproduces ``small``'s noise-weighted outputs to within ``tol =``
    :data:`REPRODUCE` ``* chi2 / n`` in sum of squares; its chi-square is then at most
    ``(sqrt(chi2) + sqrt(tol))**2``. A richer answer above ``small``'s by less already
    reproduces its fit, and a restart from an embedding cannot do better.
    """
    tol = REPRODUCE * small.chi2 / max(small.n, 1)
    return 2.0 * math.sqrt(max(small.chi2, 0.0) * tol) + tol
