"""Signal-to-noise ratios of the runs of an orthogonal-array experiment.

All functions are pure and vectorized; they run once per identification iteration on
a few dozen numbers.

S/N ratios (in dB, larger is always better):

* smaller-the-better: ``SN = -10 log10(mean(y**2))`` (the cost of a run, e.g.
  ``∫|F_measured - F_simulated| dt``, should be small);
* larger-the-better: ``SN = -10 log10(mean(1 / y**2))``;
* nominal-the-best: ``SN = 10 log10(mean(y)**2 / var(y))`` (sample variance).

Special values, identical for the three:

* **Perfect rows.** A mean square of 0 (smaller-the-better), an infinite ``1/y**2``
  mean (larger-the-better, some ``y == 0``) or a zero variance (nominal-the-best) would
  give ``±inf``. The result is clipped to ``±SN_CAP`` (300 dB, i.e. a mean square of
  1e-30), so that level means stay finite.
* **Failed rows.** A row with any NaN or ±inf replicate is a failed run (simulation
  error, time-out, diverged cost). It gets ``min(valid S/N) - failed_penalty`` (20 dB
  by default, i.e. ten times the RMS cost of the worst valid row), so that it is
  clearly the worst row without turning the level means into NaN. If every row has
  failed, :class:`~tsid_fmu.errors.StudyError` is raised.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from tsid_fmu.errors import StudyError

__all__ = ["SN_CAP", "sn_larger_the_better", "sn_nominal_the_best", "sn_smaller_the_better"]

#: Largest magnitude of an S/N ratio in dB; zero mean squares are clipped to it.
SN_CAP = 300.0

# ------------------------------------------------------------------------ S/N ratios


def _replicates(y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Return y as (runs, replicates) floats and the mask of failed rows."""
    arr = np.asarray(y, dtype=float)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise StudyError(
            f"responses must have shape (runs,) or (runs, replicates), got {np.shape(y)}"
        )
    failed = ~np.isfinite(arr).all(axis=1)
    if failed.all():
        raise StudyError(f"all {arr.shape[0]} runs failed (NaN or infinite response)")
    return arr, failed


def _finish(sn: np.ndarray, failed: np.ndarray, failed_penalty: float) -> np.ndarray:
    if failed_penalty < 0:
        raise StudyError(f"failed_penalty must be >= 0 dB, got {failed_penalty}")
    sn = np.clip(sn, -SN_CAP, SN_CAP) + 0.0  # + 0.0 turns -0.0 into 0.0
    sn[failed] = sn[~failed].min() - failed_penalty
    return sn


def sn_smaller_the_better(y: ArrayLike, *, failed_penalty: float = 20.0) -> np.ndarray:
    """Smaller-the-better S/N ratio of each run.

    Parameters
    ----------
    y : array_like
        Responses, shape ``(runs,)`` (one replicate) or ``(runs, replicates)``,
        normally >= 0 (a cost). Negative values are squared like any other.
    failed_penalty : float, optional
        dB below the worst valid row given to failed rows (any NaN/±inf replicate).

    Returns
    -------
    numpy.ndarray
        ``-10 log10(mean(y**2))`` per run, shape ``(runs,)``, in dB, clipped to
        ``±SN_CAP``; see the module notes for zero and failed rows.

    Raises
    ------
    StudyError
        If ``y`` has a wrong shape or every run failed.

    Examples
    --------
    >>> sn_smaller_the_better([[1.0, 1.0], [0.1, 0.1]])
    array([ 0., 20.])
    """
    arr, failed = _replicates(y)
    safe = np.where(failed[:, None], 1.0, arr)
    # a cost past 1e154 squares to inf: -inf dB, clipped to -SN_CAP like any huge cost
    with np.errstate(divide="ignore", over="ignore"):
        sn = -10.0 * np.log10(np.mean(safe**2, axis=1))
    return _finish(sn, failed, failed_penalty)


def sn_larger_the_better(y: ArrayLike, *, failed_penalty: float = 20.0) -> np.ndarray:
    """Larger-the-better S/N ratio of each run.

    Parameters
    ----------
    y : array_like
        Responses, shape ``(runs,)`` or ``(runs, replicates)``. A zero replicate
        gives ``-SN_CAP``.
    failed_penalty : float, optional
        dB below the worst valid row given to failed rows (any NaN/±inf replicate).

    Returns
    -------
    numpy.ndarray
        ``-10 log10(mean(1 / y**2))`` per run, shape ``(runs,)``, in dB, clipped to
        ``±SN_CAP``.

    Raises
    ------
    StudyError
        If ``y`` has a wrong shape or every run failed.
    """
    arr, failed = _replicates(y)
    safe = np.where(failed[:, None], 1.0, arr)
    with np.errstate(divide="ignore", over="ignore"):
        sn = -10.0 * np.log10(np.mean(1.0 / safe**2, axis=1))
    return _finish(sn, failed, failed_penalty)


def sn_nominal_the_best(y: ArrayLike, *, ddof: int = 1, failed_penalty: float = 20.0) -> np.ndarray:
    """Nominal-the-best S/N ratio of each run.

    Parameters
    ----------
    y : array_like
        Responses, shape ``(runs, replicates)`` with at least ``ddof + 1``
        replicates. Zero variance gives ``+SN_CAP``; zero mean gives ``-SN_CAP``.
    ddof : int, optional
        Delta degrees of freedom of the variance (1: sample variance).
    failed_penalty : float, optional
        dB below the worst valid row given to failed rows (any NaN/±inf replicate).

    Returns
    -------
    numpy.ndarray
        ``10 log10(mean(y)**2 / var(y))`` per run (``var`` with ``ddof``), shape
        ``(runs,)``, in dB, clipped to ``±SN_CAP``.

    Raises
    ------
    StudyError
        If there are too few replicates, ``y`` has a wrong shape or every run failed.
    """
    arr, failed = _replicates(y)
    if arr.shape[1] <= ddof:
        raise StudyError(
            f"nominal-the-best S/N needs more than {ddof} replicates per run, got {arr.shape[1]}"
        )
    safe = np.where(failed[:, None], 1.0, arr)
    # mean**2 / var does not depend on the row's scale: scaled to at most 1, responses
    # past 1e154 neither overflow nor give inf / inf = NaN
    peak = np.max(np.abs(safe), axis=1, keepdims=True)
    safe = safe / np.where(peak > 0, peak, 1.0)
    mean = safe.mean(axis=1)
    var = safe.var(axis=1, ddof=ddof)
    with np.errstate(divide="ignore", invalid="ignore"):
        sn = 10.0 * np.log10(mean**2 / var)
    sn = np.where(var == 0, SN_CAP, sn)
    return _finish(sn, failed, failed_penalty)
