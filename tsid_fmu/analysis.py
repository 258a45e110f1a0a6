"""Signal-to-noise ratios, response tables and ANOVA of an orthogonal-array experiment.

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

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from tsid_fmu.errors import StudyError

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "SN_CAP",
    "AnovaTable",
    "ResponseTable",
    "anova",
    "response_table",
    "sn_larger_the_better",
    "sn_nominal_the_best",
    "sn_smaller_the_better",
]

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
    msd = np.mean(safe**2, axis=1)
    with np.errstate(divide="ignore"):
        sn = -10.0 * np.log10(msd)
    return _finish(sn, failed, failed_penalty)


def sn_larger_the_better(y: ArrayLike, *, failed_penalty: float = 20.0) -> np.ndarray:
    """Larger-the-better S/N ratio of each run, ``-10 log10(mean(1 / y**2))``.

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
        S/N per run in dB, shape ``(runs,)``.

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
    """Nominal-the-best S/N ratio of each run, ``10 log10(mean(y)**2 / var(y))``.

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
        S/N per run in dB, shape ``(runs,)``.

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
    mean = safe.mean(axis=1)
    var = safe.var(axis=1, ddof=ddof)
    with np.errstate(divide="ignore", invalid="ignore"):
        sn = 10.0 * np.log10(mean**2 / var)
    sn = np.where(var == 0, SN_CAP, sn)
    return _finish(sn, failed, failed_penalty)


# ------------------------------------------------------------- shared preparation


def _prepare(
    levels_matrix: ArrayLike,
    response: ArrayLike,
    factor_names: Sequence[str],
    n_levels: Sequence[int] | None,
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], np.ndarray]:
    lev = np.asarray(levels_matrix)
    if lev.ndim == 1:
        lev = lev[:, None]
    if lev.ndim != 2 or lev.size == 0:
        raise StudyError(
            f"levels_matrix must have shape (runs, factors), got {np.shape(levels_matrix)}"
        )
    if not np.issubdtype(lev.dtype, np.integer):
        if not np.issubdtype(lev.dtype, np.number) or not np.all(lev == np.round(lev)):
            raise StudyError("levels_matrix must hold integer (0-based) level indices")
    lev = lev.astype(np.int64)
    y = np.asarray(response, dtype=float)
    if y.ndim != 1 or y.shape[0] != lev.shape[0]:
        raise StudyError(
            f"response must have shape ({lev.shape[0]},) to match levels_matrix, got {y.shape}"
        )
    if not np.isfinite(y).all():
        raise StudyError(
            f"response has non-finite values in runs {np.flatnonzero(~np.isfinite(y)) + 1}; "
            "convert costs to S/N ratios first (they map failed runs to finite values)"
        )
    names = tuple(str(n) for n in factor_names)
    if isinstance(factor_names, str) or len(names) != lev.shape[1]:
        raise StudyError(
            f"{lev.shape[1]} factor columns but factor_names has "
            f"{1 if isinstance(factor_names, str) else len(names)} entries"
        )
    if len(set(names)) != len(names):
        raise StudyError(f"duplicate factor names in {list(names)}")
    if lev.min() < 0:
        raise StudyError("levels_matrix holds negative levels; levels must be 0-based")
    observed = lev.max(axis=0) + 1
    if n_levels is None:
        k = observed
    else:
        k = np.asarray(n_levels, dtype=np.int64)
        if k.shape != (lev.shape[1],):
            raise StudyError(f"n_levels must have {lev.shape[1]} entries, got {len(k)}")
        too_high = np.flatnonzero(observed > k)
        if too_high.size:
            f = int(too_high[0])
            raise StudyError(
                f"factor {names[f]!r} uses level {observed[f]} (1-based) but n_levels says {k[f]}"
            )
    return lev, y, names, k


def _level_stats(lev: np.ndarray, y: np.ndarray, k: np.ndarray):
    """Count and sum y per (factor, level), as (factors, max_levels) arrays."""
    n_factors = lev.shape[1]
    width = int(k.max())
    codes = (lev + np.arange(n_factors) * width).ravel()
    size = n_factors * width
    counts = np.bincount(codes, minlength=size).reshape(n_factors, width)
    sums = np.bincount(codes, weights=np.repeat(y, n_factors), minlength=size)
    return counts, sums.reshape(n_factors, width)


# ----------------------------------------------------------------- response table


@dataclass(frozen=True)
class ResponseTable:
    """Mean response (usually S/N) per level of each factor.

    Attributes
    ----------
    factor_names : tuple of str
        The factors, in input order.
    means : dict of str to numpy.ndarray
        Mean response at each level (0-based index); NaN for a level no run used.
    delta : dict of str to float
        ``max - min`` of the level means.
    rank : dict of str to int
        1 for the factor with the largest delta (ties: earlier factor first).
    best_level : dict of str to int
        0-based level with the largest mean (larger S/N is better).
    grand_mean : float
        Mean of all responses.
    """

    factor_names: tuple[str, ...]
    means: dict[str, np.ndarray]
    delta: dict[str, float]
    rank: dict[str, int]
    best_level: dict[str, int]
    grand_mean: float

    @property
    def matrix(self) -> np.ndarray:
        """Level means as a ``(factors, max_levels)`` array, NaN-padded."""
        width = max(len(m) for m in self.means.values())
        out = np.full((len(self.factor_names), width), np.nan)
        for i, name in enumerate(self.factor_names):
            out[i, : len(self.means[name])] = self.means[name]
        return out

    def to_pandas(self) -> pd.DataFrame:
        """Return the table like Minitab's response table for S/N ratios.

        Returns
        -------
        pandas.DataFrame
            One row per factor; columns ``"level 1"`` .. ``"level k"``, ``"delta"``
            and ``"rank"``.
        """
        import pandas as pd

        m = self.matrix
        df = pd.DataFrame(
            m,
            index=pd.Index(self.factor_names, name="factor"),
            columns=[f"level {j + 1}" for j in range(m.shape[1])],
        )
        df["delta"] = [self.delta[n] for n in self.factor_names]
        df["rank"] = [self.rank[n] for n in self.factor_names]
        return df

    def __repr__(self) -> str:
        m = self.matrix
        name_w = max(6, *(len(n) for n in self.factor_names))
        head = [f"{'factor':<{name_w}}"] + [f"{f'level {j + 1}':>10}" for j in range(m.shape[1])]
        lines = ["ResponseTable(", "  " + " ".join([*head, f"{'delta':>10}", f"{'rank':>5}"])]
        for i, n in enumerate(self.factor_names):
            cells = [f"{v:>10.4g}" for v in m[i]]
            lines.append(
                "  "
                + " ".join(
                    [f"{n:<{name_w}}", *cells, f"{self.delta[n]:>10.4g}", f"{self.rank[n]:>5d}"]
                )
            )
        lines.append(")")
        return "\n".join(lines)


def response_table(
    levels_matrix: ArrayLike,
    response: ArrayLike,
    factor_names: Sequence[str],
    n_levels: Sequence[int] | None = None,
) -> ResponseTable:
    """Mean response per level of each factor, with delta, rank and best level.

    Parameters
    ----------
    levels_matrix : array_like of int
        ``(runs, factors)`` 0-based level of each factor in each run (the array
        columns assigned to the factors).
    response : array_like
        ``(runs,)`` finite response per run, usually the S/N ratio.
    factor_names : sequence of str
        One distinct name per column of ``levels_matrix``.
    n_levels : sequence of int, optional
        Number of levels of each factor; default ``max level + 1``. Levels no run
        used get a NaN mean.

    Returns
    -------
    ResponseTable

    Raises
    ------
    StudyError
        On inconsistent shapes, names or levels, or non-finite responses.
    """
    lev, y, names, k = _prepare(levels_matrix, response, factor_names, n_levels)
    counts, sums = _level_stats(lev, y, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = sums / counts
    valid = np.arange(means.shape[1])[None, :] < k[:, None]
    means = np.where(valid & (counts > 0), means, np.nan)
    delta = np.nanmax(means, axis=1) - np.nanmin(means, axis=1)
    best = np.nanargmax(means, axis=1)
    order = np.argsort(-delta, kind="stable")
    rank = np.empty(len(names), dtype=int)
    rank[order] = np.arange(1, len(names) + 1)
    return ResponseTable(
        factor_names=names,
        means={n: means[i, : k[i]].copy() for i, n in enumerate(names)},
        delta={n: float(delta[i]) for i, n in enumerate(names)},
        rank={n: int(rank[i]) for i, n in enumerate(names)},
        best_level={n: int(best[i]) for i, n in enumerate(names)},
        grand_mean=float(y.mean()),
    )


# -------------------------------------------------------------------------- ANOVA


@dataclass(frozen=True)
class AnovaTable:
    """Analysis of variance of a main-effects orthogonal-array experiment.

    Attributes
    ----------
    factor_names : tuple of str
        The factors, in input order (pooled ones included).
    dof, ss, ms : dict of str to float
        Degrees of freedom, sum of squares and mean square of each factor.
    f, p : dict of str to float
        F-ratio ``ms / error_ms`` and its p-value; NaN for pooled factors or when
        the error has no degrees of freedom.
    contribution : dict of str to float
        Plain percent contribution ``100 ss / ss_total``.
    pure_contribution : dict of str to float
        ``100 (ss - dof error_ms) / ss_total`` floored at 0 (0 for pooled factors;
        equal to the plain one when the error has no degrees of freedom).
    pooled : list of str
        Factors pooled into the error term.
    ss_total, dof_total : float, int
        Total (corrected) sum of squares and ``runs - 1``.
    error_ss, error_dof, error_ms : float, int, float
        Error term after pooling (residual plus pooled factors).
    error_contribution, error_pure_contribution : float
        Percent contribution of the error; the pure one is ``100 - Σ pure factors``.
    """

    factor_names: tuple[str, ...]
    dof: dict[str, int]
    ss: dict[str, float]
    ms: dict[str, float]
    f: dict[str, float]
    p: dict[str, float]
    contribution: dict[str, float]
    pure_contribution: dict[str, float]
    pooled: list[str]
    ss_total: float
    dof_total: int
    error_ss: float
    error_dof: int
    error_ms: float
    error_contribution: float
    error_pure_contribution: float
    residual_ss: float = field(repr=False, default=0.0)
    residual_dof: int = field(repr=False, default=0)

    def to_pandas(self) -> pd.DataFrame:
        """Return the ANOVA table.

        Returns
        -------
        pandas.DataFrame
            Rows: the factors, ``"error"`` (after pooling) and ``"total"``; columns
            ``dof, SS, MS, F, p, contribution %, pure contribution %, pooled``.
        """
        import pandas as pd

        rows = []
        for n in self.factor_names:
            rows.append(
                [
                    self.dof[n],
                    self.ss[n],
                    self.ms[n],
                    self.f[n],
                    self.p[n],
                    self.contribution[n],
                    self.pure_contribution[n],
                    n in self.pooled,
                ]
            )
        rows.append(
            [
                self.error_dof,
                self.error_ss,
                self.error_ms,
                np.nan,
                np.nan,
                self.error_contribution,
                self.error_pure_contribution,
                False,
            ]
        )
        rows.append([self.dof_total, self.ss_total, np.nan, np.nan, np.nan, 100.0, 100.0, False])
        columns = ["dof", "SS", "MS", "F", "p", "contribution %", "pure contribution %", "pooled"]
        df = pd.DataFrame(rows, index=[*self.factor_names, "error", "total"], columns=columns)
        df.index.name = "source"
        return df

    def __repr__(self) -> str:
        name_w = max(6, *(len(n) for n in self.factor_names))
        lines = [
            "AnovaTable(",
            f"  {'source':<{name_w}} {'dof':>4} {'SS':>11} {'MS':>11} {'F':>9} {'p':>8}"
            f" {'P %':>7} {'pure %':>7}",
        ]

        def row(name: str, dof, ss, ms, f, p, c, pc, tag="") -> str:
            return (
                f"  {name:<{name_w}} {dof:>4d} {ss:>11.5g} {ms:>11.5g} {f:>9.4g} {p:>8.3g}"
                f" {c:>7.2f} {pc:>7.2f}{tag}"
            )

        for n in self.factor_names:
            tag = "  (pooled)" if n in self.pooled else ""
            lines.append(
                row(
                    n,
                    self.dof[n],
                    self.ss[n],
                    self.ms[n],
                    self.f[n],
                    self.p[n],
                    self.contribution[n],
                    self.pure_contribution[n],
                    tag,
                )
            )
        lines.append(
            row(
                "error",
                self.error_dof,
                self.error_ss,
                self.error_ms,
                np.nan,
                np.nan,
                self.error_contribution,
                self.error_pure_contribution,
            )
        )
        lines.append(
            row("total", self.dof_total, self.ss_total, np.nan, np.nan, np.nan, 100.0, 100.0)
        )
        lines.append(")")
        return "\n".join(lines)


def _auto_pool(
    names: tuple[str, ...],
    ss: np.ndarray,
    dof: np.ndarray,
    residual_dof: int,
    dof_total: int,
    pool_fraction: float,
) -> list[int]:
    """Pick the factors the "auto" rule pools (see :func:`anova`); return their indices."""
    target = pool_fraction * dof_total
    chosen: list[int] = []
    error_dof = residual_dof
    for i in np.argsort(ss, kind="stable"):
        if error_dof >= target or len(chosen) == len(names) - 1:
            break
        chosen.append(int(i))
        error_dof += int(dof[i])
    return chosen


def anova(
    levels_matrix: ArrayLike,
    response: ArrayLike,
    factor_names: Sequence[str],
    *,
    n_levels: Sequence[int] | None = None,
    pool: str | Sequence[str] | None = "auto",
    pool_fraction: float = 0.5,
) -> AnovaTable:
    """Main-effects ANOVA with Taguchi's pooling.

    For each factor: ``dof = levels - 1`` (levels used by some run),
    ``SS = Σ_level n_level (mean_level - grand_mean)**2``, ``MS = SS / dof``. The
    residual is ``SS_T - Σ SS`` on ``(runs - 1) - Σ dof`` degrees of freedom (the
    empty columns of the array). Pooled factors are moved into the error term;
    then ``F = MS / MS_error`` with p-value ``scipy.stats.f.sf(F, dof, dof_error)``.

    Parameters
    ----------
    levels_matrix : array_like of int
        ``(runs, factors)`` 0-based level of each factor in each run.
    response : array_like
        ``(runs,)`` finite response (usually S/N ratio).
    factor_names : sequence of str
        One distinct name per factor.
    n_levels : sequence of int, optional
        Number of levels of each factor; default ``max level + 1``.
    pool : {"auto"} or str or sequence of str or None, optional
        ``None``: pool nothing. A factor name or a list of names: pool exactly those
        (use ``["auto"]`` for a factor named "auto"). ``"auto"`` (default): Taguchi's
        rule of thumb of pooling the weak factors until the error has about half of
        the total degrees of freedom: factors are pooled in order of increasing SS
        while the error dof is below ``pool_fraction * (runs - 1)``, always leaving
        at least one factor unpooled. A saturated array (error dof 0) therefore gets
        its smallest factors pooled; an array with enough empty columns gets none.
    pool_fraction : float, optional
        Target share of the total dof for the "auto" rule, in [0, 1]; 0 disables
        automatic pooling. Default 0.5.

    Returns
    -------
    AnovaTable

    Raises
    ------
    StudyError
        On inconsistent inputs, unknown pooled names, pooling every factor, or more
        factor degrees of freedom than the runs allow.
    """
    from scipy import stats

    lev, y, names, k = _prepare(levels_matrix, response, factor_names, n_levels)
    if not 0.0 <= pool_fraction <= 1.0:
        raise StudyError(f"pool_fraction must be in [0, 1], got {pool_fraction}")
    n_runs = y.shape[0]
    counts, sums = _level_stats(lev, y, k)
    grand = y.mean()
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(counts > 0, sums / np.maximum(counts, 1), grand)
    ss = (counts * (means - grand) ** 2).sum(axis=1)
    dof = (counts > 0).sum(axis=1) - 1
    ss_total = float(((y - grand) ** 2).sum())
    dof_total = n_runs - 1
    residual_dof = dof_total - int(dof.sum())
    if residual_dof < 0:
        raise StudyError(
            f"the factors have {int(dof.sum())} degrees of freedom but {n_runs} runs allow "
            f"only {dof_total}"
        )
    residual_ss = ss_total - float(ss.sum())
    if residual_ss < 1e-10 * max(ss_total, np.finfo(float).tiny):
        residual_ss = 0.0

    if pool is None:
        pooled_idx: list[int] = []
    elif isinstance(pool, str) and pool == "auto":
        pooled_idx = _auto_pool(names, ss, dof, residual_dof, dof_total, pool_fraction)
    else:
        wanted = [pool] if isinstance(pool, str) else list(pool)
        unknown = [n for n in wanted if n not in names]
        if unknown:
            raise StudyError(f"cannot pool unknown factors {unknown}; factors are {list(names)}")
        pooled_idx = sorted({names.index(n) for n in wanted})
        if len(pooled_idx) == len(names):
            raise StudyError("cannot pool every factor: at least one must stay in the table")
    is_pooled = np.zeros(len(names), dtype=bool)
    is_pooled[pooled_idx] = True

    error_ss = residual_ss + float(ss[is_pooled].sum())
    error_dof = residual_dof + int(dof[is_pooled].sum())
    error_ms = error_ss / error_dof if error_dof > 0 else np.nan

    with np.errstate(invalid="ignore", divide="ignore"):
        ms = np.where(dof > 0, ss / np.maximum(dof, 1), 0.0)
        if error_dof > 0:
            f_ratio = np.where(ss > 0, ms / error_ms, 0.0)
            p_value = stats.f.sf(f_ratio, np.maximum(dof, 1), error_dof)
            p_value = np.where(ss > 0, p_value, 1.0)
        else:
            f_ratio = np.full(len(names), np.nan)
            p_value = np.full(len(names), np.nan)
    f_ratio = np.where(is_pooled | (dof == 0), np.nan, f_ratio)
    p_value = np.where(is_pooled | (dof == 0), np.nan, p_value)

    if ss_total > 0:
        contribution = 100.0 * ss / ss_total
        ve = error_ms if error_dof > 0 else 0.0
        pure = np.maximum(100.0 * (ss - dof * ve) / ss_total, 0.0)
        error_contribution = 100.0 * error_ss / ss_total
    else:
        contribution = np.zeros(len(names))
        pure = np.zeros(len(names))
        error_contribution = 0.0
    pure = np.where(is_pooled, 0.0, pure)
    error_pure = 100.0 - float(pure.sum()) if ss_total > 0 else 0.0

    def as_dict(values: np.ndarray, cast=float) -> dict:
        return {n: cast(values[i]) for i, n in enumerate(names)}

    return AnovaTable(
        factor_names=names,
        dof=as_dict(dof, int),
        ss=as_dict(ss),
        ms=as_dict(ms),
        f=as_dict(f_ratio),
        p=as_dict(p_value),
        contribution=as_dict(contribution),
        pure_contribution=as_dict(pure),
        pooled=[names[i] for i in pooled_idx],
        ss_total=ss_total,
        dof_total=dof_total,
        error_ss=error_ss,
        error_dof=error_dof,
        error_ms=float(error_ms),
        error_contribution=float(error_contribution),
        error_pure_contribution=float(error_pure),
        residual_ss=residual_ss,
        residual_dof=residual_dof,
    )
