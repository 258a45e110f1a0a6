"""The next frame (search/nextlevels.py): the papers' cases, then the next factors (no FMU).

Axis-aligned frames are exactly :func:`tsid_fmu.doe.leveling.relevel`; rotated factors
get the same cases on their offsets, and their next half-widths are the extent of the
box of decided half-widths along each direction (``sqrt(d^T B d)``, ``B = sum h^2 d
d^T``), or with the surface's curvatures the width of an equal rise, at most GROWTH
times that extent. The figures below are worked by hand from those definitions.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tsid_fmu.doe.leveling import LevelingOptions, relevel
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi import nextlevels
from tsid_fmu.search.taguchi.frame import Factor, Frame
from tsid_fmu.search.taguchi.nextlevels import GROWTH, MAX_HALF_WIDTH, next_frame

WIDE = (-math.inf, math.inf)
CENTRE = ({"p": 101.0, "q": 99.0}, "run 3")


def _axis_case():
    levels = {"p": [1.0, 2.0, 3.0], "q": [10.0, 100.0, 1000.0]}
    space = Space(levels, {"p": (0.5, 3.0), "q": (1.0, 1e4)}, LevelingOptions())
    sn = {"p": [-30.0, -20.0, -10.0], "q": [-21.0, -20.0, -22.0]}
    return space, Frame.from_levels(space, levels), levels, sn


@pytest.mark.parametrize("centre", [None, ({"p": 2.2, "q": 150.0}, "run 4")])
def test_an_axis_aligned_frame_is_relevelled_as_the_papers_do(centre):
    """Bounds (p at its upper bound narrows), options (selective: a minor q is kept),
    contribution, the run centre and its label all reach relevel."""
    space, frame, levels, sn = _axis_case()
    opts = LevelingOptions(selective=True, min_contribution=25.0)
    share = {"p": 80.0, "q": 20.0}
    d, f = next_frame(frame, space, sn, centre, opts, share, None)
    expected = relevel(
        levels,
        sn,
        opts,
        bounds=space.bounds,
        centre=None if centre is None else centre[0],
        contribution=share,
        centre_label="the best run" if centre is None else centre[1],
    )
    assert d.to_dict() == expected.to_dict()
    # with no run centre p's best is its top level, at its bound: narrowed, not shifted
    assert [p.case for p in d.parameters] == ["narrow" if centre is None else "recentre", "keep"]
    assert f.axis_aligned and f.level_values(space) == expected.next_levels()
    if centre is not None:
        assert "about run 4 (2.2)" in d.parameters[0].reason


def _rotated_case(space: Space | None = None):
    space = space or Space(
        {"p": [92.0, 108.0], "q": [92.0, 108.0]}, {"p": WIDE, "q": WIDE}, LevelingOptions()
    )
    off = np.array([-0.25, 0.0, 0.25])
    factors = [Factor("A1", np.array([1.0, 0.0]), off), Factor("A2", np.array([0.6, 0.8]), off)]
    return space, Frame(np.zeros(2), factors, anchor={"p": 100.0, "q": 100.0})


def _extents(half: list[float]) -> list[float]:
    """``sqrt(d_k^T (sum_i h_i^2 d_i d_i^T) d_k)`` for d = (1, 0), (0.6, 0.8)."""
    return [
        math.sqrt(half[0] ** 2 + 0.36 * half[1] ** 2),
        math.sqrt(0.36 * half[0] ** 2 + half[1] ** 2),
    ]


def test_rotated_factors_get_the_cases_their_reasons_and_the_boxes_extent():
    """The run centre (101, 99) is offset (1/16, -1/16) from the anchor, i.e. factor
    coordinates z = (0.109375, -0.078125)."""
    space, frame = _rotated_case()
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-20.0, -20.01, -20.0]}
    d, f = next_frame(frame, space, sn, CENTRE, LevelingOptions(), {"A1": 90.0}, None)
    assert d.message == "Case 1: S/N changes significantly for A1"
    assert [p.reason for p in d.parameters] == [
        "S/N changes by 10 dB, best at level 2 of 3; recentred and narrowed about run 3 "
        "(offset +0.1094); next half-width 0.125 (was 0.25)",
        "S/N flat 0.01 dB; narrowed about run 3 (offset -0.07812); next half-width 0.125 "
        "(was 0.25)",
    ]
    assert [p.optimum for p in d.parameters] == pytest.approx([0.109375, -0.078125], rel=1e-12)
    assert d.parameters[0].levels == [-0.125, 0.0, 0.125]
    # directions kept (same scale at the new anchor), widths the box's extent
    assert f.note == "rotated factors kept from the previous iteration"
    assert f.anchor == {"p": 101.0, "q": 99.0} and [g.name for g in f.factors] == ["A1", "A2"]
    assert f.factors[1].direction == pytest.approx([0.6, 0.8], rel=1e-12)
    for g, w in zip(f.factors, _extents([0.125, 0.125]), strict=True):
        assert list(g.offsets) == pytest.approx([-w, 0.0, w], rel=1e-12)


def test_a_minor_rotated_factor_is_kept_and_says_why():
    space, frame = _rotated_case()
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-21.0, -20.0, -22.0]}
    opts = LevelingOptions(selective=True, min_contribution=5.0)
    d, f = next_frame(frame, space, sn, CENTRE, opts, {"A1": 90.0, "A2": 4.0}, None)
    assert [p.case for p in d.parameters] == ["recentre", "keep"]
    assert d.parameters[1].reason == (
        "ANOVA contribution 4 %; levels kept while other factors move; next half-width "
        "0.25 (was 0.25)"
    )
    assert d.parameters[1].levels == [-0.25, 0.0, 0.25]
    for g, w in zip(f.factors, _extents([0.125, 0.25]), strict=True):
        assert g.offsets[-1] == pytest.approx(w, rel=1e-12)


def test_rotated_cases_2_and_3_and_the_levels_option():
    space, frame = _rotated_case()
    flat = {"A1": [-20.0, -20.01, -20.0], "A2": [-20.0, -20.01, -20.0]}
    d, _ = next_frame(frame, space, flat, CENTRE, LevelingOptions(), {}, None)
    assert d.case == 2 and d.message == (
        "Case 2: every S/N is flat but some levels are still far apart"
    )
    d, f = next_frame(
        frame, space, flat, CENTRE, LevelingOptions(tolerance=0.1, n_levels=5), {}, None
    )
    assert d.converged and d.message == (
        "Case 3: every S/N is flat and every range is within the tolerance"
    )
    assert d.parameters[0].levels == [-0.25, -0.125, 0.0, 0.125, 0.25]  # kept, five levels
    assert [len(g.offsets) for g in f.factors] == [5, 5]


def test_a_rotated_frame_needs_a_centre():
    space, frame = _rotated_case()
    with pytest.raises(ValueError, match=r"^a rotated frame needs a centre$"):
        next_frame(
            frame, space, {"A1": [0.0] * 3, "A2": [0.0] * 3}, None, LevelingOptions(), {}, None
        )


def test_principal_axes_set_the_widths_of_an_equal_rise():
    """Axes (1, 0) and (0, 1) with curvatures 4 and 1; decided half-widths h = (0.125,
    0.125) along the current factors give rises ``d^T H d h^2`` of 4 h^2 and (0.36 * 4 +
    0.64) h^2; each new factor gets ``sqrt(rise / c)``, the geometric mean rise, at most
    GROWTH times the box's extent along it."""
    space, frame = _rotated_case()
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-20.0, -20.01, -20.0]}
    axes = (np.eye(2), np.array([4.0, 1.0]))
    _, f = next_frame(frame, space, sn, CENTRE, LevelingOptions(), {"A1": 90.0}, axes)
    h = 0.125
    rise = math.sqrt(4 * h * h * (0.36 * 4 + 0.64) * h * h)
    extent = [math.sqrt(h * h + 0.36 * h * h), math.sqrt(0.64 * h * h)]
    want = [min(math.sqrt(rise / c), GROWTH * e) for c, e in zip((4.0, 1.0), extent, strict=True)]
    assert f.note == "rotated factors: principal axes of the cost surface the runs show"
    assert [g.offsets[-1] for g in f.factors] == pytest.approx(want, rel=1e-12)
    assert f.factors[0].direction == pytest.approx([1.0, 0.0])


