"""Profile-likelihood intervals: how far each parameter can move before the data object.

The Fisher matrix describes the cost surface by its curvature at the answer. Where the
model has events (dry friction) the finite-difference Jacobian carries small errors,
and where two parameters act almost only through their sum (a knife-edge valley) those
errors decide the curvature along the valley: the Fisher matrix then claims a precision
the data do not have. The profile of a parameter does not rely on that curvature: it
moves the parameter away from the answer, re-fits the others, and finds where the cost
has risen by the threshold of a 95 % interval,

    profile(theta_j) - cost_min = t_nu(0.975)^2 * s^2 * inflation_j^2,

``s^2 = cost_min / (n - p)`` the residual variance of the weighted fit (1 when the
residuals are at the noise level), ``inflation_j`` how much time-correlated residuals
widen the parameter's standard error and ``nu`` the degrees of freedom of its variance
(:mod:`tsid_fmu.uncertainty.intervals`; ``t_nu^2`` is the F(1, nu) quantile, the
threshold of Bates and Watts' profile t, and ``chi2_1(0.95)`` = :data:`CHI2_95` for
many degrees of freedom). The re-fit is a
chord Gauss-Newton iteration with the Jacobian of the answer, which follows the stiff
directions cheaply; each profile point costs a few simulations. Only for the ``sse``
cost (for which the cost is a log-likelihood).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.search.space import Space

__all__ = ["CHI2_95", "RESOLUTION", "ProfileProblem", "profile_intervals"]

CHI2_95 = 3.841458820694124
"""95 % quantile of the chi-square distribution with one degree of freedom."""

CHORD_STEPS = 6
"""Most Gauss-Newton chord steps of the re-fit at each profile point; the re-fit stops
earlier once a step lowers the cost by less than 1 % of the threshold."""

MAX_DOUBLINGS = 10
"""Steps out from the answer, each twice the last, before an end is called open."""

MIN_STEP = 1e-3
"""Smallest first step, in search coordinates (0.1 % of a first range): a profile that
starts below what the simulations resolve would only measure their numerical noise."""

BISECTIONS = 3
"""Bisections of the bracket around an interval end."""

RESOLUTION = MIN_STEP / 2**BISECTIONS
"""Shortest distance to an interval end the profile can tell, in search coordinates:
an end closer than the first step and every bisection of it is only known to lie
within this of the answer."""


@dataclass
class ProfileProblem:
    """The weighted least-squares problem at the answer.

    Attributes
    ----------
    evaluator : Evaluator
        Scores parameter sets; its residuals' squares sum to the cost.
    space : Space
        Search coordinates of the parameters (the profile moves in them).
    s0 : numpy.ndarray
        The answer's coordinates.
    cost0 : float
        The answer's cost.
    jacobian : numpy.ndarray
        ``(n, p)`` derivative of the cost residuals with respect to the coordinates.
    threshold : float
        Rise of the cost that bounds the 95 % interval.
    thresholds : dict
        The rise for some parameters, where it differs from ``threshold``.
    unresolved : set of str
        Filled by :func:`profile_intervals`: the parameters whose ends both lie within
        the last bisection of the first step (within :data:`RESOLUTION` for the smallest
        step): their profile interval is only an upper bound.
    """

    evaluator: Evaluator
    space: Space
    s0: np.ndarray
    cost0: float
    jacobian: np.ndarray
    threshold: float
    thresholds: dict[str, float] = field(default_factory=dict)
    unresolved: set[str] = field(default_factory=set)

    def cost(self, s: np.ndarray) -> tuple[float, np.ndarray | None]:
        """Return the cost and the cost residuals at coordinates ``s``."""
        ev = self.evaluator.evaluate([self.space.to_x(s)])
        r = ev.residuals[0] if ev.residuals else None
        return float(ev.costs[0, 0]), r


def _refit(problem: ProfileProblem, j: int, delta: float, pinv: np.ndarray, limit: float) -> float:
    """Lowest cost found with coordinate ``j`` moved by ``delta``, the others re-fitted.

    The re-fit stops once a step gains less than 1 % of the threshold ``limit``.
    """
    others = [k for k in range(problem.s0.size) if k != j]
    s = problem.s0.copy()
    s[j] += delta
    s[others] -= pinv @ (problem.jacobian[:, j] * delta)
    best = math.inf
    for _ in range(CHORD_STEPS + 1):
        s = np.clip(s, problem.space.s_lower, problem.space.s_upper)
        cost, r = problem.cost(s)
        if r is None or not math.isfinite(cost) or best - cost < 0.01 * limit:
            best = min(best, cost)
            break
        best = cost
        s[others] -= pinv @ r
    return best


def _end(
    problem: ProfileProblem, j: int, sign: float, step: float, pinv: np.ndarray, limit: float
) -> tuple[float, bool]:
    """Coordinate offset of the interval's end on one side (``inf``: not reached).

    The end is where the cost has risen by ``limit``: the steps double until the rise
    exceeds it, :data:`BISECTIONS` bisections narrow that bracket, and the end is
    interpolated in it (:func:`_crossing`). An end within the first step is not: its
    bracket lies below the first step, where the rises compare offsets the simulations
    may not resolve (:data:`MIN_STEP`), and the bracket's outer end is kept as a bound.
    The flag is False where no point inside the interval was found: the end is then only
    known to lie within the offset returned.
    """
    inside, rise_in, rise = 0.0, 0.0, 0.0
    delta = step
    for _ in range(MAX_DOUBLINGS):
        target = problem.s0[j] + sign * delta
        if not problem.space.s_lower[j] - 1.0 <= target <= problem.space.s_upper[j] + 1.0:
            return math.inf, True
        rise = _refit(problem, j, sign * delta, pinv, limit) - problem.cost0
        if rise > limit:
            break
        inside, rise_in, delta = delta, rise, 2 * delta
    else:
        return math.inf, True
    outside, rise_out, doubled = delta, rise, inside > 0
    for _ in range(BISECTIONS):
        mid = 0.5 * (inside + outside)
        rise = _refit(problem, j, sign * mid, pinv, limit) - problem.cost0
        if rise > limit:
            outside, rise_out = mid, rise
        else:
            inside, rise_in = mid, rise
    if not doubled:
        return outside, inside > 0
    return _crossing(inside, rise_in, outside, rise_out, limit), True


def _crossing(
    inside: float, rise_in: float, outside: float, rise_out: float, limit: float
) -> float:
    """Offset where the rise reaches ``limit`` between a bracket's ends, interpolated.

    Linear in the root of the rise (the profile t): where the model is linear near the
    answer the rise is quadratic in the offset and this is exact; otherwise it stays
    within the bracket. Returning the bracket's outer end instead made the intervals
    systematically wide (by up to an eighth of the last doubling).
    """
    low, high = math.sqrt(max(rise_in, 0.0)), math.sqrt(rise_out)
    if not math.isfinite(high):
        return outside
    return inside + (math.sqrt(limit) - low) / (high - low) * (outside - inside)


def profile_intervals(
    problem: ProfileProblem, steps: Mapping[str, float]
) -> dict[str, list[float | None]]:
    """95 % profile intervals of every parameter, in parameter units.

    Parameters
    ----------
    problem : ProfileProblem
        The least-squares problem at the answer.
    steps : mapping
        First step out from the answer of each parameter, in search coordinates (its
        standard error is a good one).

    Returns
    -------
    dict
        ``{name: [low, high]}``; an end the profile does not reach within
        :data:`MAX_DOUBLINGS` doublings, or beyond the bounds, is ``None``. The
        parameters neither of whose ends was bracketed from inside go into
        ``problem.unresolved``.
    """
    out: dict[str, list[float | None]] = {}
    jac = problem.jacobian
    for j, name in enumerate(problem.space.names):
        others = [k for k in range(jac.shape[1]) if k != j]
        pinv = np.linalg.pinv(jac[:, others]) if others else np.zeros((0, jac.shape[0]))
        step = steps.get(name, MIN_STEP)
        step = max(step, MIN_STEP) if math.isfinite(step) else MIN_STEP
        ends, resolved = [], []
        limit = problem.thresholds.get(name, problem.threshold)
        for sign in (-1.0, 1.0):
            off, found = _end(problem, j, sign, step, pinv, limit)
            s = problem.s0[j] + sign * off
            ends.append(None if not math.isfinite(off) else problem.space.value(j, s))
            resolved.append(found)
        out[name] = ends
        if not any(resolved):
            problem.unresolved.add(name)
    return out
