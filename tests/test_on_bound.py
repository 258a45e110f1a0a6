"""An answer on a bound of its range is said, in the console, the report and --json (issue 43).

``tsid init`` writes ``min = 0`` for a positive start value; with a true value of -0.4
the study returned 1.8e-18 with exit 0 and not a word of the bound.
"""

from __future__ import annotations

import json

from fmu_factory import lag_data

from tsid_fmu import Experiment, Parameter, Study, identify
from tsid_fmu.uncertainty.bounds import bound_warnings, on_bounds


def test_on_bounds_finds_a_value_at_either_bound_and_nothing_inside():
    bounds = {"a": (0.0, float("inf")), "b": (-1.0, 2.0), "c": (0.0, 10.0)}
    levels = {"a": [1.0, 2.0], "b": [-1.0, 2.0], "c": [1.0, 9.0]}
    x = {"a": 1.8e-18, "b": 2.0 - 1e-9, "c": 5.0}
    on = on_bounds(x, bounds, levels)
    assert on == {"a": "min", "b": "max"}
    text = bound_warnings(on, x, bounds)
    assert text[0].startswith("a = 1.8e-18 sits on its bound min = 0")
    assert on_bounds({"a": 0.05}, bounds, levels) == {}  # inside, if below the first levels
    assert on_bounds({"a": 0.009}, bounds, levels) == {"a": "min"}  # log10 coordinates
    assert on_bounds({"c": 0.5}, bounds, levels) == {}


def test_an_answer_pushed_onto_min_0_is_said(tmp_path):
    fmu, data = lag_data(tmp_path, 0.37, -0.4)  # x0 truly -0.4
    study = Study(
        fmu=fmu,
        parameters=[
            Parameter("tau", [0.05, 0.5, 2.0], min=0.0, unit="s"),
            Parameter("x0", [0.1, 0.5, 1.0], min=0.0),  # as tsid init bounds it
        ],
        experiments=[Experiment(data=data, inputs={"u": "u"}, outputs={"y": "y_meas"})],
        max_iterations=6,
    )
    res = identify(study, tmp_path / "out", plots=False, workers=1, timeout=0)
    assert res.params["x0"] < 1e-3  # the search moves x0 in log10: it stops short of 0
    assert res.on_bound == {"x0": "min"}
    said = [w for w in res.warnings if w.startswith("x0 = ") and "sits on its bound min = 0" in w]
    assert said, res.warnings
    assert said[0] in (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    summary = res.to_dict()
    assert any("sits on its bound" in w for w in json.loads(json.dumps(summary))["warnings"])


def test_intervals_at_an_answer_not_shown_to_be_an_optimum_say_so():
    """Simple2R1C stopped at a limit 2.2 % off along R1 C, and R1 C's interval (203 ..
    205) excluded the true 200 with nothing said about the intervals (issue 45)."""
    from tsid_fmu.uncertainty.bounds import unshown_warnings

    stages = [("taguchi", "Case 3", 0), ("refinement", "simulation limit reached", 1)]
    intervals = {"R1": [0.1, 0.2], "C": [None, None]}
    limited = unshown_warnings(stages, 1, intervals)
    assert limited[0] == "refinement: simulation limit reached"
    assert limited[1].startswith("the answer is not shown to be an optimum (exit status 1)")
    assert "intervals of R1 and of any combination named were computed there" in limited[1]
    assert "they may not hold the truth" in limited[1]
    # at exit 0 the answer was shown stationary after that stage: its stop is in the
    # account, and no warning beside "converged" says it may not be (issue 64)
    assert unshown_warnings(stages, 0, intervals) == []
    # every parameter open: the products named across a symmetry are intervals too
    # (Simple2R1C, stopped 1.1 % off: C R1 = 202.09 (200.96 .. 203.22) around 200)
    (_, late) = unshown_warnings(stages, 1, {"C": [None, None]})
    assert "the 95 % intervals of any combination named were computed there" in late
