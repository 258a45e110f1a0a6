from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from tsid_fmu.doe import (
    SN_CAP,
    anova,
    get_array,
    response_table,
    sn_larger_the_better,
    sn_nominal_the_best,
    sn_smaller_the_better,
)
from tsid_fmu.errors import StudyError

# Hand-worked example: L9, factors A, B, C on columns 1, 2, 4 (1-based).
Y9 = np.array([8, 12, 9, 11, 12, 15, 21, 18, 20], dtype=float)
NAMES = ["A", "B", "C"]


@pytest.fixture
def lev9():
    return get_array("L9").table[:, [0, 1, 3]]


# ------------------------------------------------------------------------- S/N


def test_sn_smaller_the_better_simple_numbers():
    np.testing.assert_allclose(sn_smaller_the_better([1.0, 10.0, 0.1]), [0.0, -20.0, 20.0])
    # Replicates: mean of squares (1 + 9) / 2 = 5.
    np.testing.assert_allclose(sn_smaller_the_better([[1.0, 3.0]]), [-10 * np.log10(5.0)])
    assert sn_smaller_the_better([[2.0, 2.0], [1.0, 1.0]]).shape == (2,)


def test_sn_smaller_the_better_zero_is_capped():
    sn = sn_smaller_the_better([0.0, 1.0])
    assert sn[0] == SN_CAP and sn[1] == 0.0
    # an exact fit is never below an inexact row past the cap
    assert sn_smaller_the_better([0.0, 1e-16]).tolist() == [320.0, 320.0]


def test_sn_bad_rows_are_not_floored():
    """Only exact fits are capped (issue 64, item 4): a bad row keeps its ratio.

    The SISO example's array had five of 25 rows at -300 dB, one of them -318.6: the
    floor made them equal in the ANOVA.
    """
    costs = np.array([10**15.93, 10**15.2, 10**17.0, 1.0])
    sn = sn_smaller_the_better(costs)
    np.testing.assert_allclose(sn, [-318.6, -304.0, -340.0, 0.0])
    assert (np.argsort(sn) == np.argsort(-costs)).all()
    assert sn_smaller_the_better([1e300, 1.0, np.nan]).tolist() == [-6000.0, 0.0, -6020.0]
    assert np.isfinite(sn).all()


def test_sn_failed_rows_are_worst_finite():
    sn = sn_smaller_the_better([1.0, np.nan, 10.0, np.inf, -np.inf])
    assert np.isfinite(sn).all()
    np.testing.assert_allclose(sn, [0.0, -40.0, -20.0, -40.0, -40.0])
    sn = sn_smaller_the_better([1.0, np.nan, 10.0], failed_penalty=5.0)
    assert sn[1] == pytest.approx(-25.0)
    # One failed replicate fails the whole row.
    sn = sn_smaller_the_better([[1.0, 1.0], [1.0, np.nan]])
    assert sn[1] == pytest.approx(-20.0)


def test_sn_all_failed_raises():
    with pytest.raises(StudyError, match="all 2 runs failed"):
        sn_smaller_the_better([np.nan, np.inf])


@pytest.mark.parametrize("bad", [[], [[]], np.zeros((2, 2, 2))])
def test_sn_bad_shape(bad):
    with pytest.raises(StudyError):
        sn_smaller_the_better(bad)


def test_sn_larger_and_nominal():
    np.testing.assert_allclose(sn_larger_the_better([1.0, 10.0, 0.1]), [0.0, 20.0, -20.0])
    # a zero replicate is infinitely bad: placed like a failed row, 20 dB below the rest
    assert sn_larger_the_better([0.0, 1.0])[0] == -20.0
    y = np.array([[9.0, 11.0], [10.0, 10.0], [8.0, 12.0]])
    sn = sn_nominal_the_best(y)
    assert sn[0] == pytest.approx(10 * np.log10(100 / 2))
    assert sn[1] == SN_CAP
    assert sn[2] == pytest.approx(10 * np.log10(100 / 8))
    with pytest.raises(StudyError, match="replicates"):
        sn_nominal_the_best([1.0, 2.0])
    with pytest.raises(StudyError):
        sn_smaller_the_better([1.0], failed_penalty=-1.0)


