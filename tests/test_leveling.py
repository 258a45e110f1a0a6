"""Re-leveling, the papers' Step IV: Cases 1-3, selective Case II, log spacing, bounds."""

import math

import numpy as np
import pytest

from tsid_fmu.doe.leveling import (
    LevelingDecision,
    LevelingOptions,
    make_levels,
    relative_span,
    relevel,
    round_sig,
    use_log_scale,
)
from tsid_fmu.doe.rules import FactorState, _parabola_vertex, decide_factor, main_effect_optimum
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


# -- every case's reason and the iteration's message, word for word ----------------------
# (killed mutants of docs/dev/mutation-survivors.md: the reason is what a person checks the
# written levels against, so its level numbers, direction and case must be right)

SELECTIVE = LevelingOptions(selective=True)
REASONS = {
    "recentre": (
        {"k": [1, 2, 3, 4, 5]},
        {"k": [-30, -20, -10, -20, -30]},
        {},
        "Case 1: S/N changes significantly for k",
        [
            "S/N changes by 20 dB, best at level 3 of 5; recentred and narrowed about S/N "
            "level 3 of 5; next levels 2 .. 4"
        ],
    ),
    "shift up": (
        {"k": [1, 2, 3]},
        {"k": [-30, -20, -10]},
        {},
        "Case 1: S/N changes significantly for k",
        [
            "S/N changes by 20 dB, best at level 3 of 3; centre on the upper edge of the "
            "levels: range moved up about S/N level 3 of 3; next levels 2 .. 4"
        ],
    ),
    "shift down": (
        {"k": [1, 2, 3]},
        {"k": [-10, -20, -30]},
        {},
        "Case 1: S/N changes significantly for k",
        [
            "S/N changes by 20 dB, best at level 1 of 3; centre on the lower edge of the "
            "levels: range moved down about S/N level 1 of 3; next levels 0 .. 2"
        ],
    ),
    "narrow at a bound": (
        {"k": [1, 2, 3]},
        {"k": [-10, -20, -30]},
        {"bounds": {"k": (1.0, 10.0)}},
        "Case 1: S/N changes significantly for none",
        [
            "S/N changes by 20 dB, best at level 1 of 3; narrowed towards the lower level, "
            "which is the physical bound about S/N level 1 of 3; next levels 1 .. 1.5"
        ],
    ),
    "narrow": (
        {"k": [50, 100, 150]},
        {"k": [-20, -20.05, -20]},
        {},
        "Case 2: every S/N is flat but some levels are still far apart",
        ["S/N flat 0.05 dB; narrowed about S/N level 1 of 3; next levels 25 .. 75"],
    ),
    "converged": (
        {"k": [99.9, 100, 100.1]},
        {"k": [-20, -20.05, -20]},
        {},
        "Case 3: every S/N is flat and every range is within the tolerance",
        ["S/N flat 0.05 dB; levels within the tolerance: kept; next levels 99.9 .. 100.1"],
    ),
    "keep": (
        {"a": [1, 2, 3], "b": [10, 20, 30]},
        {"a": [-30, -20, -25], "b": [-20, -20.01, -20]},
        {"options": SELECTIVE},
        "Case 1: S/N changes significantly for a",
        [
            "S/N changes by 10 dB, best at level 2 of 3; recentred and narrowed about S/N "
            "peak between levels 2 and 3 of 3; next levels 1.66667 .. 2.66667",
            "S/N flat 0.01 dB; levels kept while other factors move; next levels 10 .. 30",
        ],
    ),
    "minor": (
        {"a": [1, 2, 3], "b": [10, 20, 30]},
        {"a": [-30, -20, -25], "b": [-21, -20, -22]},
        {
            "options": LevelingOptions(selective=True, min_contribution=5.0),
            "contribution": {"a": 90.0, "b": 4.0},
        },
        "Case 1: S/N changes significantly for a",
        [
            "S/N changes by 10 dB, best at level 2 of 3; recentred and narrowed about S/N "
            "peak between levels 2 and 3 of 3; next levels 1.66667 .. 2.66667",
            "ANOVA contribution 4 %; levels kept while other factors move; next levels 10 .. 30",
        ],
    ),
    "run centre": (
        {"k": [1, 2, 3]},
        {"k": [-30, -20, -25]},
        {"centre": {"k": 3.5}, "centre_label": "run 7"},
        "Case 1: S/N changes significantly for k",
        [
            "S/N changes by 10 dB, best at level 2 of 3; centre on the upper edge of the "
            "levels: range moved up about run 7 (3.5); next levels 2.5 .. 4.5"
        ],
    ),
    "peak": (
        {"k": [1, 2, 3, 4, 5]},
        {"k": [-30, -20, -10, -12, -30]},
        {},
        "Case 1: S/N changes significantly for k",
        [
            "S/N changes by 20 dB, best at level 3 of 5; recentred and narrowed about S/N "
            "peak between levels 3 and 4 of 5; next levels 2.33333 .. 4.33333"
        ],
    ),
}


