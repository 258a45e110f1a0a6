"""Long-run covariance of the score from an AR(p) model of each residual series.

The Fisher matrix ``F = J^T J`` of whitened residuals gives the covariance ``F^-1`` only
for white residuals. For residuals ``r`` with autocovariance ``Gamma`` (a stationary
series, ``Gamma`` Toeplitz) the covariance of a least-squares estimate is the sandwich
``F^-1 S F^-1`` with ``S = sum over series of J^T Gamma J``: the Jacobian is fixed
(the inputs are known), so ``S`` needs only ``Gamma``. This module estimates ``Gamma``
from an autoregressive model of each series, the parametric (feasible GLS) route rather
than a kernel estimate of ``S`` (Newey-West), whose small bandwidths at a few hundred
samples miss a large part of a positive correlation:

* :func:`fit_ar`: Yule-Walker AR(p) fit (Levinson-Durbin) of a residual series, ``p``
  chosen by BIC up to ``10 log10 n`` (as R's ``ar()``);
* the fit's residuals are shorter-correlated than the noise (the fit absorbs part of it,
  as it absorbs ``p`` of ``n`` degrees of freedom of white noise): the autocovariances
  of the model are corrected once so that, under the model, the *expected* residual
  autocovariances ``E[r^T S_l r] / n = tr(S_l M Gamma M) / n`` (``M = I - J F^-1 J^T``)
  equal the observed ones (a method-of-moments, REML-like correction);
* :func:`long_run_covariance`: ``S`` with the corrected models (exact Toeplitz products
  through the FFT), and the delta-method variance of each ``(F^-1 S F^-1)_jj`` from the
  asymptotic covariance of the AR estimates (Yule-Walker: ``sigma_e^2 Gamma_p^-1 / n``;
  innovation variance: ``2 sigma_e^4 / n``), which gives a Satterthwaite number of
  degrees of freedom for the intervals (:mod:`tsid_fmu.uncertainty.intervals`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import signal

from tsid_fmu.numerics.tuning import LONGRUN_STEP as STEP

__all__ = ["ArNoise", "LongRun", "fit_ar", "long_run_covariance", "max_order"]


@dataclass(frozen=True)
class ArNoise:
    """An AR(p) model of one residual series.

    Attributes
    ----------
    autocovariance : numpy.ndarray
        ``gamma_0 .. gamma_p``; the model's autocovariances beyond ``p`` follow from the
        Yule-Walker recursion.
    coefficients : numpy.ndarray
        ``phi_1 .. phi_p`` of ``r_t = sum_k phi_k r_(t-k) + e_t``.
    innovation : float
        Variance of ``e_t``.
    """

    autocovariance: np.ndarray
    coefficients: np.ndarray
    innovation: float

    @property
    def order(self) -> int:
        """``p``."""
        return int(self.coefficients.size)

    @property
    def rho1(self) -> float:
        """Lag-1 autocorrelation of the model."""
        g = self.autocovariance
        return float(g[1] / g[0]) if g.size > 1 and g[0] > 0 else 0.0

    def extend(self, n: int) -> np.ndarray:
        """Return the model's autocovariances ``gamma_0 .. gamma_(n-1)``."""
        g, p = self.autocovariance, self.order
        out = np.zeros(n)
        out[: min(n, p + 1)] = g[: min(n, p + 1)]
        if p and n > p + 1:
            a = np.concatenate([[1.0], -self.coefficients])
            zi = signal.lfiltic([1.0], a, g[p:0:-1])
            out[p + 1 :] = signal.lfilter([1.0], a, np.zeros(n - p - 1), zi=zi)[0]
        return out


