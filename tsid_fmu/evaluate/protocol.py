"""What every evaluator returns and offers: Evaluation, Simulated, the Evaluator protocol.

The study layer codes against :class:`Evaluator` only;
:func:`~tsid_fmu.evaluate.factory.make_evaluator` picks the implementation (in-process,
local worker processes, or a Dask cluster). Every implementation returns the same costs,
residuals, errors and simulation counts for the same calls, bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["Evaluation", "Evaluator", "Progress", "Simulated"]

Progress = Callable[[int, int], None]
"""``progress(done, total)``, called after each parameter set of a batch."""


@dataclass
class Evaluation:
    """Costs of a batch of parameter sets.

    Attributes
    ----------
    costs : numpy.ndarray
        Shape ``(n_sets, n_replicates)``, summed over the experiments in spec order.
        Column 0 is the cost on the measured inputs (replicate 1), columns 1.. the noisy
        replicates; ``inf`` where a set failed.
    errors : list of str or None
        Per set, the first failure's reason (``"<experiment>: <message>"``), or None.
    nfev : int
        Simulations this call actually ran (sets found in the memo cost none).
    residuals : list of numpy.ndarray or None, optional
        Per set, the concatenation over the experiments of
        ``((simulated - measured) / scale).ravel()`` on the measured inputs (read-only
        float64); None for a failed set.
    """

    costs: np.ndarray
    errors: list[str | None]
    nfev: int
    residuals: list[np.ndarray | None] | None = None

    @property
    def mean_costs(self) -> np.ndarray:
        """Mean cost over the replicates of each set (``inf`` if the set failed)."""
        return self.costs.mean(axis=1)


@dataclass
class Simulated:
    """One experiment simulated on its measured inputs.

    Attributes
    ----------
    experiment : str
        The experiment's name.
    outputs : numpy.ndarray or None
        Shape ``(n, n_out)`` (read-only), in the order of the experiment's
        ``output_names``; None when the simulation failed.
    error : str or None
        Why it failed, or None.
    """

    experiment: str
    outputs: np.ndarray | None
    error: str | None


@runtime_checkable
class Evaluator(Protocol):
    """Scores and simulates parameter sets of one :class:`EvaluationSpec` (context manager).

    Parameter sets are mappings from every name of ``spec.parameter_names`` to a number.
    No parameter set is simulated twice: results are kept by the tuple of its float values
    (costs and errors of every set, residuals and simulated outputs of the most recent
    ones), and a set given twice in one batch runs once.
    """

    spec: EvaluationSpec

    @property
    def nfev(self) -> int:
        """Simulations run so far (by :meth:`evaluate`, and :meth:`simulate` with ``count``)."""
        ...

    @property
    def n_replicates(self) -> int:
        """Replicates per parameter set (column 0: the measured inputs)."""
        ...

    def evaluate(
        self, parameter_sets: Sequence[Mapping[str, float]], progress: Progress | None = None
    ) -> Evaluation:
        """Score each parameter set on every experiment and replicate."""
        ...

    def simulate(
        self, parameter_sets: Sequence[Mapping[str, float]], *, count: bool = True
    ) -> list[list[Simulated]]:
        """Simulate each set on the measured inputs; ``count=False`` leaves ``nfev`` alone."""
        ...

    def close(self) -> None:
        """Free the FMU instances, worker processes and extracted folders."""
        ...

    def __enter__(self) -> Evaluator: ...

    def __exit__(self, *exc: object) -> None: ...
