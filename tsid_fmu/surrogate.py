"""Quadratic response surface over an orthogonal array's runs.

Main effects assume the factors act additively. Where two parameters interact along a
valley (the cost depends on their ratio, as the natural frequency ``sqrt(K_s / M_m)``
does) the main-effects optimum misses the valley. The same runs also support a
quadratic model with interactions (an L25 has 25 runs for the 21 coefficients of five
factors), whose optimum follows the valley. The engine only *proposes* that optimum
as one more confirmation run; whether it is taken is decided by its simulated cost.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.optimize import minimize

__all__ = ["quadratic_optimum"]


def _features(z: np.ndarray, interactions: bool) -> np.ndarray:
    cols = [np.ones(len(z))]
    cols += [z[:, j] for j in range(z.shape[1])]
    cols += [z[:, j] ** 2 for j in range(z.shape[1])]
    if interactions:
        cols += [z[:, i] * z[:, j] for i, j in itertools.combinations(range(z.shape[1]), 2)]
    return np.column_stack(cols)


def quadratic_optimum(z: np.ndarray, response: np.ndarray) -> np.ndarray | None:
    """Return the maximiser of a quadratic fit of ``response`` within the box ``[-1, 1]^k``.

    Parameters
    ----------
    z : numpy.ndarray
        Factor settings of each run scaled to ``[-1, 1]``, shape ``(runs, k)``.
    response : numpy.ndarray
        Response to maximise (e.g. the S/N ratio), shape ``(runs,)``; non-finite
        entries (failed runs) are left out.

    Returns
    -------
    numpy.ndarray or None
        The maximiser, shape ``(k,)``, or None when there are too few runs for even a
        quadratic without interactions.
    """
    z = np.asarray(z, dtype=float)
    y = np.asarray(response, dtype=float)
    ok = np.isfinite(y)
    z, y = z[ok], y[ok]
    k = z.shape[1]
    full = 1 + 2 * k + k * (k - 1) // 2
    if len(y) > full:
        interactions = True
    elif len(y) > 1 + 2 * k:
        interactions = False
    else:
        return None
    try:
        coef, *_ = np.linalg.lstsq(_features(z, interactions), y, rcond=None)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(coef)):
        return None

    def negative(x: np.ndarray) -> float:
        return -float((_features(x[None, :], interactions) @ coef)[0])

    start = z[int(np.argmax(y))]
    res = minimize(negative, start, bounds=[(-1.0, 1.0)] * k, method="L-BFGS-B")
    return np.clip(res.x, -1.0, 1.0) if np.all(np.isfinite(res.x)) else None
