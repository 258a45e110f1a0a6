"""Whole studies on worker processes: one answer for any worker count, crashes fail alone.

These are the study-level checks that the evaluator tests (test_evaluate.py,
test_parallel.py) do not make: the same study identified with 1, 2 and 3 workers gives
the same simulations, costs and answer; and a study whose FMU segfaults on some rows
finishes, with the crashed rows scored worst and listed in report.md.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from spec_helpers import lag_frame

import tsid_fmu
from tsid_fmu import Experiment, Method, Parameter, Study

# both tests run a whole study on worker processes
pytestmark = pytest.mark.slow


def test_a_study_gives_the_same_answer_and_count_for_any_worker_count(lag_crash_fmus):
    study = Study(
        fmu=lag_crash_fmus["lag"],
        parameters=[Parameter("tau", [0.01, 0.03, 0.1]), Parameter("x0", [-0.5, 0.0, 0.5])],
        experiments=[Experiment(data=lag_frame(1), inputs={"u": "u"}, outputs={"y": "y"})],
        method=Method(cost="iae", replicates=2, input_noise=0.02, seed=2, max_iterations=3),
    )
    results = {n: tsid_fmu.identify(study, workers=n, plots=False) for n in (1, 2, 3)}
    first = results[1]
    assert first.nfev > 0 and len(first.iterations) >= 2
    for n in (2, 3):
        got = results[n]
        assert got.params == first.params and got.fun == first.fun and got.nfev == first.nfev
        assert [s.nfev for s in got.stages] == [s.nfev for s in first.stages]
        for a, b in zip(first.iterations, got.iterations, strict=True):
            np.testing.assert_array_equal(a.costs, b.costs)


def test_a_study_survives_crashing_rows_and_reports_them(lag_crash_fmus, tmp_path):
    """Rows whose FMU segfaults are scored worst, the workers are replaced, the study
    finishes, and report.md lists the crashed rows with the signal."""
    study = Study(
        fmu=lag_crash_fmus["crash"],
        parameters=[Parameter("gain", [0.5, 1.0, 25.0])],
        experiments=[Experiment(data=lag_frame(3), inputs={"u": "u"}, outputs={"y": "y"})],
        start_values={"abort_above": 10.0, "segv_above": 20.0, "hang_above": 30.0},
        method=Method(cost="iae", replicates=2, seed=5, max_iterations=2, refine="none"),
    )
    res = tsid_fmu.identify(study, tmp_path / "out", plots=False, workers=2, timeout=20.0)
    first = res.iterations[0]
    crashed = [e for e in first.errors if e]
    assert len(crashed) == 3 and all("SIGSEGV" in e for e in crashed)
    assert math.isfinite(res.fun) and res.params["gain"] < 20.0
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Failed runs" in report and "worker crashed (signal 11 SIGSEGV)" in report
