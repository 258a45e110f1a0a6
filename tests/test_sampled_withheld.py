"""Sampled intervals a reader must not take are withheld, with the reason (issue 45)."""

from __future__ import annotations

import math
from types import SimpleNamespace

from tsid_fmu.report.notebook import parameter_rows, sampled_note
from tsid_fmu.uncertainty.sampled import COLLAPSED, MIN_CONVERGED, Sampled


def _sampled(unfinished: int = 0, failed: int = 0) -> Sampled:
    return Sampled(
        "monte_carlo",
        20,
        intervals={"K": [2.44, 2.58], "B": [1.9747e-18, 1.9747e-18]},
        failed=failed,
        unfinished=unfinished,
        method="re-fits",
    )


def test_too_few_converged_refits_withhold_every_interval():
    # 19 of 20 stopped at their step limit: 2.44 .. 2.58 against a primary 0.79 .. 6.8
    out = _sampled(unfinished=19)
    out.withhold({"K": [0.79, 6.8], "B": [None, None]})
    assert set(out.withheld) == {"K", "B"}
    assert "only 1 of 20 re-fits converged" in out.withheld["K"]
    # just enough converged: nothing is withheld for that reason
    enough = _sampled(unfinished=math.floor((1 - MIN_CONVERGED) * 20))
    enough.withhold({"K": [0.79, 6.8], "B": [0.0, 1.0]})
    assert enough.withheld == {}


def test_a_collapse_onto_one_value_is_withheld_only_where_the_primary_is_open():
    out = _sampled()
    out.withhold({"K": [0.79, 6.8], "B": [None, None]})
    assert list(out.withheld) == ["B"] and "collapsed" in out.withheld["B"]
    closed = _sampled()
    closed.withhold({"K": [0.79, 6.8], "B": [0.0, 1e-17]})
    assert closed.withheld == {}
    wide = _sampled()
    wide.intervals["B"] = [1.0, 1.0 + 10 * COLLAPSED]
    wide.withhold({"B": [None, None]})
    assert wide.withheld == {}


def test_the_table_and_the_note_say_withheld_and_why():
    out = _sampled(unfinished=19)
    out.withhold({"K": [0.79, 6.8], "B": [None, None]})
    result = SimpleNamespace(
        study=None,
        params={"K": 2.5, "B": 0.0},
        names=["K", "B"],
        structure=None,
        intervals={"K": [0.79, 6.8], "B": [None, None]},
        uncertainty=None,
        weak={},
        sampled=out,
    )
    rows = {r[0]: r for r in parameter_rows(result)}
    assert rows["K"][4] == "withheld" and rows["B"][4] == "withheld"
    assert rows["K"][3].startswith("0.79")  # the primary interval is untouched
    assert "Withheld for K, B: only 1 of 20 re-fits converged" in sampled_note(out)
    assert Sampled.from_dict(out.to_dict()).withheld == out.withheld
