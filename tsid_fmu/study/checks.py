"""Checks of single study values: each returns the value or raises a StudyError naming it.

The study's parts (:mod:`tsid_fmu.study.schema`) and the study itself
(:mod:`tsid_fmu.study.definition`) check every value they are given with these.
"""

from __future__ import annotations

import math
import tomllib
from typing import Any

import numpy as np

from tsid_fmu.errors import StudyError

__all__ = [
    "INT64",
    "MAX_SAMPLED",
    "UNCERTAINTY",
    "check_bound",
    "check_choice",
    "check_number",
    "check_text",
    "check_uncertainty",
    "check_whole",
    "check_windows",
    "parse_toml",
    "plain",
]

INT64 = (-(2**63), 2**63 - 1)
"""The integers TOML promises to hold; a study file's integers must lie in this range."""

UNCERTAINTY = ("analytic", "bootstrap", "monte_carlo")
"""``[method] uncertainty``: the covariance and profile intervals alone (``analytic``), or
also sampled ones (:mod:`tsid_fmu.uncertainty.sampled`)."""

DEFAULT_SAMPLED = 100
"""``[method] uncertainty_replicates`` when it is not given."""
MAX_SAMPLED = 100_000
"""Most re-fits of ``[method] uncertainty_replicates``."""


def _digits(value: int) -> int:
    """Return about how many decimal digits ``value`` has (without printing it)."""
    try:
        return len(str(abs(value)))
    except ValueError:  # beyond sys.get_int_max_str_digits(): an estimate
        return int(abs(value).bit_length() * math.log10(2)) + 1


def _as_float(value: int | float, what: str) -> float:
    """Return ``float(value)``; an integer too large for a float is a StudyError."""
    try:
        return float(value)
    except OverflowError:
        raise StudyError(
            f"{what} must be a number a float can hold, got an integer of {_digits(value)} digits"
        ) from None


