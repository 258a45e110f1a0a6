"""Whether an answer is shown to be an optimum, and whether its fit is as good as the noise.

A study reports "converged" (exit status 0) only where a stationarity test holds at its
answer; which test depends on what the last stage knows:

- after a least-squares refinement, the **projected Gauss-Newton test**: from the
  residuals ``r`` and the Jacobian ``J`` of the refinement's last linearisation, the
  Gauss-Newton step, restricted to the parameters that are not held at a bound by the
  gradient and cut short where it would leave the bounds, predicts the cost
  ``|r + J d|^2``. The test holds when it predicts a decrease of at most
  :data:`GATE_RTOL` of the cost: no first-order model of the cost sees a better point
  nearby. It costs no simulation.
- otherwise (a cost other than ``sse``, or ``refine = "none"``), the **local probe
  test**: the cost one convergence tolerance on either side of the answer along every
  parameter (``2 p`` simulations); it holds when no probe is lower. It shows an optimum
  at the resolution the levels converged to, and no finer.

:func:`noise_floor` gives the cost that residuals at the noise level would have; an
answer far above it (:data:`POOR_FIT` times) is a poor fit: a model that does not
explain the data, or a local minimum. Only a search that has shown its answer to be
stationary may blame the model for it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

import numpy as np

from tsid_fmu.evaluate.cost import noise_level
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.numerics.tuning import GATE_RTOL, MAX_TRIALS, POOR_FIT
from tsid_fmu.search.outcome import GN_TEST, GN_TRIED, Stationarity
from tsid_fmu.search.space import Space

__all__ = [
    "GATE_RTOL",
    "GN_TEST",
    "GN_TRIED",
    "LOWER_PROBED",
    "LOWER_TRIED",
    "POOR_FIT",
    "Stationarity",
    "bounded_step",
    "bounded_trials",
    "gauss_newton_gap",
    "gauss_newton_step",
    "gauss_newton_test",
    "noise_floor",
    "probe_points",
    "probe_test",
]


LOWER_TRIED = "tried, the step lowered the cost by"
"""How a failed stationarity test says that its step, simulated, found a lower point."""

LOWER_PROBED = "but a local probe lowered the cost by"
"""How a failed stationarity test says that, its step failing, a local probe was lower."""


def trial_fractions(jac: np.ndarray, r: np.ndarray, step: np.ndarray, gate: float) -> list[float]:
    """Return the fractions of ``step`` to simulate before calling an answer stationary.

    Where the Gauss-Newton model predicts more than ``gate`` but the step, simulated,
    does not lower the cost, the model may still be right closer in: its predicted
    decrease falls as the step shrinks (``2 f`` times the gap for small ``f``), and a
    descent direction lowers the cost at a small enough fraction. So the trial halves
    the step, 1, 1/2, 1/4, ..., down to the first fraction whose predicted decrease is
    at most ``gate`` (what the test would accept without a trial), and at most
    :data:`MAX_TRIALS` of them. An answer is stationary by trial only when none of them
    is lower and the last one reached the gate (:func:`trial_detail`).
    """
    cost = float(r @ r)
    move = jac @ step
    out, f = [], 1.0
    for _ in range(MAX_TRIALS):
        out.append(f)
        predicted = r + f * move
        if cost - float(predicted @ predicted) <= gate:
            break
        f /= 2.0
    return out


def bounded_step(
    jac: np.ndarray, r: np.ndarray, s: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> tuple[float, np.ndarray]:
    """Return the Gauss-Newton step within the bounds and the decrease it predicts.

    The bounded linear least-squares solution, every parameter together (SciPy's
    ``lsq_linear``): at a bound, one parameter's own gradient may point out of it while
    a step with the others compensating lowers the cost (viscous friction up, spring
    damping down), which the projected step (:func:`gauss_newton_step`) drops. Used at
    a nesting point (:mod:`~tsid_fmu.search.structure.boundary`) and on a log floor
    (:func:`bounded_trials`).
    """
    from scipy.optimize import lsq_linear

    r = np.asarray(r, float)
    step = lsq_linear(jac, -r, bounds=(lower - s, upper - s)).x
    return max(float(r @ r) - float(np.sum((r + jac @ step) ** 2)), 0.0), step


def bounded_trials(
    jac: np.ndarray, r: np.ndarray, s: np.ndarray, lower: np.ndarray, upper: np.ndarray,
    gate: float,
) -> list[np.ndarray]:  # fmt: skip
    """Return the points to simulate along :func:`bounded_step`, within the bounds.

    Its fractions are those of :func:`trial_fractions`.
    """
    _, step = bounded_step(jac, r, s, lower, upper)
    return [np.clip(s + f * step, lower, upper) for f in trial_fractions(jac, r, step, gate)]


def trial_reaches_gate(
    jac: np.ndarray, r: np.ndarray, step: np.ndarray, gate: float, fractions: list[float]
) -> bool:
    """Whether the smallest of ``fractions`` predicts a decrease of at most ``gate``."""
    predicted = r + fractions[-1] * (jac @ step)
    return float(r @ r) - float(predicted @ predicted) <= gate


def trial_detail(fractions: list[float], reached: bool, lower: float = 0.0) -> str:
    """Say, after a failed trial, which fractions raised the cost and what that shows.

    ``lower``: how much the lowest of them lowered the cost, no more than the gate.
    """
    which = (
        "the step and its half"
        if len(fractions) <= 2
        else f"the step and its fractions down to 1/{round(1 / fractions[-1])}"
    )
    what = f"lower the cost by no more than {lower:.3g}" if lower > 0 else "raise the cost"
    tried = f"{which} {what}"
    if reached:
        return (
            f"tried, {tried}, where the model predicts no more than the gate: no lower point there"
        )
    return (
        f"tried, {tried}, but the model still predicts more than the gate there: not "
        "shown to be an optimum"
    )


def _active(
    s: np.ndarray, g: np.ndarray, lower: np.ndarray, upper: np.ndarray, tol: float
) -> np.ndarray:
    """Parameters held at a bound by the gradient ``g`` (of half the squared residuals)."""
    return (_at(s, lower, tol) & (g > 0)) | (_at(upper, s, tol) & (g < 0))


def _at(high: np.ndarray, low: np.ndarray, tol: float) -> np.ndarray:
    """Where ``high - low`` is within ``tol`` (relative, at least absolute) of 0; finite only."""
    bound = np.where(np.isfinite(low), low, high)
    finite = np.isfinite(low) & np.isfinite(high)
    return finite & (high - low <= tol * np.maximum(1.0, np.abs(bound)))


def _feasible_fraction(s: np.ndarray, d: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """Largest ``t`` in [0, 1] with ``s + t d`` within the bounds."""
    t = 1.0
    for sj, dj, lo, hi in zip(s, d, lower, upper, strict=True):
        if dj > 0 and math.isfinite(hi):
            t = min(t, max(hi - sj, 0.0) / dj)
        elif dj < 0 and math.isfinite(lo):
            t = min(t, min(lo - sj, 0.0) / dj)
    return t


def gauss_newton_gap(
    jac: np.ndarray, r: np.ndarray, s: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> float:
    """Return the decrease of ``|r|^2`` the projected Gauss-Newton step predicts.

    See :func:`gauss_newton_step`, which also returns the step.
    """
    return gauss_newton_step(jac, r, s, lower, upper)[0]


def gauss_newton_step(
    jac: np.ndarray, r: np.ndarray, s: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> tuple[float, np.ndarray]:
    """Return the decrease of ``|r|^2`` the projected Gauss-Newton step predicts.

    Parameters
    ----------
    jac : numpy.ndarray
        Jacobian of the residuals, shape ``(m, p)``, in the coordinates ``s``.
    r : numpy.ndarray
        Residuals at ``s``, shape ``(m,)``; the cost is ``r @ r``.
    s, lower, upper : numpy.ndarray
        The point and the bounds, shape ``(p,)``.

    Returns
    -------
    gap : float
        ``|r|^2 - |r + J t d|^2`` (>= 0) for the Gauss-Newton step ``d`` of the
        parameters not held at a bound, cut to the largest ``t <= 1`` within the bounds.
        Parameters held at a bound, or that the step would push straight through one,
        are dropped from the step in turn.
    step : numpy.ndarray
        ``t d``, the step that predicts it (zeros where nothing is gained).
    """
    jac, r = np.asarray(jac, float), np.asarray(r, float)
    g = jac.T @ r
    free = ~_active(s, g, lower, upper, 1e-9)
    cost = float(r @ r)
    best = (0.0, np.zeros_like(s, dtype=float))
    for _ in range(s.size + 1):
        if not free.any():
            return best
        d = np.zeros_like(s, dtype=float)
        d[free] = np.linalg.lstsq(jac[:, free], -r, rcond=1e-12)[0]
        t = _feasible_fraction(s, d, lower, upper)
        predicted = r + t * (jac @ d)
        if cost - float(predicted @ predicted) > best[0]:
            best = (cost - float(predicted @ predicted), t * d)
        if t >= 1.0 or t * np.linalg.norm(d) > 1e-9:
            return best
        # a free parameter sits at a bound the step points through: hold it there
        blocked = free & (((d > 0) & _at(upper, s, 1e-12)) | ((d < 0) & _at(s, lower, 1e-12)))
        if not blocked.any():
            return best
        free &= ~blocked
    return best


def probe_points(space: Space, x: Mapping[str, float], step: float) -> list[dict[str, float]]:
    """Return the ``2 p`` sets ``step`` either side of ``x`` along each coordinate.

    A probe that the bounds would clip back onto ``x`` is left out.
    """
    s = space.to_s(x)
    out = []
    for j in range(space.dim):
        for sign in (-1.0, 1.0):
            t = s.copy()
            t[j] += sign * step
            t = space.clip(t)
            if not np.array_equal(t, s):
                out.append(space.to_x(t))
    return out


def probe_test(
    evaluator: Evaluator, space: Space, x: Mapping[str, float], cost: float, step: float
) -> tuple[Stationarity, dict[str, float], float]:
    """Run the local probe test; return it and the best of the answer and its probes."""
    probes = probe_points(space, x, step)
    if not probes:
        detail = "no probe fits within the bounds"
        return Stationarity(True, "local probes", 0.0, cost, detail, "probe"), dict(x), cost
    costs = evaluator.evaluate(probes).costs[:, 0]
    costs = np.where(np.isfinite(costs), costs, math.inf)
    k = int(np.argmin(costs))
    gap = max(cost - float(costs[k]), 0.0)
    if gap > 0:
        detail = (
            f"a probe {step:g} of a first range away lowers the cost by {gap:.3g}: "
            "not shown to be an optimum"
        )
        found = Stationarity(False, "local probes", gap, cost, detail, "probe", gap)
        return found, probes[k], float(costs[k])
    detail = (
        f"no probe {step:g} of a first range either side of the answer along any "
        f"parameter ({len(probes)} probes) lowers the cost"
    )
    return Stationarity(True, "local probes", 0.0, cost, detail, "probe"), dict(x), cost


def noise_floor(evaluator: Evaluator, weighted: bool) -> float:
    """Return the cost residuals at the data's noise level would have.

    With noise weighting the residuals are in units of the noise: the floor is their
    number. Otherwise each output's noise is estimated from its data
    (:func:`~tsid_fmu.evaluate.cost.noise_level`) and scaled as its residuals are.
    """
    total = 0.0
    spec = getattr(evaluator, "spec", None)
    for e in spec.experiments if spec is not None else ():
        n = e.weighted_samples  # the samples the windows score, with their weights
        if weighted:
            total += n * e.measured.shape[1]
        else:
            sigma = noise_level(e.scored(e.measured))
            total += n * float(np.sum((sigma / e.scale) ** 2))
    return total


def gauss_newton_test(
    jac: np.ndarray,
    r: np.ndarray,
    s: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    cost: float,
    gate: float,
    say: Callable[[float], str],
    simulate: Callable[[list[np.ndarray]], bool],
    lowest: Callable[[], float],
) -> Stationarity:
    """Run the projected Gauss-Newton test at an answer: the one place it is made.

    Parameters
    ----------
    jac, r, s : numpy.ndarray
        The last Jacobian, the answer's residuals and the answer, in the coordinates
        the caller searched in.
    bounds : tuple of numpy.ndarray
        The lower and upper bounds of ``s``.
    cost : float
        The answer's cost.
    gate : float
        The largest predicted decrease of the cost that still shows an optimum.
    say : callable
        ``say(gap)``: the sentence that opens the test's ``detail``.
    simulate : callable
        ``simulate(points)`` scores the trial points (in the coordinates of ``s``), and
        returns False where the runs ran out.
    lowest : callable
        ``lowest()``: the lowest cost known after the trials.

    Returns
    -------
    Stationarity
        It holds where the step predicts a decrease of at most ``gate``
        (:data:`GN_TEST`), or where the step and its halves down to the gate
        (:func:`trial_fractions`), simulated, lower the cost by no more than the gate
        (:data:`GN_TRIED`). A trial lower by more than the gate, or a trial that found
        no runs left, fails it.
    """
    gap, step = gauss_newton_step(jac, r, s, *bounds)
    detail = say(gap)
    if gap <= gate:
        return Stationarity(True, GN_TEST, gap, cost, detail)
    fractions = trial_fractions(jac, r, step, gate)
    if not simulate([s + f * step for f in fractions]):
        return Stationarity(False, GN_TEST, gap, cost, detail)
    lower = cost - lowest()
    if lower > gate:  # a point lower by no more than the gate refutes nothing
        said = f"{detail}; {LOWER_TRIED} {lower:.3g}"
        return Stationarity(False, GN_TEST, gap, cost, said, "trial", lower)
    reached = trial_reaches_gate(jac, r, step, gate, fractions)
    detail += "; " + trial_detail(fractions, reached, lower)
    test = GN_TRIED if reached else GN_TEST
    return Stationarity(reached, test, gap, cost, detail, "trial")
