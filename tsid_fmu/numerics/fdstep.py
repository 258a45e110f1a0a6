"""Finite-difference steps chosen from the FMU's own noise.

An FMU that integrates with its own adaptive solver (most Co-Simulation FMUs) returns
outputs that are not smooth functions of the parameters: a change of a parameter by
1e-5 of its range can change the solver's step sequence, and the outputs move by the
solver's error, not by the derivative. A forward difference with such a step is then
mostly noise (JModelica's Simple2R1C: column norms 20 % off and a Gauss-Newton step
pointing the wrong way at a point 13 % above the optimum's cost).

The rule used here has two parts:

- :func:`solver_noise` measures the noise of the residuals as the parameters move, with
  the ECnoise estimator of More and Wild (SIAM J. Sci. Comput. 33, 2011): the residuals
  at ``s + k h p`` (``k = 0 .. 4``, ``p`` a fixed direction, ``h`` the difference step)
  give difference tables whose ``k``-th differences of a smooth function vanish while
  those of noise of standard deviation ``sigma`` have variance
  ``C(2k, k) sigma**2``. Four simulations, once per evaluator (per study). The scale
  of the differences is the RMS of their smallest 90 %, as for the data's noise
  (:func:`tsid_fmu.evaluate.noise.trimmed_rms`), not their RMS: an event that moves with the
  parameters (dry friction's stick and slip) touches a few samples, and a solver's
  error all of them; only the latter spoils every column (a toy with step events read
  0.25 by RMS, and its parallel columns were lost to steps 1000 times wider).
- :func:`steps_for` widens the step of every column whose forward difference the noise
  would spoil by more than 1 / :data:`SHARE`: a forward difference carries noise of
  norm ``sqrt(2 n) sigma / h``, so the step that makes it ``1 / SHARE`` of the column's
  norm ``|J_j|`` is ``h = SHARE sqrt(2 n) sigma / |J_j|``, capped at :data:`MAX_STEP`.
  For a smooth FMU (the project's own solver at ``rtol`` 1e-8, an exact discretisation)
  no step changes.

Every forward-difference Jacobian of the package is taken by :func:`forward_jacobian`:
one batch of runs, a step that would pass an upper bound taken backwards. The noise
is the evaluator's own (:class:`SolverNoise`, its attribute ``fd_noise``), measured once
and read by every user: the refinement's Jacobian and gate, and the profiles' checks.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from tsid_fmu.evaluate.noise import trimmed_rms
from tsid_fmu.numerics.tuning import MAX_STEP, OVERFLOW, POINTS, SHARE

__all__ = [
    "MAX_STEP",
    "SHARE",
    "SolverNoise",
    "forward_jacobian",
    "known_noise",
    "noise_of",
    "relative_steps",
    "solver_noise",
    "steps_for",
]


def solver_noise(
    residuals: Callable[[list[np.ndarray]], list[np.ndarray]],
    s: np.ndarray,
    r0: np.ndarray,
    step: float,
    upper: np.ndarray,
) -> float:
    """Return the standard deviation of the residuals' noise under parameter changes.

    Parameters
    ----------
    residuals : callable
        Residual vectors of a list of points in search coordinates (simulations).
    s : numpy.ndarray
        The point, whose residuals are ``r0``.
    r0 : numpy.ndarray
        The residuals at ``s``.
    step : float
        The spacing of the points (the forward-difference step).
    upper : numpy.ndarray
        Upper bounds of the search coordinates: the direction turns back before them.

    Returns
    -------
    float
        Per-sample noise, the median of the estimates from differences of orders 2 to 4.
    """
    d = s.size
    p = np.where(np.arange(d) % 2 == 0, 1.0, -1.0) / math.sqrt(d)
    p = np.where(s + POINTS * step * p > upper, -np.abs(p), p)
    table = np.array([r0, *residuals([s + k * step * p for k in range(1, POINTS + 1)])])
    if not np.all(np.isfinite(table)):
        return 0.0
    # the estimates scale with the residuals: residuals past 1e150 are scaled to at
    # most 1, so that neither their differences nor their squares overflow; below, the
    # table is taken as it is (a scaling changes the estimate in its last digits, and
    # with it the difference steps and where a refinement's trust region ends)
    peak = float(np.max(np.abs(table)))
    peak = peak if peak > OVERFLOW else 1.0
    table = table / peak if peak != 1.0 else table
    estimates = []
    for k in range(1, POINTS + 1):
        table = np.diff(table, axis=0)
        gamma = math.factorial(k) ** 2 / math.factorial(2 * k)
        if k >= 2:  # trimmed: events touch a few differences (module doc)
            estimates.append(math.sqrt(gamma) * trimmed_rms(table.ravel()))
    return float(np.median(estimates)) * peak  # a float product: inf, not a warning


class SolverNoise:
    """The noise of one evaluator's residuals under parameter changes, measured once.

    The evaluator carries it as its attribute ``fd_noise``, given by :func:`noise_of`
    the first time its noise is measured: the noise belongs to the FMU, its solver
    settings and the data, which is what one evaluator scores. ``value`` is ``None``
    until measured.
    """

    __slots__ = ("value",)

    def __init__(self) -> None:
        self.value: float | None = None

    def measured(self, measure: Callable[[], float]) -> float:
        """Return the noise, calling ``measure`` (:func:`solver_noise`) the first time."""
        if self.value is None:
            self.value = float(measure())
        return self.value


ATTRIBUTE = "fd_noise"
"""The evaluator's attribute that holds its :class:`SolverNoise`."""


