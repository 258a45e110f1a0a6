"""Choose the evaluator: in-process, local worker processes, or a Dask cluster."""

from __future__ import annotations

from typing import Any

from tsid_fmu.evaluate.dask import DaskEvaluator
from tsid_fmu.evaluate.pool import PoolEvaluator, available_cores
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.serial import SerialEvaluator
from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["available_cores", "in_process", "make_evaluator"]


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
