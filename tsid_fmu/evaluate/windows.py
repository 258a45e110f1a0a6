"""Time windows: the spans of a record that are scored.

A simulation always runs the whole record from its first sample (the model's state must
pass through the warm-up to reach a window), so a window only chooses which samples the
cost, the residuals and every diagnostic drawn from them see. A
:class:`~tsid_fmu.evaluate.spec.PreparedExperiment` holds its windows as sample ranges
``[start, stop)`` (``()``: the whole record, scored as before windows existed, bit for
bit) and a weight per window.

Each window is scored as a record of its own and the windows' costs are summed with
their weights: for the ``sse`` cost that is the sum of ``weight * error**2`` over the
scored samples, and the residuals an evaluator returns are the scored samples'
``sqrt(weight) * (simulated - measured) / scale``, one window after the other, so that
their sum of squares is still the cost. The integral costs (``iae``, ``ise``) integrate
each window on its own, never across the gap between two.

:func:`window_ranges` turns a study's windows in seconds into these ranges and refuses,
naming the experiment, a window outside the record, reversed, overlapping another, or
holding fewer than two samples after its warm-up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.cost import COSTS, Cost, fit_percent, metrics

__all__ = [
    "MIN_WINDOW_SAMPLES",
    "check_ranges",
    "head_ranges",
    "scored_metrics",
    "select",
    "weighted_rows",
    "window_cost",
    "window_ranges",
]

MIN_WINDOW_SAMPLES = 2
"""Fewest samples a window must score (an integral cost needs two)."""

Ranges = tuple[tuple[int, int], ...]


def window_ranges(
    name: str,
    time: np.ndarray,
    spans: Sequence[Sequence[float]],
    warmup: float | Sequence[float] = 0.0,
) -> Ranges:
    """Return the sample ranges ``[start, stop)`` scored by windows given in seconds.

    Parameters
    ----------
    name : str
        The experiment, for messages.
    time : numpy.ndarray
        The record's sample times (increasing).
    spans : sequence of (t0, t1)
        The windows; empty: the whole record (then only ``warmup`` applies).
    warmup : float or sequence of float
        Seconds at the start of each window (one value for all, or one per window)
        that are simulated but not scored.

    Raises
    ------
    StudyError
        Naming the experiment: a window reversed or empty, outside the record,
        overlapping the one before, or with fewer than :data:`MIN_WINDOW_SAMPLES`
        samples after its warm-up.
    """
    where = f"experiment {name!r}"
    t = np.asarray(time, dtype=float)
    first, last = float(t[0]), float(t[-1])
    whole = not spans
    spans = [(first, last)] if whole else [(float(a), float(b)) for a, b in spans]
    warm = [float(warmup)] * len(spans) if isinstance(warmup, int | float) else list(warmup)
    if len(warm) != len(spans):
        raise StudyError(f"{where}: warmup has {len(warm)} values for {len(spans)} windows")
    slack = 1e-9 * max(abs(first), abs(last), last - first, 1e-300)
    out: list[tuple[int, int]] = []
    for k, ((t0, t1), w) in enumerate(zip(spans, warm, strict=True)):
        label = "the record" if whole else f"window {k + 1} [{t0:g}, {t1:g}] s"
        if not t1 > t0:
            raise StudyError(f"{where}: {label} is reversed or empty (it ends before it starts)")
        if t0 < first - slack or t1 > last + slack:
            raise StudyError(
                f"{where}: {label} lies outside the record, which runs from {first:g} to {last:g} s"
            )
        if out and t0 < spans[k - 1][1]:
            raise StudyError(
                f"{where}: {label} overlaps window {k} (windows must be in time order and "
                "must not overlap)"
            )
        start = int(np.searchsorted(t, t0 + w - slack, side="left"))
        stop = int(np.searchsorted(t, t1 + slack, side="right"))
        if out:  # windows that touch share no sample: it belongs to the first one
            start = max(start, out[-1][1])
        if stop - start < MIN_WINDOW_SAMPLES:
            after = f" after its warm-up of {w:g} s" if w else ""
            raise StudyError(
                f"{where}: {label} holds {max(stop - start, 0)} samples{after}; a window "
                f"must score at least {MIN_WINDOW_SAMPLES}"
            )
        out.append((start, stop))
    return tuple(out)


def check_ranges(ranges: Ranges, weights: Sequence[float], n: int) -> str | None:
    """Return what is wrong with sample ranges and their weights, or None if nothing."""
    last = 0
    for start, stop in ranges:
        if not last <= start < stop <= n:
            return f"windows must be increasing, disjoint sample ranges within 0..{n}: {ranges}"
        last = stop
    if len(weights) != len(ranges):
        return f"{len(weights)} window weights for {len(ranges)} windows"
    if any(not (math.isfinite(w) and w >= 0) for w in weights) or (weights and not any(weights)):
        return f"window weights must be finite, >= 0 and not all 0, got {list(weights)}"
    return None


def select(ranges: Ranges, a: np.ndarray) -> np.ndarray:
    """Return the rows of ``a`` that the windows score (``a`` itself without windows)."""
    if not ranges:
        return a
    return np.concatenate([a[start:stop] for start, stop in ranges])


def weighted_rows(ranges: Ranges, weights: Sequence[float], a: np.ndarray) -> np.ndarray:
    """Return the scored rows of ``a``, each multiplied by the square root of its weight."""
    if not ranges:
        return a
    parts = []
    for (start, stop), w in zip(ranges, weights, strict=True):
        part = a[start:stop]
        parts.append(part if w == 1.0 else part * math.sqrt(w))
    return np.concatenate(parts)


def window_cost(
    ranges: Ranges,
    weights: Sequence[float],
    cost: Cost,
    time: np.ndarray,
    measured: np.ndarray,
    simulated: np.ndarray,
) -> np.ndarray:
    """Return the cost of each output: every window's, times its weight, summed."""
    if not ranges:
        return cost.per_output(time, measured, simulated)
    total = np.zeros(measured.shape[1])
    for (start, stop), w in zip(ranges, weights, strict=True):
        total += w * cost.per_output(time[start:stop], measured[start:stop], simulated[start:stop])
    return total


