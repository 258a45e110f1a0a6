"""Re-leveling, the papers' Step IV: Cases 1-3, selective Case II, log spacing, bounds."""

import math

import pytest

from tsid_fmu.doe.leveling import LevelingOptions, make_levels, relevel
from tsid_fmu.errors import StudyError


def test_case1_interior_best_recentres_and_narrows():
    d = relevel({"k": [10, 20, 30, 40, 50]}, {"k": [-40, -30, -20, -30, -40]})
    p = d.parameters[0]
    assert p.case == "recentre"
    assert d.case == 1 and not d.converged
    assert p.best_level == 2
    assert p.optimum == pytest.approx(30)
    assert p.levels == pytest.approx([20, 25, 30, 35, 40])  # half-width 20 -> 10


def test_case1_refines_the_peak_between_levels():
    # S/N of a parabola peaking at 27: vertex lies between levels 2 and 3
    lv = [10, 20, 30, 40, 50]
    sn = [-((x - 27) ** 2) / 10 for x in lv]
    p = relevel({"k": lv}, {"k": sn}).parameters[0]
    assert p.optimum == pytest.approx(27)
    assert min(p.levels) < 27 < max(p.levels)
    plain = relevel({"k": lv}, {"k": sn}, LevelingOptions(refine=False)).parameters[0]
    assert plain.optimum == 30


def test_case1_boundary_best_moves_the_range_that_way():
    up = relevel({"k": [1, 2, 3, 4, 5]}, {"k": [-50, -40, -30, -20, -10]}).parameters[0]
    assert up.case == "shift"
    assert up.levels == pytest.approx([3, 4, 5, 6, 7])
    down = relevel({"k": [1, 2, 3, 4, 5]}, {"k": [-10, -20, -30, -40, -50]}).parameters[0]
    assert down.levels == pytest.approx([-1, 0, 1, 2, 3])


def test_boundary_shift_respects_physical_bounds():
    p = relevel(
        {"k": [1, 2, 3, 4, 5]}, {"k": [-10, -20, -30, -40, -50]}, bounds={"k": (0.5, 100)}
    ).parameters[0]
    assert min(p.levels) == pytest.approx(0.5)
    assert all(0.5 <= v <= 100 for v in p.levels)
    # best at a level that *is* the bound: narrow towards it instead of leaving the bounds
    q = relevel(
        {"k": [0, 1, 2, 3, 4]}, {"k": [-10, -20, -30, -40, -50]}, bounds={"k": (0, 100)}
    ).parameters[0]
    assert q.case == "narrow" and min(q.levels) == 0 and max(q.levels) < 4


def test_case2_flat_but_wide_narrows():
    d = relevel({"k": [10, 20, 30, 40, 50]}, {"k": [-20.0, -20.01, -20.02, -20.01, -20.03]})
    p = d.parameters[0]
    assert p.case == "narrow" and d.case == 2 and not d.converged
    assert max(p.levels) - min(p.levels) == pytest.approx(0.5 * (50 - 10))


def test_case3_flat_and_small_stops():
    lv = [100.0, 100.01, 100.02, 100.03, 100.04]
    d = relevel({"a": lv, "b": lv}, {"a": [-20] * 5, "b": [-20, -20.01, -20, -20, -20]})
    assert d.converged and d.case == 3
    assert all(p.case == "converged" for p in d.parameters)
    assert d.parameters[0].levels == lv


def test_flat_small_parameter_is_not_stopped_while_another_moves():
    lv_small = [100.0, 100.01, 100.02]
    d = relevel({"a": lv_small, "b": [1, 2, 3]}, {"a": [-20] * 3, "b": [-30, -20, -30]})
    assert not d.converged
    cases = {p.name: p.case for p in d.parameters}
    assert cases == {"a": "converged", "b": "recentre"}


def test_selective_case_ii_keeps_flat_parameters():
    levels = {"a": [1, 2, 3], "b": [10, 20, 30]}
    sn = {"a": [-30, -20, -25], "b": [-20, -20.01, -20.02]}
    sel = relevel(levels, sn, LevelingOptions(selective=True))
    cases = {p.name: p.case for p in sel.parameters}
    assert cases == {"a": "recentre", "b": "keep"}
    assert sel.next_levels()["b"] == [10, 20, 30]
    plain = relevel(levels, sn)
    assert {p.name: p.case for p in plain.parameters}["b"] == "narrow"