@pytest.mark.parametrize("name", list(REASONS))
def test_every_case_says_why_in_words(name):
    levels, sn, kw, message, reasons = REASONS[name]
    d = relevel(levels, sn, **kw)
    assert d.message == message
    assert [p.reason for p in d.parameters] == reasons


def test_a_run_centre_beyond_the_levels_is_kept_not_clipped():
    d = relevel({"k": [1.0, 2.0, 3.0]}, {"k": [-30.0, -20.0, -25.0]}, centre={"k": 3.5})
    assert d.parameters[0].optimum == 3.5 and d.parameters[0].levels == [2.5, 3.5, 4.5]
    assert d.parameters[0].centre_source == "the best run (3.5)"


def test_a_missing_response_is_named():
    with pytest.raises(StudyError, match=r"^no S/N response for parameter\(s\) b, c$"):
        relevel({"a": [1, 2], "b": [1, 2], "c": [1, 2]}, {"a": [0.0, 1.0]})


def test_a_decision_reads_back_as_written():
    d = relevel(*REASONS["keep"][:2], options=SELECTIVE)
    data = d.to_dict()
    assert data["case"] == 1 and data["converged"] is False
    back = LevelingDecision.from_dict(data)
    assert back == d and back.message == d.message and back.converged is False
    assert LevelingDecision.from_dict({**data, "converged": 1}).converged is True


def test_a_run_centre_at_the_top_level_up_to_rounding_moves_the_range_up():
    """Within 1e-9 of the range of an end counts as that end (it may have gone through
    the search coordinates and back); farther in, the centre is interior."""
    sn = {"k": [-30.0, -20.0, -25.0]}
    for c in (1000.0 - 7e-7, 1000.0, 1000.0 + 1e-3):
        p = relevel({"k": [0.0, 500.0, 1000.0]}, sn, centre={"k": c}).parameters[0]
        assert p.case == "shift" and "range moved up" in p.reason, (c, p.reason)
    p = relevel({"k": [0.0, 500.0, 1000.0]}, sn, centre={"k": 7e-7}).parameters[0]
    assert p.case == "shift" and "range moved down" in p.reason
    for c in (1000.0 - 2e-6, 2e-6):
        assert relevel({"k": [0.0, 500.0, 1000.0]}, sn, centre={"k": c}).parameters[0].case == (
            "recentre"
        )
    # at the physical bound the range narrows towards it instead
    p = relevel(
        {"k": [1.0, 2.0, 3.0]}, sn, bounds={"k": (0.0, 3.0)}, centre={"k": 3.0 - 1e-12}
    ).parameters[0]
    assert p.case == "narrow" and "towards the upper level" in p.reason


def test_a_flat_interior_best_beside_a_bound_is_narrowed_without_naming_it():
    d = relevel({"k": [1.0, 2.0, 3.0]}, {"k": [-20.0, -19.95, -20.0]}, bounds={"k": (1.0, 10.0)})
    assert d.parameters[0].reason.startswith("S/N flat 0.05 dB; narrowed about S/N level 2")


def test_make_levels_at_its_edges():
    assert make_levels(1.0, 2.0, 2) == [1.0, 2.0]
    with pytest.raises(StudyError, match=r"^a parameter needs at least 2 levels, got 1$"):
        make_levels(1.0, 2.0, 1)
    assert make_levels(1.0, 100.0, 3, log=True) == [1.0, 10.0, 100.0]
    assert make_levels(0.0, 10.0, 3, log=True) == [0.0, 5.0, 10.0]  # no log10 of 0
    # an empty range widens by 1e-9 of the value (at least 1e-9) each way
    assert make_levels(5.0, 5.0, 3) == [5.0 - 5e-9, 5.0, 5.0 + 5e-9]
    assert make_levels(0.5, 0.5, 3) == [0.5 - 1e-9, 0.5, 0.5 + 1e-9]


