"""Decisions read typed values, never a message (issue 61, item 4).

The markdown report and the discrepancy verdict picked the outputs the model does not
explain by looking for "model or solver mismatch" in the warnings' text; both now take
them from the fit and the noise (:func:`tsid_fmu.uncertainty.assess.mismatches`).
"""

from __future__ import annotations

import re
from pathlib import Path

from tsid_fmu.uncertainty.assess import MISMATCH, mismatch_warning, mismatches

PACKAGE = Path(__file__).resolve().parents[1] / "tsid_fmu"


def test_mismatches_come_from_the_fit_and_the_noise():
    fit = {
        "run": {"y": {"rmse": 2.0 * MISMATCH}, "z": {"rmse": 0.9 * MISMATCH}},
        "lost": {"error": "the simulation failed"},
        "quiet": {"y": {"rmse": 5.0}},
    }
    noise = {"run": {"y": 1.0, "z": 1.0}, "quiet": {"y": 0.0}}
    found = mismatches(fit, noise)
    assert found == [("run", "y", 2.0 * MISMATCH, 1.0)]
    said = mismatch_warning(*found[0])
    assert said.startswith("run / y: model or solver mismatch: residual RMS 3 is 3.0 times")


def test_no_module_decides_by_a_warnings_text():
    """A selection ``[w for w in warnings if "<phrase>" in w]`` is a decision made by
    parsing a message; the mismatch phrase was read back so in two places."""
    idiom = re.compile(r"\bif \"[^\"]+\" in w\b")
    found = [
        p.relative_to(PACKAGE).as_posix()
        for p in PACKAGE.rglob("*.py")
        if idiom.search(p.read_text(encoding="utf-8"))
    ]
    assert found == []