def test_log_spacing_for_ranges_spanning_decades():
    lv = [0.001, 0.01, 0.1]
    p = relevel({"c": lv}, {"c": [-30, -20, -25]}, LevelingOptions(shrink=0.9)).parameters[0]
    # computed in log10: centre near 0.01, half-width 0.9 decades -> still spans > 10x
    assert p.levels[0] > 0
    ratios = [b / a for a, b in zip(p.levels, p.levels[1:], strict=False)]
    assert ratios[0] == pytest.approx(ratios[1], rel=1e-6)
    linear = make_levels(1, 3, 3)
    assert linear == [1.0, 2.0, 3.0]


def test_uneven_first_levels_like_table_1():
    # Table I: F_cm levels 10, 50, 80, 100, 110 with the 4th level best
    p = relevel(
        {"F_cm": [10, 50, 80, 100, 110]},
        {"F_cm": [-60, -50, -45, -40, -42]},
        LevelingOptions(refine=False, scale="linear"),
    ).parameters[0]
    assert p.case == "recentre" and p.optimum == 100
    assert min(p.levels) < 100 < max(p.levels)
    assert max(p.levels) - min(p.levels) == pytest.approx(50)
    # 110/10 spans more than a decade, so "auto" works in log10: the new range is
    # geometric about 100 with half the old half-width in decades
    q = relevel(
        {"F_cm": [10, 50, 80, 100, 110]},
        {"F_cm": [-60, -50, -45, -40, -42]},
        LevelingOptions(refine=False),
    ).parameters[0]
    assert math.log10(max(q.levels) / min(q.levels)) == pytest.approx(0.5 * math.log10(11))
    assert math.sqrt(max(q.levels) * min(q.levels)) == pytest.approx(100)


def test_failed_rows_do_not_win():
    p = relevel({"k": [1, 2, 3]}, {"k": [-math.inf, -20, -30]}).parameters[0]
    assert p.best_level == 1


def test_options_are_validated():
    with pytest.raises(StudyError, match="shrink"):
        LevelingOptions(shrink=1.5)
    with pytest.raises(StudyError, match="tolerance"):
        LevelingOptions(tolerance=0)
    with pytest.raises(StudyError, match="scale"):
        LevelingOptions(scale="cubic")


def test_run_based_centre_overrides_the_best_sn_level():
    lv = {"k": [1, 2, 3, 4, 5]}
    sn = {"k": [-10, -20, -30, -40, -50]}  # main effects say: lowest level
    inner = relevel(lv, sn, centre={"k": 3.4}).parameters[0]
    assert inner.case == "recentre" and inner.optimum == pytest.approx(3.4)
    assert inner.levels == pytest.approx([2.4, 2.9, 3.4, 3.9, 4.4])
    assert "best run" in inner.reason
    edge = relevel(lv, sn, centre={"k": 5.0}).parameters[0]
    assert edge.case == "shift" and edge.levels == pytest.approx([3, 4, 5, 6, 7])


def test_expand_scales_a_boundary_move():
    lv = {"k": [1, 2, 3, 4, 5]}
    sn = {"k": [-50, -40, -30, -20, -10]}
    wide = relevel(lv, sn, LevelingOptions(expand=2.0)).parameters[0]
    assert wide.levels == pytest.approx([1, 3, 5, 7, 9])
    narrow = relevel(lv, sn, LevelingOptions(expand=0.5)).parameters[0]
    assert narrow.levels == pytest.approx([4, 4.5, 5, 5.5, 6])


def test_minor_contributors_keep_their_levels_when_selective():
    lv = {"a": [1, 2, 3], "b": [10, 20, 30]}
    sn = {"a": [-30, -20, -25], "b": [-21, -20, -22]}  # b moves 2 dB, but only by confounding
    opts = LevelingOptions(selective=True, min_contribution=5.0)
    d = relevel(lv, sn, opts, contribution={"a": 97.0, "b": 1.0})
    cases = {p.name: p.case for p in d.parameters}
    assert cases == {"a": "recentre", "b": "keep"}
    assert "ANOVA contribution 1 %" in d.parameters[1].reason
    # without the contribution the 2 dB effect counts as significant
    assert {p.name: p.case for p in relevel(lv, sn, opts).parameters}["b"] == "recentre"
