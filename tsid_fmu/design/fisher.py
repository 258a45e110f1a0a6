"""Fisher information of the study and of candidate experiments, at the answer.

Everything is in the search coordinates of :class:`~tsid_fmu.search.space.Space`
(``log10`` of a parameter whose first range spans decades, else its value, per unit of
its first range), so that a determinant or a variance does not depend on units.

- The study's own information comes from the output sensitivities at the answer
  (:func:`tsid_fmu.uncertainty.sensitivity.sensitivities`), each output whitened by its
  residual RMS there, as the study's intervals are (:mod:`tsid_fmu.uncertainty.intervals`),
  then divided by the square of the study's inflation (how much its time-correlated
  residuals widened its intervals beyond the Cramer-Rao bound): what the study's data
  are worth, not what white noise would make them.
- A candidate experiment is the template experiment with the candidate's input
  (:mod:`tsid_fmu.design.plan`): its outputs and their sensors, its initial states and
  settings. Its information is the
  Cramer-Rao one, ``J^T J`` of its output sensitivities whitened by the sensors' noise
  (the noise the study weighted the template's outputs by). All candidates go to the
  evaluator as one batch of ``2p + 1`` parameter sets, each simulating every candidate.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.errors import SimulationError, one_line
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.sensitivity import sensitivities

__all__ = ["candidate_fisher", "one_line", "study_fisher"]


class _Reasons:
    """An evaluator that keeps the first reason a simulation failed for (``first``)."""

    def __init__(self, evaluator: Evaluator) -> None:
        self.evaluator, self.spec, self.first = evaluator, evaluator.spec, None

    def simulate(self, sets: Sequence[Mapping[str, float]], *args: Any, **kwargs: Any) -> Any:
        runs = self.evaluator.simulate(sets, *args, **kwargs)
        for row in runs:
            for sim in row:
                if self.first is None and sim.outputs is None:
                    self.first = sim.error or "no reason given"
        return runs

    def because(self) -> str:
        """Return ``": <reason>"`` for a message, or '' where no simulation failed."""
        return f": {one_line(self.first)}" if self.first else ""


def _fisher(jac: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``sum_k (J_k / sigma_k)^T (J_k / sigma_k)`` over the outputs ``k`` of ``(n, k, p)``."""
    white = jac / sigma[None, :, None]
    flat = white.reshape(-1, white.shape[-1])
    return flat.T @ flat


def study_fisher(
    evaluator: Evaluator, space: Space, x: Mapping[str, float], inflation: float
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Return the information of the study's experiments at ``x`` (module doc).

    And each experiment's residuals there (measured minus simulated, its scored
    samples): the sensors' noise as the data show it.
    """
    kept = _Reasons(evaluator)
    sens = sensitivities(kept, evaluator.spec, space, x)  # type: ignore[arg-type, attr-defined]
    if sens is None:
        raise SimulationError(f"design: a simulation at the answer failed{kept.because()}")
    total = np.zeros((space.dim, space.dim))
    for r, jac in zip(sens.residuals, sens.jacobian, strict=True):
        rms = np.sqrt(np.mean(r**2, axis=0))
        total += _fisher(jac, np.where(rms > 0, rms, 1.0))
    noise = {e: -r for e, r in zip(sens.experiments, sens.residuals, strict=True)}
    return total / max(inflation, 1.0) ** 2, noise


def candidate_fisher(
    evaluator: Evaluator, space: Space, x: Mapping[str, float], sigma: np.ndarray
) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Return each candidate's Fisher matrix, its simulated outputs at ``x`` and Jacobian.

    ``evaluator`` simulates a :func:`~tsid_fmu.design.plan.candidate_spec`. The
    Jacobians are whitened by ``sigma``, one row per sample and output (sample after
    sample).
    """
    kept = _Reasons(evaluator)
    sens = sensitivities(kept, evaluator.spec, space, x)  # type: ignore[arg-type, attr-defined]
    if sens is None:
        raise SimulationError(
            "design: a simulation of a candidate input failed at the answer or beside it "
            f"(narrow [design] inputs or band){kept.because()}"
        )
    whitened = [(jac / sigma[None, :, None]).reshape(-1, space.dim) for jac in sens.jacobian]
    fishers = [w.T @ w for w in whitened]
    experiments = evaluator.spec.experiments  # type: ignore[attr-defined]
    # the residuals are simulated minus "measured" (the held columns), every sample scored
    outputs = [np.asarray(r) + e.measured for r, e in zip(sens.residuals, experiments, strict=True)]
    return fishers, outputs, whitened