def _walk_integers(value: Any, key: str, source: str) -> None:
    """Refuse an integer outside :data:`INT64` anywhere in a parsed TOML document."""
    if isinstance(value, dict):
        for k, v in value.items():
            _walk_integers(v, f"{key}.{k}" if key else str(k), source)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _walk_integers(v, f"{key}[{i}]", source)
    elif isinstance(value, int) and not isinstance(value, bool):
        if not INT64[0] <= value <= INT64[1]:
            raise StudyError(
                f"{source}: {key} is an integer of {_digits(value)} digits, outside the 64-bit "
                "range of TOML integers (write a float such as 1e30 if you mean a large number)"
            )


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """Parse TOML text; every failure is a StudyError naming ``source`` (and the key).

    Beyond :func:`tomllib.loads`, an integer outside the 64-bit range of TOML is refused
    naming its key (Python reads any number of digits, which no float holds), as are
    integers too long for Python to read at all.

    Raises
    ------
    StudyError
        Not valid TOML, nested too deeply, or an integer out of range.
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"{source}: not valid TOML: {exc}") from None
    except RecursionError:
        raise StudyError(f"{source}: not valid TOML: nested too deeply") from None
    except ValueError:  # an integer of more than sys.get_int_max_str_digits() digits
        raise StudyError(f"{source}: not valid TOML: an integer has too many digits") from None
    _walk_integers(doc, "", source)
    return doc


def plain(value: Any) -> Any:
    """Return a NumPy scalar as the Python number it holds; anything else as it is.

    ``np.int64(1000)`` and ``np.float32(0.5)`` are numbers to every SciPy user, and a
    ``np.bool_`` is a boolean (refused where a number is needed, as ``True`` is).
    """
    return value.item() if isinstance(value, np.generic) else value


def check_number(value: Any, what: str) -> float:
    """Return ``value`` as a float, refusing booleans, strings and non-finite values.

    NumPy scalars are taken as the Python numbers they hold (:func:`plain`).

    Raises
    ------
    StudyError
        Naming ``what``.
    """
    value = plain(value)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise StudyError(f"{what} must be a number, got {value!r}")
    number = _as_float(value, what)
    if not math.isfinite(number):
        raise StudyError(f"{what} must be finite, got {value!r}")
    return number


def check_bound(value: Any, what: str, default: float) -> float:
    """Return a bound: a number, ``None`` (the default) or an infinity, never NaN."""
    value = plain(value)
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise StudyError(f"{what} must be a number, got {value!r}")
    number = _as_float(value, what)
    if math.isnan(number):
        raise StudyError(f"{what} must be a number, got {value!r}")
    return number


def check_whole(value: Any, what: str, low: int, high: int | None = None) -> int:
    """Return an integer in ``[low, high]``, refusing booleans and floats."""
    value = plain(value)
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


def check_windows(
    windows: Any, warmup: Any, weights: Any, where: str
) -> tuple[list[list[float]], float | list[float], list[float] | None]:
    """Return an experiment's windows, warm-up and window weights, checked.

    What can be checked without the data: pairs of numbers, each ending after it starts,
    in time order without overlap; a warm-up >= 0 (one, or one per window); one weight
    >= 0 per window, not all 0. The record's span is checked when the data are loaded
    (:func:`tsid_fmu.evaluate.windows.window_ranges`).
    """
    if isinstance(windows, str | bytes) or not hasattr(windows, "__iter__"):
        raise StudyError(f"{where}: windows must be a list of [start, end] pairs")
    spans: list[list[float]] = []
    for k, span in enumerate(windows):
        label = f"{where}: window {k + 1}"
        if isinstance(span, str | bytes) or not hasattr(span, "__len__") or len(span) != 2:
            raise StudyError(f"{label} must be a pair [start, end] in seconds, got {span!r}")
        t0, t1 = (check_number(v, label) for v in span)
        if not t1 > t0:
            raise StudyError(f"{label} [{t0:g}, {t1:g}] is reversed or empty")
        if spans and t0 < spans[-1][1]:
            raise StudyError(
                f"{label} [{t0:g}, {t1:g}] overlaps window {k} (windows must be in time "
                "order and must not overlap)"
            )
        spans.append([t0, t1])
    if isinstance(warmup, list | tuple):
        if len(warmup) != len(spans):
            raise StudyError(f"{where}: warmup has {len(warmup)} values for {len(spans)} windows")
        warm: float | list[float] = [check_number(v, f"{where}: warmup") for v in warmup]
    else:
        warm = check_number(warmup, f"{where}: warmup")
    if any(w < 0 for w in (warm if isinstance(warm, list) else [warm])):
        raise StudyError(f"{where}: warmup must be >= 0 seconds, got {warmup}")
    if weights is None:
        return spans, warm, None
    if isinstance(weights, str | bytes) or not hasattr(weights, "__iter__"):
        raise StudyError(f"{where}: window_weights must be a list of numbers")
    checked = [check_number(v, f"{where}: window_weights") for v in weights]
    if len(checked) != len(spans):
        raise StudyError(
            f"{where}: window_weights has {len(checked)} values for {len(spans)} windows"
        )
    if any(w < 0 for w in checked) or not any(checked):
        raise StudyError(f"{where}: window_weights must be >= 0 and not all 0")
    check_weight_size(checked, f"{where}: window_weights")
    return spans, warm, checked


MAX_WEIGHT = 1e12
"""Largest weight of an output or a window: weights are relative, and one of 1e308
made every cost overflow to infinity ("all 25 runs failed")."""


def check_weight_size(weights: Any, what: str) -> None:
    """Refuse a weight above :data:`MAX_WEIGHT`, naming ``what``."""
    big = [w for w in weights if w > MAX_WEIGHT]
    if big:
        raise StudyError(
            f"{what}: {big[0]:g} is above {MAX_WEIGHT:g}; weights are relative and such a "
            "weight overflows the cost: scale them to about 1"
        )


def check_uncertainty(kind: Any, replicates: Any, cost: str) -> tuple[str, int]:
    """Return ``[method] uncertainty`` and ``uncertainty_replicates``, checked.

    The sampled kinds re-fit by least squares, so they need the ``sse`` cost; at least
    20 replicates make a 95 % percentile interval (its ends are the 2.5 % quantiles).
    """
    kind = check_choice(kind, "uncertainty", UNCERTAINTY)
    replicates = check_whole(replicates, "uncertainty_replicates", 20, MAX_SAMPLED)
    if kind == "analytic" and replicates != DEFAULT_SAMPLED:
        raise StudyError(
            f"uncertainty_replicates = {replicates} has no effect with uncertainty = "
            '"analytic" (the default): give uncertainty = "bootstrap" or "monte_carlo" '
            "beside it, or leave it out"
        )
    if kind != "analytic" and cost != "sse":
        raise StudyError(
            f"uncertainty = {kind!r} re-fits by least squares, which minimises the sse cost; "
            f'the study uses {cost!r} (give cost = "sse", or uncertainty = "analytic")'
        )
    return kind, replicates
