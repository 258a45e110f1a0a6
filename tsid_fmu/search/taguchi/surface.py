"""The cost surface as the array runs show it: principal axes for rotated factors.

Every run of an iteration leaves its residual signal ``r`` (simulated minus measured
outputs, scaled as in the cost). A linear regression of those signals on the runs'
search coordinates, ``r ~ r0 + J (s - c)``, is the array's *vector* main-effects
analysis: with an orthogonal array the columns of ``J`` are each factor's main effect on
the whole output signal. ``J^T J`` is then the Gauss-Newton curvature of the cost
surface around the centre, and its eigenvectors are the combinations of parameters that
the data determine (large eigenvalue) or barely see (small eigenvalue). No extra
simulation is run: the regression uses the runs of the last iterations only.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["principal_axes"]


def principal_axes(
    points: Sequence[tuple[np.ndarray, np.ndarray]], centre: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Return the principal axes of the local cost curvature, stiffest first.

    Parameters
    ----------
    points : sequence of (s, residual)
        Search coordinates and residual signal of each run.
    centre : numpy.ndarray
        Point the linear model is taken about.

    Returns
    -------
    directions : numpy.ndarray
        ``(p, p)``; column ``k`` is the ``k``-th axis (unit vector in search coordinates).
    curvatures : numpy.ndarray
        ``(p,)`` eigenvalues of ``J^T J``, decreasing.
    None
        Too few runs (fewer than ``p + 2``), residuals of different lengths, or
        residuals so large (past about 1e154) that the curvature is not finite.
    """
    p = len(centre)
    usable = [(s, r) for s, r in points if r is not None]
    if len(usable) < p + 2 or len({r.size for _, r in usable}) != 1:
        return None
    x = np.column_stack([np.ones(len(usable)), np.array([s - centre for s, _ in usable])])
    if np.linalg.matrix_rank(x) < p + 1:
        return None
    signals = np.array([r for _, r in usable])
    if not np.all(np.isfinite(signals)):
        return None
    with np.errstate(over="ignore", invalid="ignore"):  # huge residuals: checked below
        coef = np.linalg.lstsq(x, signals, rcond=None)[0]
        jac = coef[1:]  # (p, N): row k = effect of coordinate k on the residual signal
        curvature = jac @ jac.T
    if not np.all(np.isfinite(curvature)):
        return None  # no axes: the next frame keeps the kind it has
    values, vectors = np.linalg.eigh(curvature)
    order = np.argsort(values)[::-1]
    vectors = vectors[:, order]
    # a sign convention, so that the same surface gives the same factors
    vectors *= np.where(vectors[np.argmax(np.abs(vectors), axis=0), range(p)] < 0, -1.0, 1.0)
    return vectors, np.maximum(values[order], 0.0)
