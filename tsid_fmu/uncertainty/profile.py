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
many degrees of freedom). The re-fit is a chord Gauss-Newton iteration, which follows
the stiff directions cheaply; each profile point costs a few simulations. Its Jacobian
starts as the answer's and is corrected by every simulation (Broyden's secant rule),
and a doubling that passes the threshold is checked re-linearised (:class:`_Secant`,
at most :data:`CHECKS` times a side): where the model has events, the answer's Jacobian
is far off away from it, and chord steps with it alone overstated the rise and made the
intervals too narrow (measured on the SISO rig). Only for the ``sse`` cost (for which
the cost is a log-likelihood).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.numerics.fdstep import forward_jacobian, known_noise, steps_for
from tsid_fmu.numerics.space import Space
from tsid_fmu.numerics.tuning import (
    BISECTIONS,
    CHECK_STEP,
    CHECKS,
    CHI2_95,
    CHORD_STEPS,
    MAX_DOUBLINGS,
    MIN_STEP,
    RESOLUTION,
    SECANT_MIN,
)
from tsid_fmu.uncertainty.intervals import seen_inverse

__all__ = ["CHI2_95", "RESOLUTION", "ProfileProblem", "profile_intervals"]


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

    def residuals(self, points: list[np.ndarray]) -> list[np.ndarray]:
        """Return the cost residuals at ``points``, one batch; raise if a run fails."""
        ev = self.evaluator.evaluate([self.space.to_x(s) for s in points])
        rs = ev.residuals or [None] * len(points)
        if any(r is None for r in rs) or not np.isfinite(ev.costs[:, 0]).all():
            raise _Failed
        return [np.asarray(r, dtype=float) for r in rs]


class _Failed(Exception):
    """A run of a Jacobian's batch failed."""


class _Secant:
    """The Jacobian one side's profile re-fits with, corrected by every simulation.

    Starts as the answer's; each new point updates it by Broyden's rank-one secant
    rule along the step from the last point, at no extra simulation. On the SISO rig
    (dev seeds 101-112) that cut the intervals' simulations by 16 % (median 246 against
    294 with the checks alone) for the same ends. Steps shorter than :data:`SECANT_MIN`
    leave it as it is; :meth:`relinearise` replaces it where a bracket is checked.
    """

    def __init__(self, problem: ProfileProblem, j: int) -> None:
        self.others = [k for k in range(problem.s0.size) if k != j]
        self.jac = problem.jacobian.copy()
        self.s = problem.s0.copy()  # the last point simulated and its residuals
        self.r: np.ndarray | None = None
        self.start = problem.s0.copy()  # the best re-fit of the last offset, its residuals
        self.start_r: np.ndarray | None = None
        self._pinv: np.ndarray | None = None

    @property
    def pinv(self) -> np.ndarray:
        """Pseudo-inverse of the other parameters' columns."""
        if self._pinv is None:
            self._pinv = seen_inverse(self.jac[:, self.others])
        return self._pinv

    def update(self, s: np.ndarray, r: np.ndarray) -> None:
        """Take the point ``s`` with residuals ``r`` as the last one."""
        if self.r is not None:
            ds = s - self.s
            if np.linalg.norm(ds) >= SECANT_MIN:
                change = np.outer(r - self.r - self.jac @ ds, ds) / (ds @ ds)
                if np.isfinite(change).all():
                    self.jac += change
                    self._pinv = None
        self.s, self.r = s.copy(), np.asarray(r, dtype=float)

    def relinearise(self, problem: ProfileProblem) -> bool:
        """Replace the Jacobian by forward differences at the best re-fit (one run a column).

        Returns False, leaving it as it was, where a run fails.
        """
        s0, r0 = self.start, self.start_r
        if r0 is None:
            return False
        # where the FMU's own solver is noisy, steps that beat its noise (one rule with
        # the refinement's Jacobian, :mod:`tsid_fmu.numerics.fdstep`)
        wide = steps_for(np.full(s0.size, CHECK_STEP), self.jac, known_noise(problem.evaluator))
        try:
            jac = forward_jacobian(problem.residuals, s0, r0, wide, problem.space.s_upper)
        except _Failed:
            return False
        self.jac, self._pinv = jac, None
        self.s, self.r = s0.copy(), r0
        return True