def noise_of(owner: Any, measure: Callable[[], float]) -> float:
    """Return ``owner``'s noise, measuring it the first time (:func:`solver_noise`).

    An owner without a :class:`SolverNoise` is given one; one that takes no new
    attribute is measured each time.
    """
    record = getattr(owner, ATTRIBUTE, None)
    if not isinstance(record, SolverNoise):
        record = SolverNoise()
        try:
            setattr(owner, ATTRIBUTE, record)
        except (AttributeError, TypeError):
            return float(measure())
    return record.measured(measure)


def known_noise(owner: Any) -> float:
    """Return the noise measured for ``owner`` so far, or 0 if none was."""
    record = getattr(owner, ATTRIBUTE, None)
    value = record.value if isinstance(record, SolverNoise) else None
    return 0.0 if value is None else value


def relative_steps(z: np.ndarray) -> np.ndarray:
    """Return SciPy's ``"2-point"`` steps at ``z``: ``sqrt(eps) max(1, |z|)``, signed.

    Positive at ``z >= 0``, negative below (as :func:`scipy.optimize.approx_derivative`
    takes them), each the exactly representable ``(z + h) - z``. For coordinates that
    are already scaled (the combinations' and the nesting fit's).
    """
    z = np.asarray(z, dtype=float)
    h = np.finfo(float).eps ** 0.5 * np.where(z >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(z))
    return (z + h) - z


def forward_jacobian(
    run: Callable[[list[np.ndarray]], Sequence[np.ndarray]],
    z: np.ndarray,
    r0: np.ndarray,
    steps: np.ndarray,
    upper: np.ndarray | None = None,
    which: np.ndarray | None = None,
    lower: np.ndarray | None = None,
) -> np.ndarray:
    """Return forward differences of the residuals at ``z``: one batch of runs.

    Parameters
    ----------
    run : callable
        Residual vectors of a list of points (one batch of simulations).
    z : numpy.ndarray
        The point, whose residuals are ``r0``.
    r0 : numpy.ndarray
        The residuals at ``z``.
    steps : numpy.ndarray
        The step of every coordinate (its sign taken as given).
    upper, lower : numpy.ndarray, optional
        Bounds: a step that would pass one is taken the other way.
    which : numpy.ndarray, optional
        The coordinates differenced (all by default), in the order of the columns.

    Returns
    -------
    numpy.ndarray
        ``(r0.size, len(which))``, column ``k`` the difference along ``which[k]``.
    """
    which = np.arange(z.size) if which is None else np.asarray(which, dtype=int)
    h = np.asarray(steps, dtype=float)[which]
    if upper is not None:
        h = np.where(z[which] + h <= upper[which], h, -h)
    if lower is not None:
        h = np.where(z[which] + h >= lower[which], h, -h)
    points = []
    for j, hj in zip(which, h, strict=True):
        t = np.array(z, dtype=float)
        t[j] += hj
        points.append(t)
    cols = run(points)
    return np.column_stack([(c - r0) / hj for c, hj in zip(cols, h, strict=True)])


def steps_for(steps: np.ndarray, jac: np.ndarray, noise: float) -> np.ndarray:
    """Return the steps at which every column of ``jac`` beats the noise (module doc).

    ``jac`` holds forward differences taken with ``steps``; a column's step grows to
    ``SHARE sqrt(2 n) noise / |J_j|`` where that is larger, at most :data:`MAX_STEP`,
    and never shrinks.
    """
    if noise <= 0:
        return steps
    with np.errstate(over="ignore"):  # a column past 1e154: norm inf, its step kept
        norms = np.maximum(np.linalg.norm(jac, axis=0), 1e-300)
    need = SHARE * math.sqrt(2.0 * jac.shape[0]) * noise / norms
    return np.maximum(np.abs(steps), np.minimum(need, MAX_STEP)) * np.sign(steps)
