"""What an evaluator needs to score parameter sets: the FMU and the prepared experiments."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["EvaluationSpec", "PreparedExperiment"]


@dataclass(frozen=True)
class PreparedExperiment:
    """An experiment's data arranged for simulation (read-only arrays)."""

    name: str
    time: np.ndarray
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    inputs: np.ndarray | None
    measured: np.ndarray
    weights: np.ndarray
    scale: np.ndarray
    noisy_inputs: tuple[np.ndarray, ...] = ()
    start_values: Mapping[str, float] = field(default_factory=dict)
    hold: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class EvaluationSpec:
    """The FMU, the parameters varied, the experiments and the cost kind."""

    fmu: Path
    parameter_names: tuple[str, ...]
    experiments: tuple[PreparedExperiment, ...]
    cost: str = "sse"
    start_values: Mapping[str, float] = field(default_factory=dict)
    interface: str = "auto"
    step_size: float | None = None

    @property
    def n_replicates(self) -> int:
        """Runs per parameter set: the measured inputs plus the noisy copies."""
        return 1 + max((len(e.noisy_inputs) for e in self.experiments), default=0)
