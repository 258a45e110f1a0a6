"""``anova`` split along its steps (issue 26) gives bit-identical tables.

The reference below is ``anova`` as one function, before the split; both run on every
standard array with random, rounded and constant responses and each pooling rule.
"""

from __future__ import annotations

import numpy as np
import pytest

from tsid_fmu.doe.anova import AnovaTable, _auto_pool, _f_tests, _pooled, anova
from tsid_fmu.doe.arrays import get_array
from tsid_fmu.doe.response import level_stats, prepare_design
from tsid_fmu.errors import StudyError


def _reference(levels_matrix, response, factor_names, *, pool="auto", pool_fraction=0.5):
    lev, y, names, k = prepare_design(levels_matrix, response, factor_names, None)
    if not 0.0 <= pool_fraction <= 1.0:
        raise StudyError(f"pool_fraction must be in [0, 1], got {pool_fraction}")
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
        raise StudyError("too many degrees of freedom")
    residual_ss = ss_total - float(ss.sum())
    if residual_ss < 1e-10 * max(ss_total, np.finfo(float).tiny):
        residual_ss = 0.0
    if isinstance(pool, str) and pool == "auto":
        pooled_idx = _auto_pool(ss, dof, residual_dof, pool_fraction * dof_total)
    else:
        pooled_idx = _pooled(pool, names)
    is_pooled = np.zeros(len(names), dtype=bool)
    is_pooled[pooled_idx] = True
    error_ss = residual_ss + float(ss[is_pooled].sum())
    error_dof = residual_dof + int(dof[is_pooled].sum())
    error_ms = error_ss / error_dof if error_dof > 0 else np.nan
    ms, f_ratio, p_value = _f_tests(ss, dof, error_ms, error_dof, is_pooled)
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

    def as_dict(values, cast=float):
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


@pytest.mark.parametrize("name", ["L4", "L8", "L9", "L12", "L16", "L18", "L25", "L27"])
def test_anova_is_bit_identical_to_the_one_function_it_was(name):
    rng = np.random.default_rng(26)
    table = np.asarray(get_array(name).table)
    compared = 0
    for k in range(1, table.shape[1] + 1):
        lev, names = table[:, :k], [f"f{i}" for i in range(k)]
        for y in (
            rng.normal(size=len(table)) * 10.0 ** rng.integers(-3, 3),
            np.round(rng.normal(size=len(table)), 1),
            np.full(len(table), 2.5),
        ):
            for pool, frac in (("auto", 0.5), (None, 0.5), ("auto", 0.0), ("auto", 1.0),
                               (names[:1], 0.5)):  # fmt: skip
                try:
                    want = _reference(lev, y, names, pool=pool, pool_fraction=frac)
                except StudyError:
                    with pytest.raises(StudyError):
                        anova(lev, y, names, pool=pool, pool_fraction=frac)
                    continue
                got = anova(lev, y, names, pool=pool, pool_fraction=frac)
                assert repr(got) == repr(want), (name, k, pool, frac)
                compared += 1
    assert compared > 0