def test_rotated_widths_keep_a_log_parameter_positive_and_at_most_max_half_width():
    """p in log10 (two decades of first levels) at 10: one search unit of the anchored
    coordinates is 10 ln10 * 2 of p, and a factor along p may move it by at most
    POSITIVE_MARGIN of its value."""
    space = Space(
        {"p": [1.0, 100.0], "q": [92.0, 108.0]},
        {"p": (0.0, math.inf), "q": WIDE},
        LevelingOptions(),
    )
    frame = Frame(
        np.zeros(2),
        [
            Factor("A1", np.array([1.0, 0.0]), np.array([-0.5, 0.0, 0.5])),
            Factor("A2", np.array([0.0, 1.0]), np.array([-1.5, 0.0, 1.5])),
        ],
        anchor={"p": 10.0, "q": 100.0},
    )
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-30.0, -20.0, -25.0]}
    centre = ({"p": 10.0, "q": 100.0}, "run 1")
    d, f = next_frame(frame, space, sn, centre, LevelingOptions(), {}, None)
    # decided half-widths 0.25 and 0.75 (recentred: half the old ones)
    assert [p.levels[-1] for p in d.parameters] == [0.25, 0.75]
    room = nextlevels.POSITIVE_MARGIN * 10.0 / (10.0 * math.log(10) * 2)
    assert f.factors[0].offsets[-1] == pytest.approx(room, rel=1e-12)
    assert f.factors[1].offsets[-1] == MAX_HALF_WIDTH


