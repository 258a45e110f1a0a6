"""What every evaluator shares: the memo, one run per distinct set, the counters.

:class:`MemoEvaluator` implements :class:`~tsid_fmu.evaluate.protocol.Evaluator` on top of
one method its subclasses provide, :meth:`MemoEvaluator._run_jobs`, which runs
:class:`~tsid_fmu.evaluate.runner.SetRunner` jobs somewhere (this process, worker
processes, a Dask cluster) and reports each result. Everything that decides what is
simulated and what is counted happens here, in the calling process, before and after the
jobs run -- never in the order they finish -- so results and counters do not depend on
how many workers there are or how they are scheduled. The caches take a batch's results
in the order of its jobs once the batch ends, so what they drop does not depend on the
order the jobs finished in either.

Memo keys are :meth:`EvaluationSpec.key`: the exact float values in parameter order.

* Costs and errors of every set evaluated are kept for the evaluator's life (a few
  numbers per set).
* Residuals are kept for the last ``residual_cache`` sets (least recently used first out);
  a set whose costs are known but whose residuals have been dropped runs again on the
  measured inputs only, and those simulations count.
* :meth:`simulate` keeps the outputs of the last ``output_cache`` sets.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.evaluate.protocol import Evaluation, Progress, Simulated
from tsid_fmu.evaluate.runner import Job, OnResult, SetResult, SimResult
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.fmu import native

__all__ = ["OUTPUT_CACHE", "RESIDUAL_CACHE", "MemoEvaluator"]

RESIDUAL_CACHE = 256
"""Default number of parameter sets whose residuals an evaluator keeps."""
OUTPUT_CACHE = 32
"""Default number of parameter sets whose simulated outputs an evaluator keeps."""

Key = tuple[float, ...]


class _LRU(OrderedDict):
    """A dict that keeps its ``size`` most recently used entries."""

    def __init__(self, size: int) -> None:
        super().__init__()
        self.size = int(size)

    def get_recent(self, key: Key) -> Any:
        if key not in self:
            return None
        self.move_to_end(key)
        return self[key]

    def put(self, key: Key, value: Any) -> None:
        self[key] = value
        self.move_to_end(key)
        while len(self) > self.size:
            self.popitem(last=False)


class MemoEvaluator:
    """Base class of the evaluators: memo, deduplication, progress and ``nfev``.

    Parameters
    ----------
    spec : EvaluationSpec
        What to simulate and how to score it.
    residual_cache : int
        Parameter sets whose residuals are kept (at least 1).
    output_cache : int
        Parameter sets whose :meth:`simulate` outputs are kept (0: none).
    """

    def __init__(
        self,
        spec: EvaluationSpec,
        *,
        residual_cache: int = RESIDUAL_CACHE,
        output_cache: int = OUTPUT_CACHE,
    ) -> None:
        if not isinstance(spec, EvaluationSpec):
            raise TypeError(f"an evaluator needs an EvaluationSpec, got {type(spec).__name__}")
        self.spec = spec
        self._nfev = 0
        self.last_cost: float | None = None  # the cost of the set last scored (progress)
        self._costs: dict[Key, tuple[np.ndarray, str | None]] = {}
        self._residuals = _LRU(max(1, residual_cache))
        self._outputs = _LRU(max(0, output_cache))
        self._known: set[Key] = set()
        self.batches: list[int] = []  # parameter sets run per batch (:meth:`rounds`)

    @property
    def nfev(self) -> int:
        """Simulations run so far (by :meth:`evaluate`, and :meth:`simulate` with ``count``)."""
        return self._nfev

    @property
    def n_replicates(self) -> int:
        """Replicates per parameter set (column 0: the measured inputs)."""
        return self.spec.n_replicates

    # -- to be provided ------------------------------------------------------------------

    def _run_jobs(self, jobs: list[Job], on_result: OnResult) -> None:
        """Run ``jobs`` (:meth:`SetRunner.run_job`); call ``on_result(index, result)``."""
        raise NotImplementedError

    def _batch_done(self) -> None:
        """Run after every batch that ran jobs (hook for the time limit)."""

    # -- the Evaluator interface ---------------------------------------------------------

    def evaluate(
        self, parameter_sets: Sequence[Mapping[str, float]], progress: Progress | None = None
    ) -> Evaluation:
        """Score each parameter set on every experiment and replicate.

        Parameters
        ----------
        parameter_sets : sequence of mapping
            Values of every parameter of the spec, one mapping per set.
        progress : callable, optional
            Called as ``progress(done, total)`` after each set (sets found in the memo
            first).

        Returns
        -------
        Evaluation
            Costs (column 0: measured inputs), errors, residuals, and the simulations run.

        Raises
        ------
        StudyError
            A set lacks a parameter, has an unknown one, or a value that is no number.
        """
        keys = [self.spec.key(p) for p in parameter_sets]
        where: dict[Key, list[int]] = {}
        for i, k in enumerate(keys):
            where.setdefault(k, []).append(i)
        fresh: dict[Key, np.ndarray | None] = {}
        jobs: list[tuple[Key, Job]] = []
        done = 0
        for k in where:
            known = self._costs.get(k)
            if known is None or (known[1] is None and self._residuals.get_recent(k) is None):
                jobs.append((k, ("run", self.spec.values(k), known is None)))
                continue
            fresh[k] = self._residuals.get(k)
            done = self._report(progress, done, len(keys), len(where[k]), known[0][0])
        nfev = 0

        def on_result(index: int, result: SetResult) -> None:
            nonlocal done, nfev
            k, (_, _, full) = jobs[index]
            counted = 0 if k in self._known else result.nfev
            self._known.discard(k)
            nfev += counted
            self._nfev += counted
            if full:
                result.costs.flags.writeable = False
                self._costs[k] = (result.costs, result.error)
            fresh[k] = result.residuals  # the LRU may drop it before this batch ends
            done = self._report(progress, done, len(keys), len(where[k]), result.costs[0])

        try:
            self._run(jobs, on_result)
        finally:  # into the LRU in the jobs' order, not the order they finished in
            for k, _ in jobs:
                if fresh.get(k) is not None:
                    self._residuals.put(k, fresh[k])
        costs = np.zeros((len(keys), self.n_replicates))
        for i, k in enumerate(keys):
            costs[i] = self._costs[k][0]
        return Evaluation(
            costs=costs,
            errors=[self._costs[k][1] for k in keys],
            nfev=nfev,
            residuals=[fresh[k] for k in keys],
        )

    def simulate(
        self, parameter_sets: Sequence[Mapping[str, float]], *, count: bool = True
    ) -> list[list[Simulated]]:
        """Simulate each parameter set on the measured inputs of every experiment.

        Parameters
        ----------
        parameter_sets : sequence of mapping
            Values of every parameter of the spec, one mapping per set.
        count : bool
            Add the simulations run to :attr:`nfev` (``False`` for plots).

        Returns
        -------
        list of list of Simulated
            Per set, one :class:`Simulated` per experiment (outputs are read-only).
        """
        keys = [self.spec.key(p) for p in parameter_sets]
        found: dict[Key, list[Simulated]] = {}
        jobs: list[tuple[Key, Job]] = []
        for k in dict.fromkeys(keys):
            hit = self._outputs.get_recent(k)
            if hit is None:
                jobs.append((k, ("sim", self.spec.values(k), True)))
            else:
                found[k] = hit

        def on_result(index: int, result: SimResult) -> None:
            if count:
                self._nfev += result.nfev
            found[jobs[index][0]] = result.simulated

        try:
            self._run(jobs, on_result)
        finally:  # into the LRU in the jobs' order, not the order they finished in
            for k, _ in jobs:
                if k in found:
                    self._outputs.put(k, found[k])
        return [list(found[k]) for k in keys]

    def mark_known(self, parameter_sets: Sequence[Mapping[str, float]]) -> None:
        """Declare sets an interrupted run of the study simulated already.

        Their first simulation here is not counted in :attr:`nfev`: the uninterrupted
        study had their results in memory, so a resumed study counts what it would have.
        """
        self._known.update(self.spec.key(p) for p in parameter_sets)

    def _run(self, jobs: list[tuple[Key, Job]], on_result: OnResult) -> None:
        def recorded(index: int, result: SetResult | SimResult) -> None:
            if result.printed:  # into the study folder's record, when a study runs
                native.record(jobs[index][1][1], result.printed)
            on_result(index, result)

        if jobs:
            self.batches.append(len(jobs))
            self._run_jobs([job for _, job in jobs], recorded)
            self._batch_done()

    def rounds(self, workers: int) -> int:
        """Return the rounds of parallel simulation the batches so far take on ``workers``.

        A batch of ``b`` parameter sets takes ``ceil(b / workers)`` rounds: the wall time
        of a study whose simulations all take about as long, in units of one.
        """
        return sum(-(-b // max(workers, 1)) for b in self.batches)

    def _report(self, progress: Progress | None, done: int, total: int, n: int, cost: float) -> int:
        """Count ``n`` sets done; :attr:`last_cost` is the cost of the set just scored."""
        self.last_cost = float(cost)
        for _ in range(n):
            done += 1
            if progress is not None:
                progress(done, total)
        return done

    # -- life cycle ----------------------------------------------------------------------

    def close(self) -> None:
        """Free what the evaluator holds (subclasses extend this)."""

    def __enter__(self) -> MemoEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.spec.fmu.name!r}, nfev={self._nfev})"
