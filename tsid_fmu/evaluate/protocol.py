"""The interface every evaluator has, and what it returns."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["Evaluation", "Evaluator", "Simulated"]


@dataclass
class Evaluation:
    """Costs of a batch of parameter sets (column 0: on the measured inputs)."""

    costs: np.ndarray
    errors: list[str | None]
    nfev: int
    residuals: list[np.ndarray | None] | None = None

    @property
    def mean_costs(self) -> np.ndarray:
        """Mean cost over the replicates of each set (``inf`` if any failed)."""
        return self.costs.mean(axis=1)


@dataclass
class Simulated:
    """One experiment simulated on its measured inputs."""

    experiment: str
    outputs: np.ndarray | None
    error: str | None


class Evaluator(Protocol):
    """Scores parameter sets of a study against its measured experiments."""

    spec: EvaluationSpec

    @property
    def nfev(self) -> int: ...

    @property
    def n_replicates(self) -> int: ...

    def evaluate(
        self,
        parameter_sets: Sequence[Mapping[str, float]],
        progress: Callable[[int, int], None] | None = None,
    ) -> Evaluation: ...

    def simulate(
        self, parameter_sets: Sequence[Mapping[str, float]], *, count: bool = True
    ) -> list[list[Simulated]]: ...

    def close(self) -> None: ...