def _levinson(gamma: np.ndarray) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Levinson-Durbin: coefficients of orders 1..p, innovation variances 0..p, reflections."""
    p = gamma.size - 1
    phi, v = np.zeros(0), float(gamma[0])
    coefficients, variances, reflections = [], [v], []
    for k in range(1, p + 1):
        kappa = (gamma[k] - phi @ gamma[k - 1 : 0 : -1]) / v if v > 0 else 0.0
        phi = np.concatenate([phi - kappa * phi[::-1], [kappa]])
        v *= 1.0 - kappa * kappa
        coefficients.append(phi)
        variances.append(v)
        reflections.append(kappa)
    return coefficients, np.array(variances), np.array(reflections)


def _model(gamma: np.ndarray) -> ArNoise | None:
    """Return the AR model whose first autocovariances are ``gamma`` (None: not stationary)."""
    if not gamma[0] > 0:
        return None
    coefficients, variances, reflections = _levinson(gamma)
    if reflections.size and not np.all(np.abs(reflections) < 1.0):
        return None
    phi = coefficients[-1] if coefficients else np.zeros(0)
    return ArNoise(np.asarray(gamma, dtype=float), phi, float(variances[-1]))


def _from_coefficients(phi: np.ndarray, innovation: float) -> np.ndarray | None:
    """``gamma_0 .. gamma_p`` of the AR(p) process ``phi`` (None unless stationary)."""
    p = phi.size
    system = np.eye(p + 1)
    for lag in range(p + 1):
        for k in range(1, p + 1):
            system[lag, abs(lag - k)] -= phi[k - 1]
    rhs = np.zeros(p + 1)
    rhs[0] = innovation
    try:
        gamma = np.linalg.solve(system, rhs)
    except np.linalg.LinAlgError:
        return None
    return gamma if gamma[0] > 0 else None


def max_order(n: int) -> int:
    """Highest AR order tried for ``n`` samples: ``10 log10 n``, below ``n / 2``."""
    return max(0, min(int(10 * math.log10(n)) if n > 1 else 0, n // 2 - 1))


def _autocovariances(r: np.ndarray, lags: int) -> np.ndarray:
    """``sum_t r_t r_(t+l) / n`` for ``l = 0 .. lags`` (zero mean assumed: the noise)."""
    n = r.size
    size = 1 << (2 * n - 1).bit_length()
    spec = np.fft.rfft(r, size)
    return np.fft.irfft(spec * np.conj(spec), size)[: lags + 1] / n


def fit_ar(residuals: np.ndarray, order: int | None = None) -> ArNoise:
    """Yule-Walker AR fit of a residual series, its order by BIC (``order``: fixed).

    The autocovariances are not centred: the residuals of a fit stand for zero-mean
    noise, and an offset the model misses is part of what the intervals must allow for.
    """
    r = np.asarray(residuals, dtype=float)
    n = r.size
    top = max_order(n) if order is None else min(order, max(n - 1, 0))
    gamma = _autocovariances(r, top) if n else np.zeros(1)
    if not gamma[0] > 0:
        return ArNoise(np.zeros(1), np.zeros(0), 0.0)
    _, variances, _ = _levinson(gamma)
    if order is None:
        positive = np.maximum(variances, 1e-300 * gamma[0])
        bic = n * np.log(positive) + np.arange(top + 1) * math.log(n)
        top = int(np.argmin(bic))
    found = _model(gamma[: top + 1])
    return found if found is not None else ArNoise(gamma[:1], np.zeros(0), float(gamma[0]))


class _Series:
    """One residual series and its Jacobian, with their spectra for Toeplitz products."""

    def __init__(self, jacobian: np.ndarray, inverse: np.ndarray) -> None:
        self.n = jacobian.shape[0]
        self.inverse = inverse
        self.size = 1 << max(2 * self.n - 1, 1).bit_length()
        self.spectrum = np.fft.rfft(jacobian, self.size, axis=0)  # (f, q)
        self.projected = self.spectrum @ inverse  # rows of F^-1 J^T, as spectra
        weights = np.full(self.spectrum.shape[0], 2.0)
        weights[0] = 1.0
        if self.size % 2 == 0:
            weights[-1] = 1.0
        self.weights = weights / self.size

    def kernel(self, gamma: np.ndarray) -> np.ndarray:
        """Real spectrum of the symmetric circular embedding of ``gamma_0 .. gamma_(n-1)``."""
        c = np.zeros(self.size)
        c[: self.n] = gamma
        c[self.size - self.n + 1 :] = gamma[:0:-1]
        return np.fft.rfft(c).real

    def middle(self, kernel: np.ndarray) -> np.ndarray:
        """``J^T Gamma J``."""
        s = self.spectrum
        return ((s.conj() * (kernel * self.weights)[:, None]).T @ s).real

    def variance(self, kernel: np.ndarray) -> np.ndarray:
        """Diagonal of ``F^-1 J^T Gamma J F^-1``."""
        return (kernel * self.weights) @ np.abs(self.projected) ** 2

    def lagged(self, x: np.ndarray, y: np.ndarray, lags: int) -> np.ndarray:
        """``sum_t x_(t+l) . y_t`` for ``l = 0 .. lags``, from the spectra of ``x`` and ``y``."""
        cross = np.sum(x * y.conj(), axis=1)
        return np.fft.irfft(cross, self.size)[: lags + 1]

    def expected(self, model: ArNoise, kernel: np.ndarray, outer: np.ndarray) -> np.ndarray:
        """``E[sum_t r_t r_(t+l)] / n`` for ``l = 0 .. p``, under ``model``.

        ``outer`` is ``F^-1 Omega F^-1``, ``Omega`` the ``S`` of every series.
        """
        p, n = model.order, self.n
        s = self.spectrum
        product = np.fft.irfft(kernel[:, None] * s, self.size, axis=0)[:n]  # Gamma J
        g = np.fft.rfft(product, self.size, axis=0)
        total = (n - np.arange(p + 1)) * model.autocovariance
        total -= self.lagged(s, g @ self.inverse, p) + self.lagged(g, self.projected, p)
        total += self.lagged(s, s @ outer, p)
        return total / n


@dataclass
class LongRun:
    """The long-run covariance of the score and what it rests on.

    Attributes
    ----------
    middle : numpy.ndarray
        ``S = sum over series of J^T Gamma J``, ``(q, q)``.
    variance : numpy.ndarray
        Delta-method variance of each diagonal element of ``F^-1 S F^-1``.
    models : list of ArNoise
        The corrected AR model of each series.
    """

    middle: np.ndarray
    variance: np.ndarray
    models: list[ArNoise]


def _corrected(series: list[_Series], models: list[ArNoise], inverse: np.ndarray) -> list[ArNoise]:
    """One moment step: models whose expected residual autocovariances are the observed."""
    kernels = [s.kernel(m.extend(s.n)) for s, m in zip(series, models, strict=True)]
    omega = sum((s.middle(k) for s, k in zip(series, kernels, strict=True)), np.zeros_like(inverse))
    outer = inverse @ omega @ inverse
    out = []
    for s, m, k in zip(series, models, kernels, strict=True):
        gamma = m.autocovariance
        better = _model(gamma + (gamma - s.expected(m, k, outer))) if gamma[0] > 0 else None
        out.append(better if better is not None else m)
    return out


def _delta_variance(s: _Series, m: ArNoise, diagonal: np.ndarray) -> np.ndarray:
    """Variance of ``diag(F^-1 J^T Gamma J F^-1)`` from the uncertainty of ``m``."""
    out = 2.0 * diagonal**2 / max(s.n, 1)
    p = m.order
    if not p or not m.innovation > 0:
        return out
    gradient = np.zeros((p, diagonal.size))
    for i in range(p):
        phi = m.coefficients.copy()
        phi[i] += STEP
        gamma = _from_coefficients(phi, m.innovation)
        moved = _model(gamma) if gamma is not None else None
        if moved is not None:
            gradient[i] = (s.variance(s.kernel(moved.extend(s.n))) - diagonal) / STEP
    toeplitz = m.autocovariance[np.abs(np.subtract.outer(np.arange(p), np.arange(p)))]
    cov = m.innovation * np.linalg.pinv(toeplitz) / s.n
    return out + np.einsum("iq,ij,jq->q", gradient, cov, gradient)


def long_run_covariance(
    series: Sequence[tuple[np.ndarray, np.ndarray]], inverse: np.ndarray
) -> LongRun:
    """Long-run covariance of the score of every residual series (module doc).

    Parameters
    ----------
    series : sequence of (residuals, jacobian)
        Per experiment and output, in time order: the whitened residuals ``(n,)`` and
        their derivatives ``(n, q)`` with respect to the ``q`` coordinates. Series may
        differ in length; they are taken as independent of each other.
    inverse : numpy.ndarray
        ``F^-1``, the (pseudo-)inverse of the Fisher matrix of all the series.

    Returns
    -------
    LongRun
    """
    inverse = np.asarray(inverse, dtype=float)
    prepared = [_Series(np.asarray(jac, dtype=float), inverse) for _, jac in series]
    models = _corrected(prepared, [fit_ar(r) for r, _ in series], inverse)
    middle = np.zeros_like(inverse)
    variance = np.zeros(inverse.shape[0])
    for s, m in zip(prepared, models, strict=True):
        kernel = s.kernel(m.extend(s.n))
        middle += s.middle(kernel)
        variance += _delta_variance(s, m, s.variance(kernel))
    return LongRun(middle, variance, models)