def scored_metrics(
    ranges: Ranges,
    time: np.ndarray,
    measured: np.ndarray,
    simulated: np.ndarray,
    names: Sequence[str],
) -> dict[str, dict[str, float]]:
    """Return every cost kind and the fit percentage of each output on the scored samples.

    The sums and means (``sse``, ``rmse``, ``nrmse``, fit %) are over the scored samples
    together, the integrals (``iae``, ``ise``) the sum of each window's (window weights
    do not enter: these describe the fit, they are not the cost).
    """
    if not ranges:
        return metrics(time, measured, simulated, names)
    y, s = select(ranges, measured), select(ranges, simulated)
    t = select(ranges, time)
    e = s - y
    out: dict[str, dict[str, float]] = {n: {} for n in names}
    for kind, fn in COSTS.items():
        if kind in ("iae", "ise"):
            values = sum(
                fn(time[a:b], simulated[a:b] - measured[a:b], measured[a:b]) for a, b in ranges
            )
        else:
            values = fn(t, e, y)
        for n, v in zip(names, np.atleast_1d(values), strict=True):
            out[n][kind] = float(v)
    for n, v in zip(names, fit_percent(y, s), strict=True):
        out[n]["fit_percent"] = float(v)
    return out


def head_ranges(ranges: Ranges, n: int, fraction: float, min_samples: int) -> tuple[int, Ranges]:
    """Return where to cut a windowed record to score its first ``fraction``, and its ranges.

    The cut keeps ``ceil(fraction * scored)`` of the scored samples (at least
    ``min_samples``, at most all of them); the windows past the cut are dropped and
    the one it falls in is shortened.
    """
    scored = sum(b - a for a, b in ranges)
    want = min(scored, max(min_samples, math.ceil(fraction * scored)))
    kept: list[tuple[int, int]] = []
    for a, b in ranges:
        take = min(b - a, want)
        if take <= 0:
            break
        kept.append((a, a + take))
        want -= take
    cut = kept[-1][1] if kept[-1][1] < ranges[-1][1] else n
    return cut, tuple(kept)
