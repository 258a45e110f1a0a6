"""Choose the evaluator: in-process, local worker processes, or a Dask cluster."""

from __future__ import annotations

from typing import Any

from tsid_fmu.evaluate.dask import DaskEvaluator
from tsid_fmu.evaluate.pool import PoolEvaluator, available_cores
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.serial import SerialEvaluator
from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["available_cores", "make_evaluator"]


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
        seconds (see :mod:`tsid_fmu.evaluate.timelimit`). Only worker processes can
        apply it.
    scheduler : str or distributed.Client, optional
        A Dask scheduler address (``"tcp://host:8786"``) or client.

    Returns
    -------
    Evaluator
        A :class:`~tsid_fmu.evaluate.dask.DaskEvaluator` with ``scheduler``; else a
        :class:`~tsid_fmu.evaluate.serial.SerialEvaluator` (in this process, **no time
        limit**) when one worker is asked for, or only one core is available, and no
        positive ``timeout`` is given; else a
        :class:`~tsid_fmu.evaluate.pool.PoolEvaluator`.
    """
    if scheduler is not None:
        return DaskEvaluator(spec, scheduler, timeout=timeout)
    n = available_cores() if workers is None else int(workers)
    if n == 1 and not (timeout is not None and timeout > 0):
        return SerialEvaluator(spec)
    return PoolEvaluator(spec, workers=n, timeout=timeout)