def test_relative_span_and_round_sig_at_their_edges():
    assert relative_span([0.5, 1.5]) == 1.0
    assert relative_span([-1.0, 1.0]) == math.inf and relative_span([0.0, 0.0]) == 0.0
    assert round_sig(1 / 3) == 0.333333333333  # 12 significant figures
    assert round_sig(123.456789012345) == 123.456789012
    assert round_sig(math.inf) == math.inf and round_sig(0.0) == 0.0


def test_the_parabola_refines_only_a_peak():
    assert _parabola_vertex(np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0])) is None
    assert _parabola_vertex(np.array([1.0, 2.0, 3.0]), np.array([0.5, 2.0, 4.5])) is None
    assert _parabola_vertex(
        np.array([1.0, 2.0, 3.0]), np.array([-2.0, 0.0, -1.0])
    ) == pytest.approx(2 + 1 / 6, rel=1e-15)
    u = np.array([1.0, 2.0, 3.0])
    # a symmetric peak is the level itself; a missing neighbour leaves the level
    assert main_effect_optimum(u, np.array([-20.0, -10.0, -20.0]), True) == (
        1,
        2.0,
        "S/N level 2 of 3",
    )
    assert main_effect_optimum(u, np.array([-np.inf, -10.0, -20.0]), True) == (
        1,
        2.0,
        "S/N level 2 of 3",
    )


def test_no_finite_sn_is_a_zero_span():
    d, _, _ = decide_factor(
        "k",
        np.array([1.0, 2.0, 3.0]),
        np.full(3, -np.inf),
        FactorState(flat=True, small=False),
        LevelingOptions(),
    )
    assert d.delta_db == 0.0


def test_log_spacing_rules_at_their_edges():
    log = LevelingOptions(scale="log")
    assert use_log_scale([0.5, 2.0], log) and not use_log_scale([0.0, 2.0], log)
    assert use_log_scale([1.0, 10.0], LevelingOptions())  # exactly log_ratio (10)
    # scale = "log" keeps geometric levels even once the range spans less than log_ratio
    d = relevel({"k": [1.0, 2.0, 4.0]}, {"k": [-30.0, -10.0, -30.0]}, log)
    assert d.parameters[0].levels == pytest.approx([2 / 2**0.5, 2.0, 2 * 2**0.5], rel=1e-11)
    # automatic: a range narrowed to exactly one decade (log_ratio 10) stays geometric
    d = relevel({"k": [1.0, 10.0, 100.0]}, {"k": [-30.0, -10.0, -30.0]})
    assert d.parameters[0].levels == pytest.approx([10**0.5, 10.0, 10**1.5], rel=1e-11)
    assert d.parameters[0].optimum == 10.0  # back from log10


def test_log_levels_at_a_bound_and_about_a_run_centre():
    sn = {"k": [-10.0, -20.0, -30.0]}  # best at the lowest level
    at_one = relevel({"k": [1.0, 10.0, 100.0]}, sn, bounds={"k": (1.0, 1e4)})
    assert at_one.parameters[0].case == "narrow"  # log10 of the bound 1 is 0, the level
    at_zero = relevel({"k": [1.0, 10.0, 100.0]}, sn, bounds={"k": (0.0, 1e4)})
    assert at_zero.parameters[0].case == "shift"  # a bound of 0 is -inf decades away
    assert at_zero.parameters[0].levels == pytest.approx([0.1, 1.0, 10.0], rel=1e-11)
    capped = relevel(
        {"k": [1.0, 10.0, 100.0]}, {"k": [-30.0, -20.0, -10.0]}, bounds={"k": (0.5, 50.0)}
    )
    assert max(capped.parameters[0].levels) == 50.0
    # a run centre is taken in log10 too; one at or below 0 makes the levels linear
    sn2 = {"k": [-30.0, -10.0, -20.0]}
    run = relevel({"k": [1.0, 10.0, 100.0]}, sn2, centre={"k": 20.0}).parameters[0]
    assert run.optimum == 20.0 and run.levels[1] == pytest.approx(20.0, rel=1e-11)
    assert run.levels == pytest.approx([20 / 10**0.5, 20.0, 20 * 10**0.5], rel=1e-11)
    half = relevel({"k": [1.0, 10.0, 100.0]}, sn2, centre={"k": 0.5}).parameters[0]
    assert half.levels == pytest.approx([0.05, 0.5, 5.0], rel=1e-11)  # geometric
    zero = relevel({"k": [1.0, 10.0, 100.0]}, sn2, centre={"k": 0.0}).parameters[0]
    assert zero.levels == [-49.5, 0.0, 49.5]  # linear about 0, moved: the same width


