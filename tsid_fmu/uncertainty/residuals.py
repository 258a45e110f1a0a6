"""Are the residuals white? Ljung-Box tests and long-run (HAC) covariances.

Standard errors from the Fisher matrix assume residuals that are white noise. When the
model misses something (a term, an input timing, a solver error) or the sensor is
quantised, the residuals are correlated in time, and those standard errors are too
small. This module measures that:

* :func:`ljung_box`: the Ljung-Box statistic of a residual series, with its p-value;
* :func:`bartlett_bandwidth`: Andrews' (1991) automatic bandwidth for the Bartlett kernel
  from an AR(1) fit of the series;
* :func:`long_run_covariance`: the Newey-West (1987) estimate of the long-run covariance
  of score contributions ``g_t`` (``sum over lags of Bartlett-weighted
  autocovariances``), the middle of a HAC sandwich covariance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Whiteness", "bartlett_bandwidth", "ljung_box", "long_run_covariance"]

LAGS = 20
"""Lags of the Ljung-Box test."""

ALPHA = 0.01
"""Significance level below which residuals are called coloured."""


@dataclass(frozen=True)
class Whiteness:
    """The Ljung-Box test of one residual series.

    Attributes
    ----------
    statistic : float
        ``Q = n (n + 2) sum_k rho_k^2 / (n - k)`` over ``lags`` lags.
    p_value : float
        Probability of a ``Q`` this large for white residuals (chi-square, ``lags`` dof).
    lags : int
        Lags tested.
    rho1 : float
        Lag-1 autocorrelation.
    """

    statistic: float
    p_value: float
    lags: int
    rho1: float

    @property
    def white(self) -> bool:
        """True unless the test rejects whiteness at :data:`ALPHA`."""
        return not self.p_value < ALPHA


def _autocorrelation(x: np.ndarray, lags: int) -> np.ndarray:
    x = np.asarray(x, dtype=float) - np.mean(x)
    denom = float(x @ x)
    if denom == 0:
        return np.zeros(lags + 1)
    n = x.size
    size = 1 << (2 * n - 1).bit_length()
    spec = np.fft.rfft(x, size)
    acov = np.fft.irfft(spec * np.conj(spec), size)[: lags + 1]
    return acov / denom


def ljung_box(residuals: np.ndarray, lags: int = LAGS) -> Whiteness:
    """Ljung-Box test of a residual series for autocorrelation up to ``lags``."""
    from scipy import stats

    x = np.asarray(residuals, dtype=float)
    n = x.size
    lags = max(1, min(lags, n // 4))
    rho = _autocorrelation(x, lags)
    k = np.arange(1, lags + 1)
    q = float(n * (n + 2) * np.sum(rho[1:] ** 2 / (n - k)))
    return Whiteness(q, float(stats.chi2.sf(q, lags)), lags, float(rho[1]) if lags else 0.0)


def bartlett_bandwidth(series: np.ndarray, limit: int | None = None) -> int:
    """Andrews' automatic bandwidth (Bartlett kernel) from the series' AR(1) coefficient.

    ``L = 1.1447 (alpha n)^(1/3)`` with ``alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)``;
    at most ``limit`` (default ``n / 4``).
    """
    x = np.asarray(series, dtype=float)
    n = x.size
    limit = n // 4 if limit is None else limit
    if n < 3:
        return 0
    rho = float(_autocorrelation(x, 1)[1])
    rho = min(max(rho, -0.999), 0.999)
    alpha = 4 * rho * rho / ((1 - rho) ** 2 * (1 + rho) ** 2)
    return int(min(max(math.ceil(1.1447 * (alpha * n) ** (1 / 3)), 0), limit))


def long_run_covariance(scores: np.ndarray, bandwidth: int) -> np.ndarray:
    """Newey-West long-run covariance ``sum_l w_l (G_l + G_l^T)`` of ``scores``.

    Parameters
    ----------
    scores : numpy.ndarray
        ``(n, p)`` score contributions ``g_t`` in time order.
    bandwidth : int
        Bartlett bandwidth ``L``: lag ``l`` gets the weight ``1 - l / (L + 1)``.

    Returns
    -------
    numpy.ndarray
        ``(p, p)``, symmetric positive semi-definite.
    """
    g = np.asarray(scores, dtype=float)
    out = g.T @ g
    for lag in range(1, min(bandwidth, g.shape[0] - 1) + 1):
        gamma = g[lag:].T @ g[:-lag]
        out += (1.0 - lag / (bandwidth + 1.0)) * (gamma + gamma.T)
    return out