@settings(max_examples=50, deadline=None)
@given(
    st.lists(st.floats(min_value=1e-6, max_value=1e6), min_size=1, max_size=30),
    st.floats(min_value=1e-3, max_value=1e3),
)
def test_sn_smaller_scaling(ys, scale):
    """Scaling the cost by c shifts the S/N by -20 log10(c)."""
    y = np.array(ys)
    np.testing.assert_allclose(
        sn_smaller_the_better(scale * y),
        sn_smaller_the_better(y) - 20 * np.log10(scale),
        atol=1e-9,
    )


# -------------------------------------------------------------- response table


def test_response_table_hand_example(lev9):
    rt = response_table(lev9, Y9, NAMES)
    np.testing.assert_allclose(rt.means["A"], [29 / 3, 38 / 3, 59 / 3])
    np.testing.assert_allclose(rt.means["B"], [40 / 3, 14.0, 44 / 3])
    np.testing.assert_allclose(rt.means["C"], [40 / 3, 16.0, 38 / 3])
    assert rt.delta == pytest.approx({"A": 10.0, "B": 4 / 3, "C": 10 / 3})
    assert rt.rank == {"A": 1, "C": 2, "B": 3}
    assert rt.best_level == {"A": 2, "B": 2, "C": 1}
    assert rt.grand_mean == pytest.approx(14.0)
    assert rt.factor_names == ("A", "B", "C")
    assert rt.matrix.shape == (3, 3)


def test_response_table_pandas_and_repr(lev9):
    rt = response_table(lev9, Y9, NAMES)
    df = rt.to_pandas()
    assert list(df.columns) == ["level 1", "level 2", "level 3", "delta", "rank"]
    assert list(df.index) == NAMES
    assert df.loc["C", "level 2"] == pytest.approx(16.0)
    assert df.loc["B", "rank"] == 3
    text = repr(rt)
    assert "level 3" in text and "delta" in text and "19.67" in text


def test_response_table_mixed_levels_pads_with_nan():
    l18 = get_array("L18").table[:, [0, 1]]
    y = np.arange(18.0)
    rt = response_table(l18, y, ["two", "three"])
    assert len(rt.means["two"]) == 2 and len(rt.means["three"]) == 3
    assert np.isnan(rt.matrix[0, 2])
    assert rt.best_level == {"two": 1, "three": 2}
    df = rt.to_pandas()
    assert np.isnan(df.loc["two", "level 3"])


def test_response_table_unused_level_with_n_levels(lev9):
    rt = response_table(lev9, Y9, NAMES, n_levels=[3, 3, 4])
    assert len(rt.means["C"]) == 4 and np.isnan(rt.means["C"][3])
    assert rt.delta["C"] == pytest.approx(10 / 3)


def test_response_table_accepts_sn_of_failed_rows(lev9):
    cost = Y9.copy()
    cost[4] = np.nan
    rt = response_table(lev9, sn_smaller_the_better(cost), NAMES)
    assert all(np.isfinite(m).all() for m in rt.means.values())


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"response": Y9[:8]}, "response must have shape"),
        ({"factor_names": ["A", "B"]}, "factor_names has 2"),
        ({"factor_names": ["A", "A", "B"]}, "duplicate"),
        ({"response": np.where(np.arange(9) == 2, np.nan, Y9)}, "non-finite"),
        ({"n_levels": [3, 3, 2]}, "n_levels says 2"),
        ({"levels_matrix": -np.ones((9, 3), dtype=int)}, "negative"),
        ({"levels_matrix": np.full((9, 3), 0.5)}, "integer"),
    ],
)
def test_response_table_validation(lev9, kwargs, match):
    args = {"levels_matrix": lev9, "response": Y9, "factor_names": NAMES, **kwargs}
    with pytest.raises(StudyError, match=match):
        response_table(**args)


# ------------------------------------------------------------------------ ANOVA


def test_anova_hand_example_unpooled(lev9):
    a = anova(lev9, Y9, NAMES, pool=None)
    assert a.ss == pytest.approx({"A": 158.0, "B": 8 / 3, "C": 56 / 3})
    assert a.dof == {"A": 2, "B": 2, "C": 2}
    assert a.ss_total == pytest.approx(180.0)
    assert a.dof_total == 8
    assert a.error_ss == pytest.approx(2 / 3)
    assert a.error_dof == 2
    assert a.error_ms == pytest.approx(1 / 3)
    assert a.pooled == []
    assert a.ms["A"] == pytest.approx(79.0)
    assert a.f["A"] == pytest.approx(237.0)
    assert a.f["B"] == pytest.approx(4.0)
    assert a.p["C"] == pytest.approx(stats.f.sf(28.0, 2, 2))
    assert a.contribution["A"] == pytest.approx(100 * 158 / 180)
    assert a.pure_contribution["A"] == pytest.approx(100 * (158 - 2 / 3) / 180)
    total = sum(a.pure_contribution.values()) + a.error_pure_contribution
    assert total == pytest.approx(100.0)
    assert sum(a.contribution.values()) + a.error_contribution == pytest.approx(100.0)


