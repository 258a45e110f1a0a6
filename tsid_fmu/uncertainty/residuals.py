"""Are the residuals white? Ljung-Box tests.

Standard errors from the Fisher matrix assume residuals that are white noise. When the
model misses something (a term, an input timing, a solver error) or the sensor is
quantised, the residuals are correlated in time, and those standard errors are too
small. :func:`ljung_box` gives the Ljung-Box statistic of a residual series, with its
p-value; :mod:`tsid_fmu.uncertainty.longrun` estimates how much wider the intervals must
be.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tsid_fmu.numerics.tuning import LAGS
from tsid_fmu.numerics.tuning import RESIDUALS_ALPHA as ALPHA

__all__ = ["Whiteness", "ljung_box"]


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
