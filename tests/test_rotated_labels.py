"""Rotated factors are labelled with the combination each one really moves."""

from __future__ import annotations

import numpy as np

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi.frame import Factor, Frame


def test_anchored_rotated_factors_are_not_all_labelled_by_the_largest_parameter():
    # K_s is in the thousands, M_m and B_s are not: in the anchored coordinates' own
    # parameter units K_s swamped every direction and A1-A3 all read "+1.00 K_s"
    space = Space(
        {"K_s": [1000.0, 10000.0], "M_m": [2.0, 20.0], "B_s": [10.0, 100.0]},
        {"K_s": (1.0, 1e6), "M_m": (0.1, 100.0), "B_s": (0.1, 1e4)},
        LevelingOptions(scale="log"),
    )
    a1 = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    a2 = np.array([1.0, -1.0, 1.0]) / np.sqrt(3)
    a3 = np.cross(a1, a2)
    offsets = np.array([-0.1, 0.0, 0.1])
    factors = [Factor(f"A{k + 1}", d, offsets) for k, d in enumerate((a1, a2, a3))]
    frame = Frame(np.zeros(3), factors, anchor={"K_s": 5000.0, "M_m": 8.0, "B_s": 30.0})
    labels = [frame.describe(space, f) for f in factors]
    assert len(set(labels)) == 3, labels
    assert labels[0] == "+0.71 lg M_m +0.71 lg K_s"
    assert all("K_s" in t and "M_m" in t for t in labels[1:]), labels
    assert "B_s" in labels[1] and "B_s" in labels[2]


def test_a_short_label_keeps_whole_terms():
    from tsid_fmu.report.style import short_combination

    text = "+0.71 lg F_vm -0.70 lg B_s +0.05 M_m"
    assert short_combination(text) == "+0.71 lg F_vm -0.70 lg B_s …"
    assert short_combination("+1.00 M_m") == "+1.00 M_m"
