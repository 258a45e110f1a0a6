"""Main-effects ANOVA of an orthogonal-array experiment, with Taguchi's pooling."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from tsid_fmu.doe.response import level_stats, prepare_design
from tsid_fmu.errors import StudyError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["AnovaTable", "anova"]


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

    def _rows(self) -> list[tuple[str, list]]:
        """Return the rows, ``(source, [dof, SS, MS, F, p, P %, pure %, pooled])``."""
        rows = [
            (
                n,
                [
                    self.dof[n],
                    self.ss[n],
                    self.ms[n],
                    self.f[n],
                    self.p[n],
                    self.contribution[n],
                    self.pure_contribution[n],
                    n in self.pooled,
                ],
            )
            for n in self.factor_names
        ]
        error = [self.error_dof, self.error_ss, self.error_ms, np.nan, np.nan]
        error += [self.error_contribution, self.error_pure_contribution, False]
        rows.append(("error", error))
        total = [self.dof_total, self.ss_total, np.nan, np.nan, np.nan, 100.0, 100.0, False]
        rows.append(("total", total))
        return rows

    def to_pandas(self) -> pd.DataFrame:
        """Return the ANOVA table.

        Returns
        -------
        pandas.DataFrame
            Rows: the factors, ``"error"`` (after pooling) and ``"total"``; columns
            ``dof, SS, MS, F, p, contribution %, pure contribution %, pooled``.
        """
        import pandas as pd

        rows = self._rows()
        columns = ["dof", "SS", "MS", "F", "p", "contribution %", "pure contribution %", "pooled"]
        df = pd.DataFrame(
            [values for _, values in rows], index=[name for name, _ in rows], columns=columns
        )
        df.index.name = "source"
        return df

    def __repr__(self) -> str:
        name_w = max(6, *(len(n) for n in self.factor_names))
        lines = [
            "AnovaTable(",
            f"  {'source':<{name_w}} {'dof':>4} {'SS':>11} {'MS':>11} {'F':>9} {'p':>8}"
            f" {'P %':>7} {'pure %':>7}",
        ]
        for name, (dof, ss, ms, f, p, c, pc, pooled) in self._rows():
            tag = "  (pooled)" if pooled else ""
            lines.append(
                f"  {name:<{name_w}} {dof:>4d} {ss:>11.5g} {ms:>11.5g} {f:>9.4g} {p:>8.3g}"
                f" {c:>7.2f} {pc:>7.2f}{tag}"
            )
        lines.append(")")
        return "\n".join(lines)


def _auto_pool(ss: np.ndarray, dof: np.ndarray, residual_dof: int, target: float) -> list[int]:
    """Pick the factors the "auto" rule pools (see :func:`anova`); return their indices.

    Factors join the error term in order of increasing SS while its degrees of freedom
    (the residual's and theirs) are below ``target``; one factor always stays.
    """
    chosen: list[int] = []
    error_dof = residual_dof
    for i in np.argsort(ss, kind="stable"):
        if error_dof >= target or len(chosen) == len(ss) - 1:
            break
        chosen.append(int(i))
        error_dof += int(dof[i])
    return chosen


@dataclass(frozen=True)
class _Squares:
    """Sums of squares of a main-effects design, before any pooling (step 1 of anova)."""

    ss: np.ndarray
    dof: np.ndarray
    ss_total: float
    dof_total: int
    residual_ss: float
    residual_dof: int


def _squares(lev: np.ndarray, y: np.ndarray, k: np.ndarray) -> _Squares:
    """Return each factor's SS and dof, the total, and the residual (the empty columns).

    Raises
    ------
    StudyError
        The factors have more degrees of freedom than the runs allow.
    """
    n_runs = y.shape[0]
    counts, sums = level_stats(lev, y, k)
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
    return _Squares(ss, dof, ss_total, dof_total, residual_ss, residual_dof)


def _contributions(
    sq: _Squares, is_pooled: np.ndarray, error_ss: float, error_ms: float, error_dof: int
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Return the percent contributions: plain and pure per factor, then of the error."""
    if sq.ss_total > 0:
        contribution = 100.0 * sq.ss / sq.ss_total
        ve = error_ms if error_dof > 0 else 0.0
        pure = np.maximum(100.0 * (sq.ss - sq.dof * ve) / sq.ss_total, 0.0)
        error_contribution = 100.0 * error_ss / sq.ss_total
    else:
        contribution = np.zeros(len(sq.ss))
        pure = np.zeros(len(sq.ss))
        error_contribution = 0.0
    pure = np.where(is_pooled, 0.0, pure)
    error_pure = 100.0 - float(pure.sum()) if sq.ss_total > 0 else 0.0
    return contribution, pure, error_contribution, error_pure


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
    lev, y, names, k = prepare_design(levels_matrix, response, factor_names, n_levels)
    if not 0.0 <= pool_fraction <= 1.0:
        raise StudyError(f"pool_fraction must be in [0, 1], got {pool_fraction}")
    sq = _squares(lev, y, k)
    if isinstance(pool, str) and pool == "auto":
        pooled_idx = _auto_pool(sq.ss, sq.dof, sq.residual_dof, pool_fraction * sq.dof_total)
    else:
        pooled_idx = _pooled(pool, names)
    return _table(names, sq, pooled_idx)


def _table(names: tuple[str, ...], sq: _Squares, pooled_idx: list[int]) -> AnovaTable:
    """Return the ANOVA table of the sums of squares ``sq`` with ``pooled_idx`` pooled."""
    is_pooled = np.zeros(len(names), dtype=bool)
    is_pooled[pooled_idx] = True
    error_ss = sq.residual_ss + float(sq.ss[is_pooled].sum())
    error_dof = sq.residual_dof + int(sq.dof[is_pooled].sum())
    error_ms = error_ss / error_dof if error_dof > 0 else np.nan
    ms, f_ratio, p_value = _f_tests(sq.ss, sq.dof, error_ms, error_dof, is_pooled)
    contribution, pure, error_contribution, error_pure = _contributions(
        sq, is_pooled, error_ss, error_ms, error_dof
    )

    def as_dict(values: np.ndarray, cast=float) -> dict:
        return {n: cast(values[i]) for i, n in enumerate(names)}

    return AnovaTable(
        factor_names=names,
        dof=as_dict(sq.dof, int),
        ss=as_dict(sq.ss),
        ms=as_dict(ms),
        f=as_dict(f_ratio),
        p=as_dict(p_value),
        contribution=as_dict(contribution),
        pure_contribution=as_dict(pure),
        pooled=[names[i] for i in pooled_idx],
        ss_total=sq.ss_total,
        dof_total=sq.dof_total,
        error_ss=error_ss,
        error_dof=error_dof,
        error_ms=float(error_ms),
        error_contribution=float(error_contribution),
        error_pure_contribution=float(error_pure),
        residual_ss=sq.residual_ss,
        residual_dof=sq.residual_dof,
    )


def _pooled(pool: str | Sequence[str] | None, names: tuple[str, ...]) -> list[int]:
    """Return the indices of the factors ``pool`` names (see :func:`anova`; not "auto")."""
    if pool is None:
        return []
    wanted = [pool] if isinstance(pool, str) else list(pool)
    unknown = [n for n in wanted if n not in names]
    if unknown:
        raise StudyError(f"cannot pool unknown factors {unknown}; factors are {list(names)}")
    pooled_idx = sorted({names.index(n) for n in wanted})
    if len(pooled_idx) == len(names):
        raise StudyError("cannot pool every factor: at least one must stay in the table")
    return pooled_idx


def _f_tests(
    ss: np.ndarray, dof: np.ndarray, error_ms: float, error_dof: int, is_pooled: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return mean squares, F ratios and p-values (NaN where pooled or no error dof)."""
    from scipy import stats

    with np.errstate(invalid="ignore", divide="ignore"):
        ms = np.where(dof > 0, ss / np.maximum(dof, 1), 0.0)
        if error_dof > 0:
            f_ratio = np.where(ss > 0, ms / error_ms, 0.0)
            p_value = stats.f.sf(f_ratio, np.maximum(dof, 1), error_dof)
            p_value = np.where(ss > 0, p_value, 1.0)
        else:
            f_ratio = np.full(len(ss), np.nan)
            p_value = np.full(len(ss), np.nan)
    f_ratio = np.where(is_pooled | (dof == 0), np.nan, f_ratio)
    p_value = np.where(is_pooled | (dof == 0), np.nan, p_value)
    return ms, f_ratio, p_value