def test_kept_and_converged_levels_are_kept_as_they_were():
    uneven = {"a": [1.0, 2.0, 3.0], "b": [10.0, 12.0, 30.0]}
    sn = {"a": [-30.0, -20.0, -25.0], "b": [-20.0, -20.01, -20.0]}
    d = relevel(uneven, sn, SELECTIVE)
    assert d.parameters[1].case == "keep" and d.parameters[1].levels == [10.0, 12.0, 30.0]
    assert d.parameters[1].optimum == 20.0  # the middle of the range
    conv = relevel({"k": [99.9, 99.95, 100.1]}, {"k": [-20.0, -20.05, -20.0]})
    assert conv.converged and conv.parameters[0].levels == [99.9, 99.95, 100.1]
    assert conv.parameters[0].optimum == 100.0


def test_no_finite_sn_is_flat_and_a_missing_contribution_is_not_minor():
    d = relevel({"k": [1.0, 2.0, 3.0]}, {"k": [-np.inf] * 3})
    assert d.case == 2 and d.parameters[0].case == "narrow"
    opts = LevelingOptions(selective=True, min_contribution=5.0)
    d = relevel(*REASONS["minor"][:2], opts, contribution={"a": 90.0})
    assert [p.case for p in d.parameters] == ["recentre", "recentre"]


def test_a_shrink_override_and_two_moving_parameters():
    d = relevel({"k": [1, 2, 3, 4, 5]}, {"k": [-30, -20, -10, -20, -30]}, shrink=0.25)
    assert d.parameters[0].levels == [2.5, 2.75, 3.0, 3.25, 3.5]
    both = relevel(
        {"a": [1.0, 2.0, 3.0], "b": [1.0, 2.0, 3.0]},
        {"a": [-30.0, -20.0, -25.0], "b": [-30.0, -20.0, -25.0]},
    )
    assert both.message == "Case 1: S/N changes significantly for a, b"


def test_the_parabola_needs_both_neighbours_of_the_best_level():
    u = np.arange(1.0, 6.0)
    assert main_effect_optimum(u, np.array([-30.0, -20.0, -10.0, -np.inf, -40.0]), True) == (
        2,
        3.0,
        "S/N level 3 of 5",
    )
    best, _, source = main_effect_optimum(u, np.array([-30.0, -20.0, -10.0, -15.0, -np.inf]), True)
    assert best == 2 and source == "S/N peak between levels 3 and 4 of 5"


def test_a_run_centre_exactly_eps_inside_an_end_is_on_that_end():
    """eps = 1e-9 of the range (2e-9 for levels 0, 1, 2, a sum exact in floating point):
    a centre at u[0] + eps or u[-1] - eps counts as on the end (the rule is strict), one
    a little farther in is interior."""
    u, sn = np.array([0.0, 1.0, 2.0]), np.array([-30.0, -20.0, -25.0])
    eps = 1e-9 * 2.0
    state = FactorState(flat=False, small=False)

    def case(c: float) -> str:
        return decide_factor("k", u, sn, state, LevelingOptions(), centre=(c, "run 1"))[0].case

    assert 0.0 + eps == 2e-9 and 2.0 - eps == 2.0 - 2e-9
    assert case(0.0 + eps) == case(2.0 - eps) == "shift"
    assert case(0.0 + 2 * eps) == case(2.0 - 2 * eps) == "recentre"


def test_decide_factor_leaves_the_levels_and_optimum_to_its_caller():
    """Its docstring: the decision comes with ``levels`` empty (and no optimum, NaN):
    the caller makes them in its own units."""
    d, _, half = decide_factor(
        "k",
        np.array([1.0, 2.0, 3.0]),
        np.array([-30.0, -20.0, -25.0]),
        FactorState(flat=False, small=False),
        LevelingOptions(),
    )
    assert d.levels == [] and math.isnan(d.optimum)
    assert d.case == "recentre" and half == 0.5
