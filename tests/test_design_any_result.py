"""A design from any result (issue 65, item 4): a structure that leaves a parameter
unused, and a headline that says what the design proposes."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import test_structure_vendor as vendor
from fmu_factory import pythonfmu_available

from tsid_fmu import Study, identify
from tsid_fmu.design import design
from tsid_fmu.design.outcome import Design, Structural
from tsid_fmu.design.signals import Signal
from tsid_fmu.errors import StudyError

DESIGN = '\n[design]\ninputs = { u = [-2.0, 2.0] }\nbands = 1\nkinds = ["chirp"]\n'


@pytest.fixture(scope="module")
def linear(tmp_path_factory):
    """The vendor Drag FMU's study on data of its linear law (``law = 0``): q is unused."""
    if not pythonfmu_available():
        pytest.skip("pythonfmu cannot build here")
    tmp = tmp_path_factory.mktemp("linear")
    (tmp / "drag_slave.py").write_text(textwrap.dedent(vendor.SLAVE))
    subprocess.run(
        [sys.executable, "-m", "pythonfmu", "build", "-f", str(tmp / "drag_slave.py"),
         "-d", str(tmp)],
        check=True, capture_output=True,
    )  # fmt: skip
    truth = dict(vendor.TRUTH)
    try:
        vendor.TRUTH.update(law=0, q=0.0)
        vendor._data(tmp)
    finally:
        vendor.TRUTH.clear()
        vendor.TRUTH.update(truth)
    (tmp / "study.toml").write_text(vendor.STUDY + DESIGN)
    study = Study.from_toml(tmp / "study.toml")
    # worker processes: a pythonfmu FMU loaded into this process can crash it when it is
    # unloaded (its embedded interpreter)
    return identify(study, tmp / "out", plots=False, workers=2, timeout=0)


def test_a_parameter_the_chosen_structure_does_not_use_is_not_required(linear):
    """law=0 is chosen and q gets no value; the design was refused ("the result's
    parameters differ from the study's: it has no q"), and before that a KeyError."""
    assert linear.params["law"] == 0.0 and "q" not in linear.params
    found = design(linear, workers=2)
    assert found.names == ["tau"] and found.proposal is not None
    assert found.structural == []  # "no input separates" is said only of what acts
    (after,) = found.after
    assert after[0] < 0.4 < after[1]  # the truth, 0.4, inside the predicted interval


def test_a_result_that_chose_no_structure_still_needs_every_parameter(linear):
    """Only a chosen structure leaves parameters out: a missing one otherwise means
    another study's result (finding 5 of issue 66)."""
    import dataclasses

    other = dataclasses.replace(linear, structure=None)
    with pytest.raises(StudyError, match="it has no q"):
        design(other, workers=2)


def _design(**changes):
    signal = Signal("steps 0.1 Hz", "steps", (0.1, 0.1), np.zeros((2, 1)))
    base = dict(
        names=["a"], values={"a": 1.0}, criterion="D", inputs=["u"], limits=[(-1.0, 1.0)],
        band=(0.1, 1.0), time=np.array([0.0, 1.0]), candidates=[], proposal=None,
        predicted_outputs=None, output_names=["y"], template="e", study_intervals={},
        after=None, weak=[], structural=[], nfev=0, separating=signal,
    )  # fmt: skip
    return Design(**{**base, **changes})


def test_the_headline_names_the_input_that_separates_the_structures():
    """With no proposal for the parameters, the headline said "no experiment of this
    kind helps" above the section's "run steps 0.1 Hz to separate them"."""
    assert _design().verdict.startswith("run steps 0.1 Hz: it tells the structures apart")
    fixed = Structural(["a"], [{"a": 1.0}], [])
    line = _design(structural=[fixed]).verdict
    assert line.startswith("run steps 0.1 Hz") and "for the parameters, no input" in line
    assert _design(separating=None).verdict == "no experiment of this kind helps"
