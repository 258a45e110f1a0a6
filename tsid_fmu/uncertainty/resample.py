"""Noise draws for sampled intervals: a block bootstrap of residuals, and AR noise.

Two ways to make a new data set that the model at the answer could have produced,
``y* = y(answer) + e*``, with ``e*`` coloured as the residuals are:

* :func:`block_bootstrap`: the residual rows, cut into blocks of :func:`block_length`
  consecutive samples that are put together in a random order (the *circular* block
  bootstrap: a block that runs past the end wraps round to the start, so that every
  sample is drawn equally often). The rows of one experiment are drawn together, so
  the outputs of a sample stay together (their cross-correlation is kept), and within a
  block the samples keep their order (the colour within a block length is kept);
* :func:`ar_draw`: a stationary Gaussian path of the AR(p) model of a residual series
  (:func:`tsid_fmu.uncertainty.longrun.fit_ar`: Yule-Walker, order by BIC), the Monte
  Carlo route; white residuals give an AR(0) model, i.e. white Gaussian noise of their
  RMS.

The block length (:func:`block_length`) is Politis and White's (2004, with the
correction of Patton, Politis and White 2009) rule for the circular block bootstrap,
``b = (2 G^2 / D)^(1/3) n^(1/3)`` with ``G = sum_k |k| gamma_k`` and ``D = 4/3 (sum_k
gamma_k)^2``, whose autocovariances ``gamma_k`` are those of the residual's AR model (not
Politis and White's flat-top lag window). White residuals give ``b = 1``: an i.i.d.
resampling of the rows, which is right for them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import signal

from tsid_fmu.uncertainty.longrun import ArNoise, fit_ar

__all__ = ["ar_draw", "block_bootstrap", "block_length", "circular_blocks", "percentile"]


def block_length(residuals: np.ndarray) -> int:
    """Return the block length for resampling ``residuals``, ``(n,)`` or ``(n, k)``.

    The Politis-White rule (module doc) for each column, from its AR model's
    autocovariances; the longest over the columns (they are drawn together), at least 1
    and at most ``n // 2``.
    """
    r = np.asarray(residuals, dtype=float)
    r = r.reshape(r.shape[0], -1)
    n = r.shape[0]
    best = 1.0
    for column in r.T:
        model = fit_ar(column - column.mean())
        if model.order == 0 or not model.innovation > 0:
            continue
        gamma = model.extend(n)
        lags = np.arange(n)
        g = 2.0 * float(np.sum(lags[1:] * gamma[1:]))
        spectrum = float(gamma[0] + 2.0 * np.sum(gamma[1:]))
        if spectrum <= 0:
            continue
        d = 4.0 / 3.0 * spectrum**2
        best = max(best, (2.0 * g * g / d) ** (1.0 / 3.0) * n ** (1.0 / 3.0))
    return int(min(max(math.ceil(best), 1), max(n // 2, 1)))


def circular_blocks(n: int, block: int, rng: np.random.Generator) -> np.ndarray:
    """Return ``n`` sample indices: blocks of ``block`` from random starts, wrapping round."""
    block = max(1, min(int(block), n))
    count = -(-n // block)
    starts = rng.integers(0, n, count)
    return ((starts[:, None] + np.arange(block)[None, :]) % n).reshape(-1)[:n]


def block_bootstrap(residuals: np.ndarray, block: int, rng: np.random.Generator) -> np.ndarray:
    """Return a circular block bootstrap draw of the rows of ``residuals`` (centred).

    Each column is centred first (the draw is noise about the answer's outputs, with no
    offset that the fit already absorbed).
    """
    r = np.asarray(residuals, dtype=float)
    centred = r - r.mean(axis=0)
    return centred[circular_blocks(r.shape[0], block, rng)]


def ar_draw(model: ArNoise, n: int, rng: np.random.Generator) -> np.ndarray:
    """Return a stationary Gaussian path of ``n`` samples of the AR model ``model``.

    The first ``p`` samples are drawn from the model's stationary distribution (the
    Toeplitz covariance of its autocovariances), the rest by the recursion, so the path
    has the model's autocovariances from its first sample on.
    """
    p = model.order
    if not model.innovation > 0:
        return np.zeros(n)
    e = rng.normal(0.0, math.sqrt(model.innovation), n)
    if p == 0:
        return e
    gamma = model.extend(p)
    cov = gamma[np.abs(np.subtract.outer(np.arange(p), np.arange(p)))]
    head = rng.multivariate_normal(np.zeros(p), cov, method="cholesky")
    if n <= p:
        return head[:n]
    a = np.concatenate([[1.0], -model.coefficients])
    zi = signal.lfiltic([1.0], a, head[::-1])
    tail = signal.lfilter([1.0], a, e[p:], zi=zi)[0]
    return np.concatenate([head, tail])


def percentile(samples: Sequence[float], level: float) -> list[float | None]:
    """Return the percentile interval ``[q((1 - level) / 2), q((1 + level) / 2)]``.

    Efron's percentile interval: the quantiles of the replicates' estimates themselves
    (NumPy's linear interpolation between order statistics); ``[None, None]`` without
    two finite samples.
    """
    s = np.asarray([v for v in samples if math.isfinite(v)], dtype=float)
    if s.size < 2:
        return [None, None]
    low, high = np.quantile(s, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return [float(low), float(high)]
