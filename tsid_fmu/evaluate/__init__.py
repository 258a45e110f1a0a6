"""Scoring parameter sets: simulate each experiment, compare with the data, cost."""

from tsid_fmu.evaluate.cost import COSTS, NOISE_POWER, Cost, fit_percent, metrics, noise_level
from tsid_fmu.evaluate.factory import make_evaluator
from tsid_fmu.evaluate.protocol import Evaluation, Evaluator, Simulated
from tsid_fmu.evaluate.serial import SerialEvaluator
from tsid_fmu.evaluate.spec import EvaluationSpec, PreparedExperiment

__all__ = [
    "COSTS",
    "NOISE_POWER",
    "Cost",
    "Evaluation",
    "EvaluationSpec",
    "Evaluator",
    "PreparedExperiment",
    "SerialEvaluator",
    "Simulated",
    "fit_percent",
    "make_evaluator",
    "metrics",
    "noise_level",
]