def _refit(problem: ProfileProblem, j: int, delta: float, secant: _Secant, limit: float) -> float:
    """Lowest cost found with coordinate ``j`` moved by ``delta``, the others re-fitted.

    Chord Gauss-Newton steps with ``secant``'s Jacobian, from the best re-fit of the
    last offset; the re-fit stops once a step gains less than 1 % of the threshold
    ``limit``.
    """
    others = secant.others
    s = secant.start.copy()
    shift = problem.s0[j] + delta - s[j]
    s[j] += shift
    s[others] -= secant.pinv @ (secant.jac[:, j] * shift)
    best = math.inf
    for _ in range(CHORD_STEPS + 1):
        s = np.clip(s, problem.space.s_lower, problem.space.s_upper)
        cost, r = problem.cost(s)
        if r is None or not math.isfinite(cost):
            break
        secant.update(s, r)
        if cost < best:
            secant.start, secant.start_r = s.copy(), secant.r
        if best - cost < 0.01 * limit:
            best = min(best, cost)
            break
        best = cost
        s[others] -= secant.pinv @ r
    return best


def _end(
    problem: ProfileProblem, j: int, sign: float, step: float, limit: float
) -> tuple[float, bool]:
    """Coordinate offset of the interval's end on one side (``inf``: not reached).

    The end is where the cost has risen by ``limit``: the steps double until the rise
    exceeds it, :data:`BISECTIONS` bisections narrow that bracket, and the end is
    interpolated in it (:func:`_crossing`). An end within the first step is not: its
    bracket lies below the first step, where the rises compare offsets the simulations
    may not resolve (:data:`MIN_STEP`), and the bracket's outer end is kept as a bound.
    The flag is False where no point inside the interval was found: the end is then only
    known to lie within the offset returned.

    A doubling's rise above ``limit`` is checked, at most :data:`CHECKS` times a side:
    the Jacobian is re-linearised at that offset's best re-fit and the re-fit repeated;
    where it then rises less, the doublings go on.
    """
    secant = _Secant(problem, j)
    inside, rise_in, rise = 0.0, 0.0, 0.0
    delta, checks = step, 0
    for _ in range(MAX_DOUBLINGS):
        target = problem.s0[j] + sign * delta
        if not problem.space.s_lower[j] - 1.0 <= target <= problem.space.s_upper[j] + 1.0:
            return math.inf, True
        rise = _refit(problem, j, sign * delta, secant, limit) - problem.cost0
        if rise > limit and checks < CHECKS and secant.relinearise(problem):
            checks += 1
            rise = min(rise, _refit(problem, j, sign * delta, secant, limit) - problem.cost0)
        if rise > limit:
            break
        inside, rise_in, delta = delta, rise, 2 * delta
    else:
        return math.inf, True
    outside, rise_out, doubled = delta, rise, inside > 0
    for _ in range(BISECTIONS):
        mid = 0.5 * (inside + outside)
        rise = _refit(problem, j, sign * mid, secant, limit) - problem.cost0
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
    for j, name in enumerate(problem.space.names):
        step = steps.get(name, MIN_STEP)
        step = max(step, MIN_STEP) if math.isfinite(step) else MIN_STEP
        ends, resolved = [], []
        limit = problem.thresholds.get(name, problem.threshold)
        for sign in (-1.0, 1.0):
            off, found = _end(problem, j, sign, step, limit)
            s = problem.s0[j] + sign * off
            ends.append(None if not math.isfinite(off) else problem.space.value(j, s))
            resolved.append(found)
        out[name] = ends
        if not any(resolved):
            problem.unresolved.add(name)
    return out
