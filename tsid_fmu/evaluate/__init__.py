"""Score parameter sets of an FMU against measured data: the costly step of every study.

The layer below the study: it takes an explicit, picklable
:class:`~tsid_fmu.evaluate.spec.EvaluationSpec` (FMU, parameter names, prepared
experiments) and returns costs per parameter set and replicate, residuals and simulated
outputs, through one interface (:class:`~tsid_fmu.evaluate.protocol.Evaluator`) with
three implementations:

* :class:`SerialEvaluator` -- in this process (no time limit, no crash isolation: what
  :func:`make_evaluator` gives only for one worker with ``timeout=0``);
* :class:`PoolEvaluator` -- local worker processes, with crash isolation and a time limit
  per simulation;
* :class:`DaskEvaluator` -- a ``dask.distributed`` cluster (optional dependency).

:func:`make_evaluator` picks one. All three give the same costs, residuals, errors and
simulation counts, bit for bit, and never simulate the same parameter set twice.
"""

from __future__ import annotations

from tsid_fmu.evaluate.cost import COSTS, NOISE_POWER, Cost, fit_percent, metrics, noise_level
from tsid_fmu.evaluate.dask import DaskEvaluator
from tsid_fmu.evaluate.factory import available_cores, make_evaluator
from tsid_fmu.evaluate.memo import RESIDUAL_CACHE
from tsid_fmu.evaluate.pool import PoolEvaluator
from tsid_fmu.evaluate.protocol import Evaluation, Evaluator, Progress, Simulated
from tsid_fmu.evaluate.serial import SerialEvaluator
from tsid_fmu.evaluate.spec import EvaluationSpec, PreparedExperiment
from tsid_fmu.evaluate.timelimit import TimeLimit

__all__ = [
    "COSTS",
    "NOISE_POWER",
    "RESIDUAL_CACHE",
    "Cost",
    "DaskEvaluator",
    "Evaluation",
    "EvaluationSpec",
    "Evaluator",
    "PoolEvaluator",
    "PreparedExperiment",
    "Progress",
    "SerialEvaluator",
    "Simulated",
    "TimeLimit",
    "available_cores",
    "fit_percent",
    "make_evaluator",
    "metrics",
    "noise_level",
]
