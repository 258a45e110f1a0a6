"""Choose the evaluator: in-process, local worker processes, or a Dask cluster."""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.dask import DaskEvaluator
from tsid_fmu.evaluate.pool import PoolEvaluator, available_cores
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.serial import SerialEvaluator
from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["MAX_WORKERS_ENV", "WORKERS_PER_CORE", "available_cores", "check_runner", "in_process",
           "make_evaluator"]  # fmt: skip

WORKERS_PER_CORE = 4
"""Most local worker processes per available core, unless :data:`MAX_WORKERS_ENV` allows
more: each worker holds its own FMU instance, and 30 workers for a 25-run array on two
cores took 4 GB and ran no faster."""
MAX_WORKERS_ENV = "TSID_FMU_MAX_WORKERS"
"""Environment variable: the most local worker processes allowed (overrides the cap)."""


def _whole(value: Any, what: str) -> int:
    """Return ``value`` as an int (NumPy integers too); TypeError for anything else."""
    if isinstance(value, np.integer):
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{what} must be a whole number, got {value!r}")
    return value


def check_runner(workers: Any, timeout: Any) -> tuple[int | None, float | None]:
    """Return ``workers`` and ``timeout`` checked, as :func:`make_evaluator` takes them.

    Raises
    ------
    TypeError
        ``workers`` is not a whole number, or ``timeout`` is not a number (both None
        allowed: the defaults).
    StudyError
        ``workers`` below 1, or above :data:`WORKERS_PER_CORE` per available core
        (unless :data:`MAX_WORKERS_ENV` allows it); ``timeout`` negative or not finite.
    """
    if workers is not None:
        workers = _whole(workers, "workers")
        if workers < 1:
            raise StudyError(f"workers must be at least 1, got {workers}")
        cores = available_cores()
        allowed = os.environ.get(MAX_WORKERS_ENV, "")
        most = int(allowed) if allowed.isdigit() else WORKERS_PER_CORE * cores
        if workers > most:
            raise StudyError(
                f"workers {workers} is more than {most} ({WORKERS_PER_CORE} per available "
                f"core, {cores} cores): each worker holds its own FMU instance; set "
                f"{MAX_WORKERS_ENV}={workers} to allow it"
            )
    if timeout is not None:
        if isinstance(timeout, np.generic):
            timeout = timeout.item()
        if isinstance(timeout, bool) or not isinstance(timeout, int | float):
            raise TypeError(f"timeout must be a number of seconds (0: none), got {timeout!r}")
        if not (math.isfinite(timeout) and timeout >= 0):
            raise StudyError(
                f"timeout must be 0 (none) or a positive number of seconds, got {timeout}"
            )
    return workers, timeout


def make_evaluator(
    spec: EvaluationSpec,
    *,
    workers: int | None = None,
    timeout: float | None = None,
    scheduler: Any = None,
) -> Evaluator:
    """Return the evaluator for a spec: in this process, on local workers or on Dask.

    Which one is said under Returns. All of them give the same costs and count the
    same simulations for the same parameter sets, whatever the number of workers.

    Parameters
    ----------
    spec : EvaluationSpec
        What to simulate and how to score it; every evaluator takes it as it is.
    workers : int, optional
        Local worker processes; default the number of available cores
        (:func:`available_cores`). Ignored with ``scheduler``.
    timeout : float, optional
        Time limit per simulation: ``None`` (default) automatic, ``0`` none, else
        seconds (see :mod:`tsid_fmu.evaluate.timelimit`).
    scheduler : str or distributed.Client, optional
        A Dask scheduler address (``"tcp://host:8786"``) or client.

    Returns
    -------
    Evaluator
        A :class:`~tsid_fmu.evaluate.dask.DaskEvaluator` with ``scheduler``; else a
        :class:`~tsid_fmu.evaluate.serial.SerialEvaluator` (in this process: no time
        limit, and a crash of the FMU ends the process) only for one worker with
        ``timeout=0`` (:func:`in_process`); else a
        :class:`~tsid_fmu.evaluate.pool.PoolEvaluator` -- with one worker process when
        one worker is asked for or only one core is available, so that the time limit
        holds and a crash fails only its parameter set there too.
    """
    if scheduler is not None:
        return DaskEvaluator(spec, scheduler, timeout=timeout)
    n = available_cores() if workers is None else int(workers)
    if in_process(workers, timeout, scheduler):
        return SerialEvaluator(spec)
    return PoolEvaluator(spec, workers=n, timeout=timeout)


def in_process(workers: int | None, timeout: float | None, scheduler: Any = None) -> bool:
    """Return True if :func:`make_evaluator` simulates in the calling process.

    Only for one worker (asked for, or the only available core) with ``timeout=0``:
    no time limit, no worker process to start -- the explicit choice of a script that
    wants the FMU in its own process. Everything else runs in worker processes.
    """
    if scheduler is not None:
        return False
    n = available_cores() if workers is None else int(workers)
    return n == 1 and timeout is not None and float(timeout) == 0