def test_factors_of_a_space_with_parameters_named_like_factors_are_named_z():
    space = Space(
        {"A1": [92.0, 108.0], "q": [92.0, 108.0]}, {"A1": WIDE, "q": WIDE}, LevelingOptions()
    )
    off = np.array([-0.25, 0.0, 0.25])
    frame = Frame(
        np.zeros(2),
        [Factor("A1", np.array([1.0, 0.0]), off), Factor("A2", np.array([0.0, 1.0]), off)],
        anchor={"A1": 100.0, "q": 100.0},
    )
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-30.0, -20.0, -25.0]}
    _, f = next_frame(
        frame, space, sn, ({"A1": 100.0, "q": 100.0}, "run 1"), LevelingOptions(), {}, None
    )
    assert [g.name for g in f.factors] == ["Z1", "Z2"]


def test_a_rotated_factor_centred_on_its_edge_shifts_and_both_movers_are_named():
    """Centre (104.96, 101.28): factor coordinates (0.25, 0.1), A1 on its upper edge."""
    space, frame = _rotated_case()
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-30.0, -20.0, -25.0]}
    centre = ({"p": 104.96, "q": 101.28}, "run 5")
    d, _ = next_frame(frame, space, sn, centre, LevelingOptions(), {}, None)
    assert [p.case for p in d.parameters] == ["shift", "recentre"]
    assert d.message == "Case 1: S/N changes significantly for A1, A2"


def test_a_flat_small_rotated_factor_beside_a_mover_is_done_and_no_finite_sn_is_flat():
    space = Space(
        {"p": [92.0, 108.0], "q": [92.0, 108.0]}, {"p": WIDE, "q": WIDE}, LevelingOptions()
    )
    frame = Frame(
        np.zeros(2),
        [
            Factor("A1", np.array([1.0, 0.0]), np.array([-0.25, 0.0, 0.25])),
            Factor("A2", np.array([0.0, 1.0]), np.array([-1 / 128, 0.0, 1 / 128])),  # span 0.25 %
        ],
        anchor={"p": 100.0, "q": 100.0},
    )
    centre = ({"p": 100.0, "q": 100.0}, "run 1")
    moving = {"A1": [-30.0, -20.0, -25.0], "A2": [-20.0, -20.01, -20.0]}
    d, _ = next_frame(frame, space, moving, centre, LevelingOptions(), {}, None)
    assert [p.case for p in d.parameters] == ["recentre", "converged"]
    failed = {"A1": [-np.inf] * 3, "A2": [-np.inf] * 3}  # every run failed: flat, 0 dB
    d, _ = next_frame(frame, space, failed, centre, LevelingOptions(), {}, None)
    assert [p.delta_db for p in d.parameters] == [0.0, 0.0] and d.case == 2


