"""Evaluate parameter sets in this process, one after the other.

The simplest :class:`~tsid_fmu.evaluate.protocol.Evaluator`: one
:class:`~tsid_fmu.evaluate.runner.SetRunner` (one FMU session per experiment) in the
calling process. It cannot protect the study from the FMU's native code: a simulation
that crashes ends the process, and one that hangs is never stopped -- there is **no time
limit** here. Use :class:`~tsid_fmu.evaluate.pool.PoolEvaluator` (even with one worker)
for either; :func:`~tsid_fmu.evaluate.factory.make_evaluator` chooses this evaluator only
for one worker with ``timeout=0`` (the opt-out of scripts that want the FMU in their own
process; ``benchmarks/isolation.py`` measures what the worker process costs).
"""

from __future__ import annotations

from tsid_fmu.errors import SimulationError
from tsid_fmu.evaluate.memo import RESIDUAL_CACHE, MemoEvaluator
from tsid_fmu.evaluate.runner import Job, OnResult, SetRunner
from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["SerialEvaluator"]


class SerialEvaluator(MemoEvaluator):
    """Score parameter sets in this process (context manager).

    Parameters
    ----------
    spec, residual_cache
        As for :class:`~tsid_fmu.evaluate.memo.MemoEvaluator` (``residual_cache``
        defaults to 256).

    Raises
    ------
    FMUError
        The FMU cannot be opened or lacks a variable of the spec.

    Examples
    --------
    >>> with SerialEvaluator(spec) as ev:  # doctest: +SKIP
    ...     ev.evaluate([{"tau": 0.1}, {"tau": 0.2}]).costs
    """

    def __init__(self, spec: EvaluationSpec, *, residual_cache: int = RESIDUAL_CACHE) -> None:
        super().__init__(spec, residual_cache=residual_cache)
        self._runner: SetRunner | None = SetRunner(spec)

    def _run_jobs(self, jobs: list[Job], on_result: OnResult) -> None:
        runner = self._runner
        if runner is None:
            raise SimulationError(f"{self.spec.fmu.name}: the evaluator is closed")
        for index, job in enumerate(jobs):
            on_result(index, runner.run_job(job))

    def close(self) -> None:
        """Free the FMU sessions (instances and extracted folders)."""
        if self._runner is not None:
            self._runner.close()
            self._runner = None
