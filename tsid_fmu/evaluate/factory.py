"""Choose an evaluator (temporary: serial only until the worker pools land)."""

from __future__ import annotations

from typing import Any

from tsid_fmu.evaluate.serial import SerialEvaluator
from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["make_evaluator"]


def make_evaluator(
    spec: EvaluationSpec, *, workers: int | None = None, timeout: float | None = None,
    scheduler: Any = None,
) -> SerialEvaluator:  # fmt: skip
    """Return an evaluator of ``spec``."""
    return SerialEvaluator(spec)