# -- kept rotated directions, names, log limits, zero widths, no centre (killed mutants of
# docs/dev/mutation-survivors.md)


def test_kept_directions_are_rescaled_to_the_new_centre_and_stay_unit_vectors():
    """p in log10 at 10, the new centre at p = 20: the anchored scale of p doubles, so a
    kept direction (0.6, 0.8) becomes (0.3, 0.8) normalised."""
    space = Space(
        {"p": [1.0, 100.0], "q": [92.0, 108.0]},
        {"p": (0.0, math.inf), "q": WIDE},
        LevelingOptions(),
    )
    off = np.array([-0.1, 0.0, 0.1])
    factors = [Factor("A1", np.array([1.0, 0.0]), off), Factor("A2", np.array([0.6, 0.8]), off)]
    frame = Frame(np.zeros(2), factors, anchor={"p": 10.0, "q": 100.0})
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-30.0, -20.0, -25.0]}
    _, f = next_frame(
        frame, space, sn, ({"p": 20.0, "q": 100.0}, "run 2"), LevelingOptions(), {}, None
    )
    want = np.array([0.3, 0.8]) / math.hypot(0.3, 0.8)
    assert f.factors[0].direction == pytest.approx([1.0, 0.0], rel=1e-12)
    assert f.factors[1].direction == pytest.approx(want, rel=1e-12)


def test_only_names_like_a1_make_the_factors_z():
    space = Space(
        {"k1": [92.0, 108.0], "q": [92.0, 108.0]}, {"k1": WIDE, "q": WIDE}, LevelingOptions()
    )
    off = np.array([-0.25, 0.0, 0.25])
    frame = Frame(
        np.zeros(2),
        [Factor("A1", np.array([1.0, 0.0]), off), Factor("A2", np.array([0.0, 1.0]), off)],
        anchor={"k1": 100.0, "q": 100.0},
    )
    sn = {"A1": [-30.0, -20.0, -25.0], "A2": [-30.0, -20.0, -25.0]}
    centre = ({"k1": 100.0, "q": 100.0}, "run 1")
    _, f = next_frame(frame, space, sn, centre, LevelingOptions(), {}, None)
    assert [g.name for g in f.factors] == ["A1", "A2"]


def test_a_log_parameter_after_a_linear_one_is_kept_positive_too():
    """As test_rotated_widths_keep_a_log_parameter_positive_..., with the linear parameter
    first: every log parameter limits the widths, not only those before a linear one."""
    space = Space(
        {"q": [92.0, 108.0], "p": [1.0, 100.0]},
        {"q": WIDE, "p": (0.0, math.inf)},
        LevelingOptions(),
    )
    centre = {"q": 100.0, "p": 10.0}
    directions = np.eye(2)
    limit = nextlevels._positive_limit(space, space.anchored(centre), centre, directions)
    room = nextlevels.POSITIVE_MARGIN * 10.0 / (10.0 * math.log(10) * 2)
    assert limit[0] == math.inf and limit[1] == pytest.approx(room, rel=1e-12)


def test_a_zero_half_width_is_floored_above_zero():
    """A factor decided to zero width (no extent along it) keeps a half-width of 1e-12,
    not zero."""
    _, frame = _rotated_case()
    out = nextlevels._widths(np.eye(2), None, np.zeros((2, 2)), frame, [0.0, 0.0], np.ones(2))
    assert list(out) == [1e-12, 1e-12]


def test_an_axis_aligned_frame_rotated_without_a_run_centre_is_anchored_at_its_centre():
    """SISO selection (no run centre) with principal axes: the rotated frame is anchored
    at the current frame's centre, the middle of the first levels here."""
    space, frame, _, sn = _axis_case()
    axes = (np.eye(2), np.array([4.0, 1.0]))
    _, f = next_frame(frame, space, sn, None, LevelingOptions(), {}, axes)
    assert not f.axis_aligned
    assert f.anchor == pytest.approx({"p": 2.0, "q": 100.0}, rel=1e-12)
