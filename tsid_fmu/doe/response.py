"""Response tables: the mean response (usually S/N) per level of each factor.

Shared with :mod:`tsid_fmu.doe.anova`: the checks of a levels matrix against a response
and the per-level sums, computed once with ``numpy.bincount``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from tsid_fmu.errors import StudyError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ResponseTable", "level_stats", "prepare_design", "response_table"]


def prepare_design(
    levels_matrix: ArrayLike,
    response: ArrayLike,
    factor_names: Sequence[str],
    n_levels: Sequence[int] | None,
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], np.ndarray]:
    """Check a levels matrix against its response; return them as arrays.

    Returns
    -------
    tuple
        ``(levels as int64 (runs, factors), response (runs,), factor names, levels per
        factor)``.

    Raises
    ------
    StudyError
        On mismatched shapes, non-integer or negative levels, non-finite responses,
        duplicate names, or a level beyond ``n_levels``.
    """
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


def level_stats(lev: np.ndarray, y: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Count and sum y per (factor, level), as ``(factors, max_levels)`` arrays."""
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
    lev, y, names, k = prepare_design(levels_matrix, response, factor_names, n_levels)
    counts, sums = level_stats(lev, y, k)
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
