"""Evaluate parameter sets on local worker processes.

:class:`PoolEvaluator` runs the parameter sets of a batch on several processes
(:class:`~tsid_fmu.evaluate.workers.LocalPool`), one set per job. Every set runs through
exactly the serial code (:class:`~tsid_fmu.evaluate.runner.SetRunner`) on exactly the
same inputs, and everything counted is decided per set, so costs, residuals, errors and
``nfev`` are bit-identical to :class:`~tsid_fmu.evaluate.serial.SerialEvaluator`'s and do
not depend on the number of workers or the order jobs finish in.

The workers also isolate the study from the FMU's native code: a crash (``abort()``,
segmentation fault) fails only its parameter set and the worker is replaced, and a
simulation past the time limit (automatic by default, see
:mod:`tsid_fmu.evaluate.timelimit`) is stopped. Neither ever raises out of
:meth:`PoolEvaluator.evaluate`.

Examples
--------
>>> from tsid_fmu.evaluate import PoolEvaluator
>>> with PoolEvaluator(spec, workers=4, timeout=10.0) as ev:  # doctest: +SKIP
...     result = ev.evaluate([{"K_s": 4000.0}, {"K_s": 6000.0}])
"""

from __future__ import annotations

import os

from tsid_fmu.errors import SimulationError, StudyError
from tsid_fmu.evaluate.memo import RESIDUAL_CACHE, MemoEvaluator
from tsid_fmu.evaluate.runner import Job, OnResult
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.evaluate.timelimit import TimeLimit
from tsid_fmu.evaluate.workers import LocalPool

__all__ = ["PoolEvaluator", "available_cores"]


def available_cores() -> int:
    """Return the number of CPU cores this process may run on (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


class PoolEvaluator(MemoEvaluator):
    """Score parameter sets on local worker processes (context manager).

    Parameters
    ----------
    spec : EvaluationSpec
        What to simulate and how to score it.
    workers : int, optional
        Worker processes; default the number of available cores.
    timeout : float, optional
        Time limit per simulation in seconds: ``None`` (default) automatic -- 20 times
        the median duration of the first batch's simulations, at least 5 s --, ``0``
        none (see :mod:`tsid_fmu.evaluate.timelimit`).
    recycle_after : int, optional
        Replace a worker after this many parameter sets (FMUs that leak memory).
    start_method : {"forkserver", "spawn"}, optional
        How workers start; default ``forkserver`` where available.
    residual_cache : int, optional
        Parameter sets whose residuals are kept (default 256).

    Raises
    ------
    FMUError
        As :class:`~tsid_fmu.evaluate.serial.SerialEvaluator` raises it (a worker's
        start-up error is raised here).
    StudyError
        ``workers``, ``timeout`` or ``recycle_after`` out of range.
    """

    def __init__(
        self,
        spec: EvaluationSpec,
        *,
        workers: int | None = None,
        timeout: float | None = None,
        recycle_after: int | None = None,
        start_method: str | None = None,
        residual_cache: int = RESIDUAL_CACHE,
    ) -> None:
        super().__init__(spec, residual_cache=residual_cache)
        if workers is not None and int(workers) < 1:
            raise StudyError(f"workers must be at least 1, got {workers}")
        if recycle_after is not None and int(recycle_after) < 1:
            raise StudyError(f"recycle_after must be at least 1, got {recycle_after}")
        self.workers = available_cores() if workers is None else int(workers)
        self.limit = TimeLimit(timeout)
        self._pool: LocalPool | None = LocalPool(
            spec,
            self.workers,
            self.limit,
            None if recycle_after is None else int(recycle_after),
            start_method,
        )

    @property
    def time_limit(self) -> float | None:
        """The time limit per simulation now, in seconds (None: no limit)."""
        return self.limit.seconds()

    @property
    def retried(self) -> list[str]:
        """Sets that crashed a worker and then succeeded in a fresh one, with the reason."""
        return list(self._pool.retried) if self._pool is not None else []

    def _run_jobs(self, jobs: list[Job], on_result: OnResult) -> None:
        if self._pool is None:
            raise SimulationError(f"{self.spec.fmu.name}: the evaluator is closed")
        self._pool.run(jobs, on_result)

    def _batch_done(self) -> None:
        self.limit.end_batch()

    def close(self) -> None:
        """Stop the workers (they free their FMU instances and extracted folders)."""
        pool, self._pool = getattr(self, "_pool", None), None
        if pool is not None:
            pool.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass

    def __repr__(self) -> str:
        return f"PoolEvaluator({self.spec.fmu.name!r}, {self.workers} workers, nfev={self.nfev})"
