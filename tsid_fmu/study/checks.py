"""Checks of single study values: each returns the value or raises a StudyError naming it.

The study's parts (:mod:`tsid_fmu.study.schema`) and the study itself
(:mod:`tsid_fmu.study.definition`) check every value they are given with these.
"""

from __future__ import annotations

import math
from typing import Any

from tsid_fmu.errors import StudyError

__all__ = ["check_bound", "check_choice", "check_number", "check_text", "check_whole"]


def check_number(value: Any, what: str) -> float:
    """Return ``value`` as a float, refusing booleans, strings and non-finite values.

    Raises
    ------
    StudyError
        Naming ``what``.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise StudyError(f"{what} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise StudyError(f"{what} must be finite, got {value!r}")
    return float(value)


def check_bound(value: Any, what: str, default: float) -> float:
    """Return a bound: a number, ``None`` (the default) or an infinity, never NaN."""
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        raise StudyError(f"{what} must be a number, got {value!r}")
    return float(value)


def check_whole(value: Any, what: str, low: int, high: int | None = None) -> int:
    """Return an integer in ``[low, high]``, refusing booleans and floats."""
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise StudyError(f"{what} must be an integer >= {low}, got {value!r}")
    if high is not None and value > high:
        raise StudyError(f"{what} must be an integer from {low} to {high}, got {value!r}")
    return int(value)


def check_text(value: Any, what: str) -> str:
    """Return ``value`` if it is printable text (no control characters, no escapes)."""
    if not isinstance(value, str) or not value.isprintable():
        raise StudyError(f"{what} must be printable text, got {value!r}")
    return value


def check_choice(value: Any, what: str, allowed: tuple[str, ...]) -> str:
    """Return ``value`` if it is one of ``allowed`` (the message lists them)."""
    if value not in allowed:
        choices = ", ".join(map(repr, allowed[:-1])) + f" or {allowed[-1]!r}"
        raise StudyError(f"{what} must be {choices}, got {value!r}")
    return str(value)
