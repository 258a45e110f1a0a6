"""Signal-to-noise ratios of the runs of an orthogonal-array experiment.

All functions are pure and vectorized; they run once per identification iteration on
a few dozen numbers.

S/N ratios (in dB, larger is always better):

* smaller-the-better: ``SN = -10 log10(mean(y**2))`` (the cost of a run, e.g.
  ``∫|F_measured - F_simulated| dt``, should be small);
* larger-the-better: ``SN = -10 log10(mean(1 / y**2))``;
* nominal-the-best: ``SN = 10 log10(mean(y)**2 / var(y))`` (sample variance).

Special values, identical for the three:

* **Exact fits.** A mean square of 0 (smaller-the-better) or a zero variance
  (nominal-the-best) would give ``+inf``. Only these are capped: at ``SN_CAP``
  (300 dB, i.e. a mean square of 1e-30), or at the best other row where that is
  higher, so that level means stay finite and an exact fit is never below an inexact
  one.
* **Bad rows are not floored.** Each ratio is computed in logarithms (a row scaled by
  its largest or smallest magnitude first), so a cost of 1e200 gives -4000 dB, not an
  overflow clipped to a floor: on the SISO example five of 25 rows of an array read
  -300 where one was -318.6, and the floor fed the ANOVA.
* **Failed and infinitely bad rows.** A row with any NaN or ±inf replicate is a failed
  run (simulation error, time-out, diverged cost), and a row whose ratio is ``-inf``
  (a zero replicate, larger-the-better; a zero mean, nominal-the-best) is as bad as
  one. Each gets ``min(other S/N) - failed_penalty`` (20 dB by default, i.e. ten times
  the RMS cost of the worst other row), so that it is clearly the worst row without
  turning the level means into NaN (``-SN_CAP`` where no row is finite). If every
  row has failed, :class:`~tsid_fmu.errors.StudyError` is raised.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from tsid_fmu.errors import StudyError

__all__ = ["SN_CAP", "sn_larger_the_better", "sn_nominal_the_best", "sn_smaller_the_better"]

#: The S/N ratio in dB of an exact fit (a zero mean square or variance), at least.
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
    """Cap exact fits, and put failed and infinitely bad rows below the others."""
    if failed_penalty < 0:
        raise StudyError(f"failed_penalty must be >= 0 dB, got {failed_penalty}")
    sn = np.where(failed, np.nan, sn) + 0.0  # + 0.0 turns -0.0 into 0.0
    finite = sn[np.isfinite(sn)]
    top = max(SN_CAP, float(finite.max())) if finite.size else SN_CAP
    bottom = float(finite.min()) - failed_penalty if finite.size else -SN_CAP
    sn[sn == np.inf] = top
    sn[~np.isfinite(sn)] = bottom  # failed rows (NaN) and -inf alike
    return sn


def _log10_mean_square(ratio: np.ndarray, log_scale: np.ndarray) -> np.ndarray:
    """Return ``log10(mean(ratio**2)) + 2 log_scale`` per row.

    ``ratio`` is a row divided by one of its own magnitudes (at most 1 in size), and
    ``log_scale`` that magnitude's ``log10``, so that neither the squares of 1e200 nor
    those of 1e-200 leave the floating-point range.
    """
    return np.log10(np.mean(ratio**2, axis=1)) + 2.0 * log_scale


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
        ``-10 log10(mean(y**2))`` per run, shape ``(runs,)``, in dB, exact fits
        capped at ``SN_CAP``; see the module notes for zero and failed rows.

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
    safe = np.abs(np.where(failed[:, None], 1.0, arr))
    peak = safe.max(axis=1)
    sn = np.full(len(safe), np.inf)  # a row of zeros is an exact fit
    some = peak > 0
    sn[some] = -10.0 * _log10_mean_square(safe[some] / peak[some, None], np.log10(peak[some]))
    return _finish(sn, failed, failed_penalty)


def sn_larger_the_better(y: ArrayLike, *, failed_penalty: float = 20.0) -> np.ndarray:
    """Larger-the-better S/N ratio of each run.

    Parameters
    ----------
    y : array_like
        Responses, shape ``(runs,)`` or ``(runs, replicates)``. A zero replicate
        makes the row as bad as a failed one.
    failed_penalty : float, optional
        dB below the worst valid row given to failed rows (any NaN/±inf replicate).

    Returns
    -------
    numpy.ndarray
        ``-10 log10(mean(1 / y**2))`` per run, shape ``(runs,)``, in dB.

    Raises
    ------
    StudyError
        If ``y`` has a wrong shape or every run failed.
    """
    arr, failed = _replicates(y)
    safe = np.abs(np.where(failed[:, None], 1.0, arr))
    least = safe.min(axis=1)
    sn = np.full(len(safe), -np.inf)  # a zero replicate: infinitely bad
    some = least > 0
    # mean(1 / y**2) = mean((least / y)**2) / least**2, each term at most 1
    sn[some] = -10.0 * _log10_mean_square(least[some, None] / safe[some], -np.log10(least[some]))
    return _finish(sn, failed, failed_penalty)


def sn_nominal_the_best(y: ArrayLike, *, ddof: int = 1, failed_penalty: float = 20.0) -> np.ndarray:
    """Nominal-the-best S/N ratio of each run.

    Parameters
    ----------
    y : array_like
        Responses, shape ``(runs, replicates)`` with at least ``ddof + 1``
        replicates. Zero variance is an exact fit (``SN_CAP``); a zero mean makes the row as
        bad as a failed one.
    ddof : int, optional
        Delta degrees of freedom of the variance (1: sample variance).
    failed_penalty : float, optional
        dB below the worst valid row given to failed rows (any NaN/±inf replicate).

    Returns
    -------
    numpy.ndarray
        ``10 log10(mean(y)**2 / var(y))`` per run (``var`` with ``ddof``), shape
        ``(runs,)``, in dB, exact fits capped at ``SN_CAP``.

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
        sn = 20.0 * np.log10(np.abs(mean)) - 10.0 * np.log10(var)
    sn = np.where(var == 0, np.inf, sn)  # an exact fit; a zero mean is -inf
    return _finish(sn, failed, failed_penalty)
