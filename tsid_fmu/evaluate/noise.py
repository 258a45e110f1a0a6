"""The parts of :func:`tsid_fmu.evaluate.cost.noise_level`: white noise and quantisation.

Two estimates of one measured column's noise, each cheap (a few sorts of ``n`` values)
and deterministic:

- :func:`white_noise`, from the differences of orders 1 to :data:`MAX_ORDER`: the
  ``k``-th difference of white noise of standard deviation ``sigma`` has variance
  ``C(2k, k) sigma**2``, while a signal sampled much faster than it changes contributes
  less at each higher order; steps and impacts touch only ``k + 1`` differences each;
- :func:`quantum`, the step of the grid on which every value of a quantised sensor
  (an encoder) lies, when the data show it acting: a rounding error spread uniformly
  over one step has the standard deviation ``q / sqrt(12)``.

:func:`column_noise` combines them.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ACTIVE", "KEEP", "MAX_ORDER", "column_noise", "quantum", "trimmed_rms", "white_noise"]

MAX_ORDER = 6
"""Highest order of differences tried."""
KEEP = 0.9
"""Share of the differences (the smallest by magnitude) kept by the trimmed RMS."""
#: RMS of the 90 % smallest (by magnitude) of standard-normal samples, relative to 1:
#: ``sqrt((p - 2 c phi(c)) / p)`` with ``p = 0.9``, ``c = Phi^-1((1 + p) / 2)``
_TRIM_RMS = 0.7893133
ACTIVE = 0.05
"""Share of second differences off zero above which a grid's rounding counts as noise."""
_ON_GRID = 1e-3  # tolerance, in steps of the grid, of a value that lies on it


def column_noise(y: np.ndarray) -> float:
    """Return the noise of one column: its rounding or its white noise.

    On a grid of step ``q`` (:func:`quantum`) whose rounding acts, a white-noise estimate
    below ``2 q / sqrt(12)`` cannot be told from the rounding alone: the differences of
    a rounded smooth signal are whole steps whose spread depends on how fast the signal
    crosses the grid (the estimate ranges from about half to twice ``q / sqrt(12)``), so
    the rounding's ``q / sqrt(12)`` is returned. Above that the noise before rounding is
    at least about ``q / 2``, which makes the rounding errors independent, and
    :func:`white_noise` (which then includes them) is returned. Noise of about ``q / 4`` to
    ``q / 2`` before rounding falls between the two and comes out up to 2 times low.

    Parameters
    ----------
    y : numpy.ndarray
        One column, at least 2 values.

    Returns
    -------
    float
        The standard deviation of the noise (0, or round-off, for a noise-free column).
    """
    white = white_noise(y)
    rounding = quantum(y) / math.sqrt(12.0)
    return rounding if white < 2.0 * rounding else white


def white_noise(y: np.ndarray) -> float:
    """Return the white-noise standard deviation of ``y``: the least over difference orders.

    For each order ``k`` (1 to :data:`MAX_ORDER`, fewer for a short column) the trimmed RMS
    of the ``k``-th differences (the :data:`KEEP` smallest by magnitude, corrected for the
    trimming of a Gaussian) over ``sqrt(C(2k, k))`` estimates the noise plus what the
    signal leaks into that order; the least of these is the order that sees the signal
    least. The trimmed RMS, not the median absolute deviation, because the differences
    of a quantised signal are mostly a few whole steps (often a median of 0).

    Parameters
    ----------
    y : numpy.ndarray
        One column, at least 2 values.

    Returns
    -------
    float
        The estimate (0 for a constant column).
    """
    best = math.inf
    d = np.asarray(y, dtype=float)
    for k in range(1, min(MAX_ORDER, d.size - 1) + 1):
        d = np.diff(d)
        best = min(best, trimmed_rms(d) / math.sqrt(math.comb(2 * k, k)))
    return best


def trimmed_rms(d: np.ndarray) -> float:
    """Return the RMS of the :data:`KEEP` smallest of ``|d|``, scaled to a Gaussian's sd."""
    a = np.abs(np.asarray(d, dtype=float))
    m = max(1, math.ceil(KEEP * a.size))
    small = np.partition(a, m - 1)[:m] if m < a.size else a
    return float(np.sqrt(np.mean(small * small))) / _TRIM_RMS


def quantum(y: np.ndarray) -> float:
    """Return the step of the grid on which every value of ``y`` lies, or 0 if none shows.

    The candidate step is the smallest first or second difference off zero; it counts if
    every value lies on that grid (relative to the first one) and at least
    :data:`ACTIVE` of the second differences are whole steps off zero, so that the
    rounding acts as noise. A straight line on a grid (a noise-free ramp), a piecewise
    constant signal (a command, a counter) or a column that never moves gives 0: their
    rounding, if any, is no noise.

    Parameters
    ----------
    y : numpy.ndarray
        One column.

    Returns
    -------
    float
        The step ``q`` (the rounding noise is then ``q / sqrt(12)``), or 0.
    """
    y = np.asarray(y, dtype=float)
    if y.size < 3 or not np.all(np.isfinite(y)):
        return 0.0
    d1 = np.diff(y)
    d2 = np.diff(d1)
    tiny = 1e-12 * max(float(np.max(np.abs(y))), 1e-300)  # float round-off of a difference
    steps = np.abs(np.concatenate([d1, d2]))
    steps = steps[steps > tiny]
    if steps.size == 0:
        return 0.0
    q = float(steps.min())
    r = (y - y[0]) / q
    if np.max(np.abs(r - np.round(r))) > _ON_GRID:
        return 0.0
    if np.mean(np.abs(d2) > q / 2) < ACTIVE:
        return 0.0
    return q
