"""Many short least-squares re-fits of one model to data sets that differ by their noise.

The replicates of :mod:`.sampled` share the model: replicate ``i`` minimises
``|r(s) - o_i|^2``, ``r`` the evaluator's residuals in the search coordinates ``s`` and
``o_i`` its own offset (the noise it was given). All of them start at the answer ``s0``
and end within a few standard errors of it, so they share one local model of ``r``
too::

    r(s0 + d) ~ r0 + J0 d + C^T phi(d),   phi(d) = (d, d_j d_k for j <= k)

``r0`` and ``J0`` are the residuals and the central-difference Jacobian at the answer
(the ones the covariance intervals use); ``C`` (a correction of the slope and the
curvature) is the least-squares fit, over every simulation the replicates have run so
far, of what ``r0 + J0 d`` missed. Every replicate contributes its simulations to the
model of all; no replicate pays for a Jacobian of its own.

A step of a replicate at ``d`` (where its residuals ``r(d)`` are known) minimises the
model corrected to pass through them, ``m(d') + r(d) - m(d)``, by a few Gauss-Newton
iterations on the model alone; the trial point, ``trust`` times that step, is
simulated. The step is taken if it lowers the replicate's cost (``trust`` doubles, at
most 1), else not (``trust`` halves). The fixed point of these steps is where the
model's Jacobian is orthogonal to the replicate's true residuals, the least-squares
optimum as far as the model's slope is right. The steps of every replicate still
moving go to the evaluator as one batch (in parallel over its workers).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tsid_fmu.numerics.space import Space
from tsid_fmu.numerics.tuning import INNER as _INNER
from tsid_fmu.numerics.tuning import MAX_STEPS, TOL

__all__ = ["MAX_STEPS", "TOL", "Replicate", "SharedModel", "refit", "tolerance"]


Simulate = Callable[[list[np.ndarray]], list[np.ndarray | None]]
Progress = Callable[[int, int, int], None]


class SharedModel:
    """The replicates' common model of the residuals near the answer (module doc)."""

    def __init__(self, r0: np.ndarray, jac0: np.ndarray) -> None:
        self.r0, self.jac0 = r0, jac0
        p = jac0.shape[1]
        self.upper = np.triu_indices(p)
        size = p + self.upper[0].size
        self.gram = np.zeros((size, size))
        self.moments = np.zeros((size, r0.size))
        self.coef = np.zeros((size, r0.size))

    def features(self, d: np.ndarray) -> np.ndarray:
        """``phi(d)``: the coordinates and their products."""
        return np.concatenate([d, np.outer(d, d)[self.upper]])

    def _dfeatures(self, d: np.ndarray) -> np.ndarray:
        """Return the derivative of ``phi`` at ``d``, ``(features, p)``."""
        p = d.size
        rows = [np.eye(p)]
        quad = np.zeros((self.upper[0].size, p))
        for k, (i, j) in enumerate(zip(*self.upper, strict=True)):
            quad[k, i] += d[j]
            quad[k, j] += d[i]
        rows.append(quad)
        return np.vstack(rows)

    def add(self, d: np.ndarray, r: np.ndarray) -> None:
        """Learn from one simulation: residuals ``r`` at ``s0 + d``."""
        phi = self.features(d)
        self.gram += np.outer(phi, phi)
        self.moments += np.outer(phi, r - self.r0 - self.jac0 @ d)

    def fit(self) -> None:
        """Refit ``C`` to every simulation added (least squares, minimum norm)."""
        self.coef = np.linalg.pinv(self.gram, rcond=1e-10) @ self.moments

    def value(self, d: np.ndarray) -> np.ndarray:
        """``m(d)``."""
        return self.r0 + self.jac0 @ d + self.features(d) @ self.coef

    def jacobian(self, d: np.ndarray) -> np.ndarray:
        """``dm/dd`` at ``d``, ``(residuals, p)``."""
        return self.jac0 + self.coef.T @ self._dfeatures(d)


@dataclass
class Replicate:
    """One re-fit: its offset, where it is, its residuals there, and its trust."""

    offset: np.ndarray
    d: np.ndarray
    r: np.ndarray
    tol: float
    trust: float = 1.0
    steps: int = 0
    taken: int = 0
    errors: int = 0
    converged: bool = False

    @property
    def cost(self) -> float:
        """The replicate's cost at ``d``."""
        return float(self.r @ self.r)

    @property
    def done(self) -> bool:
        """Converged, or out of steps."""
        return self.converged or self.steps >= MAX_STEPS

    def trial(self, model: SharedModel, space: Space, s0: np.ndarray) -> np.ndarray:
        """Return the next point to simulate, ``s0 + d``, within the bounds."""
        shift = self.r - model.value(self.d)  # the replicate's model through r(d)
        d = self.d.copy()
        for _ in range(_INNER):
            jac = model.jacobian(d)
            rhs = model.value(d) + shift
            a = jac.T @ jac
            ridge = 1e-10 * max(float(np.max(np.diag(a))), 1e-300)
            try:
                step = np.linalg.solve(a + ridge * np.eye(a.shape[0]), -(jac.T @ rhs))
            except np.linalg.LinAlgError:
                break
            d = space.clip(s0 + d + step) - s0
            if float(step @ step) < 1e-24:
                break
        return space.clip(s0 + self.d + self.trust * (d - self.d))

    def update(self, d: np.ndarray, r: np.ndarray | None) -> None:
        """Take the trial point ``d`` (its residuals ``r``) if it lowers the cost."""
        self.steps += 1
        self.errors += r is None
        moved = bool(np.any(d != self.d))
        fall = self.cost - (math.inf if r is None else float(r @ r))
        if r is not None and moved and fall >= 0:
            self.d, self.r = d, r
            self.taken += 1
            self.trust = min(1.0, 2.0 * self.trust)
        else:
            self.trust *= 0.5
        # no step left that changes the cost by more than the tolerance, either way
        self.converged = not moved or abs(fall) <= self.tol or self.trust < 1e-3


def refit(
    reps: list[Replicate],
    model: SharedModel,
    space: Space,
    s0: np.ndarray,
    simulate: Simulate,
    progress: Progress | None = None,
) -> None:
    """Step every replicate still moving until all are done (module doc).

    ``simulate`` takes the trial points (search coordinates) and returns the evaluator's
    residuals of each (None where it failed); ``progress(step, stepped, still_moving)``
    is called after each batch.
    """
    for k in range(1, MAX_STEPS + 1):
        moving = [rep for rep in reps if not rep.done]
        if not moving:
            return
        trials = [rep.trial(model, space, s0) for rep in moving]
        found = simulate(trials)
        for rep, s, r in zip(moving, trials, found, strict=True):
            d = s - s0
            if r is not None and np.all(np.isfinite(r)):
                model.add(d, r)
            rep.update(d, None if r is None else r - rep.offset)
        model.fit()
        if progress:
            progress(k, len(moving), sum(not rep.done for rep in reps))


def tolerance(r0: np.ndarray) -> float:
    """Return the cost fall below which a replicate stops: :data:`TOL` residual variances."""
    return TOL * float(r0 @ r0) / max(r0.size, 1) if r0.size else math.inf