def test_anova_auto_pools_smallest_until_half_the_dof(lev9):
    a = anova(lev9, Y9, NAMES)  # pool="auto", pool_fraction=0.5
    assert a.pooled == ["B"]
    assert a.error_dof == 4
    assert a.error_ss == pytest.approx(2 / 3 + 8 / 3)
    assert np.isnan(a.f["B"]) and np.isnan(a.p["B"])
    assert a.pure_contribution["B"] == 0.0
    assert a.f["A"] == pytest.approx(79.0 / (10 / 3 / 4))
    assert a.residual_ss == pytest.approx(2 / 3) and a.residual_dof == 2
    # pool_fraction=0 disables automatic pooling.
    assert anova(lev9, Y9, NAMES, pool_fraction=0.0).pooled == []


def test_anova_saturated_array_pools():
    l9 = get_array("L9").table
    names = ["A", "B", "E", "C"]  # E on the otherwise empty column 3
    a = anova(l9, Y9, names, pool=None)
    assert a.error_dof == 0 and a.error_ss == 0.0
    assert all(np.isnan(v) for v in a.f.values())
    assert a.pure_contribution == pytest.approx(a.contribution)
    a = anova(l9, Y9, names)
    assert a.pooled == ["E", "B"]  # SS 0.667 then 2.667
    assert a.error_dof == 4
    assert a.error_ss == pytest.approx(10 / 3)
    assert a.f["C"] == pytest.approx((56 / 3 / 2) / (10 / 3 / 4))
    # Explicit pooling by name.
    a = anova(l9, Y9, names, pool="E")
    assert a.pooled == ["E"] and a.error_dof == 2
    a = anova(l9, Y9, names, pool=["B", "E"])
    assert a.pooled == ["B", "E"] and a.error_dof == 4


def test_anova_auto_keeps_one_factor():
    a = anova(get_array("L4").table[:, [0]], [1.0, 2.0, 3.0, 5.0], ["A"], pool_fraction=1.0)
    assert a.pooled == []


def test_anova_pool_errors(lev9):
    with pytest.raises(StudyError, match="unknown factors"):
        anova(lev9, Y9, NAMES, pool=["Z"])
    with pytest.raises(StudyError, match="every factor"):
        anova(lev9, Y9, NAMES, pool=NAMES)
    with pytest.raises(StudyError, match="pool_fraction"):
        anova(lev9, Y9, NAMES, pool_fraction=1.5)


def test_anova_too_many_dof():
    lev = np.array([[0, 0], [1, 1], [2, 0]])
    with pytest.raises(StudyError, match="degrees of freedom"):
        anova(lev, [1.0, 2.0, 3.0], ["A", "B"])


def test_anova_constant_response(lev9):
    a = anova(lev9, np.full(9, 7.0), NAMES, pool=None)
    assert a.ss_total == 0.0
    assert all(v == 0.0 for v in a.contribution.values())
    assert all(v == 1.0 for v in a.p.values())


def test_anova_pandas_and_repr(lev9):
    a = anova(lev9, Y9, NAMES)
    df = a.to_pandas()
    assert list(df.index) == ["A", "B", "C", "error", "total"]
    assert df.loc["B", "pooled"]
    assert df.loc["total", "SS"] == pytest.approx(180.0)
    assert df.loc["error", "dof"] == 4
    text = repr(a)
    assert "(pooled)" in text and "error" in text and "158" in text


def test_anova_l25_five_factors_matches_brute_force():
    rng = np.random.default_rng(0)
    l25 = get_array("L25").table[:, :5]
    y = rng.normal(size=25)
    a = anova(l25, y, list("abcde"), pool=None)
    grand = y.mean()
    for j, n in enumerate("abcde"):
        ss = sum(5 * (y[l25[:, j] == lv].mean() - grand) ** 2 for lv in range(5))
        assert a.ss[n] == pytest.approx(ss)
    assert a.error_dof == 4
    assert a.error_ss == pytest.approx(a.ss_total - sum(a.ss.values()))
