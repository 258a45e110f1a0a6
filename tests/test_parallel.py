"""Parallel and Dask evaluation: same costs as serial, crash and hang isolation."""

from __future__ import annotations

import dataclasses
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from spec_helpers import experiment, lag_frame, make_spec

import tsid_fmu.fmu.extraction as extraction
from tsid_fmu.errors import FMUError, StudyError
from tsid_fmu.evaluate import (
    DaskEvaluator,
    PoolEvaluator,
    SerialEvaluator,
    available_cores,
    make_evaluator,
)


def _frame(seed: int) -> pd.DataFrame:
    return lag_frame(seed)


@pytest.fixture(scope="module")
def lag_spec(lag_crash_fmus):
    noise = {"replicates": 3, "input_noise": 0.02, "seed": 11}
    return make_spec(
        lag_crash_fmus["lag"],
        ["tau", "x0"],
        [
            experiment(_frame(1), {"u": "u"}, {"y": "y"}, name="a", index=0, **noise),
            experiment(_frame(2), {"u": "u"}, {"y": "y2"}, name="b", index=1, **noise),
        ],
        cost="iae",
    )


@pytest.fixture(scope="module")
def crash_spec(lag_crash_fmus):
    return make_spec(
        lag_crash_fmus["crash"],
        ["gain"],
        [experiment(_frame(3), {"u": "u"}, {"y": "y"}, replicates=2, input_noise=0.01, seed=5)],
        cost="iae",
        start_values={"abort_above": 10.0, "segv_above": 20.0, "hang_above": 30.0},
    )


# rows: good, good, bad tau in experiment "a", x0 varies
SETS = [
    {"tau": 0.03, "x0": 0.0},
    {"tau": 0.1, "x0": 0.5},
    {"tau": -1.0, "x0": 0.0},
    {"tau": 0.01, "x0": -0.5},
    {"tau": 0.05, "x0": 0.25},
]


@pytest.fixture(scope="module")
def serial(lag_spec):
    with SerialEvaluator(lag_spec) as ev:
        return ev.evaluate(SETS), ev.simulate([SETS[1]])[0]


def test_parallel_costs_are_bit_identical_to_serial(lag_spec, serial):
    expected, _ = serial
    seen = []
    with PoolEvaluator(lag_spec, workers=2) as pe:
        assert pe.n_replicates == 3
        got = pe.evaluate(SETS, progress=lambda done, total: seen.append((done, total)))
        assert pe.nfev == got.nfev
    np.testing.assert_array_equal(got.costs, expected.costs)
    assert got.errors == expected.errors
    assert "tau must be positive" in got.errors[2] and got.errors[2].startswith("a: ")
    assert seen == [(k, len(SETS)) for k in range(1, len(SETS) + 1)]
    # the same work as serial, the failed row included (it stops at its first failure)
    assert got.nfev == expected.nfev


def test_simulate_and_recycling_match_serial(lag_spec, serial):
    expected, clean = serial
    with PoolEvaluator(lag_spec, workers=2, recycle_after=2, residual_cache=2) as pe:
        got = pe.evaluate(SETS)
        again = pe.evaluate(SETS[:2])
        sim = pe.simulate([SETS[1]])[0]
    np.testing.assert_array_equal(got.costs, expected.costs)
    np.testing.assert_array_equal(again.costs, expected.costs[:2])
    for s1, s2 in zip(sim, clean, strict=True):
        assert s1.experiment == s2.experiment and s1.error is None and s2.error is None
        np.testing.assert_array_equal(s1.outputs, s2.outputs)


def test_make_evaluator_chooses_serial_or_parallel(lag_spec, monkeypatch):
    """One worker is still a worker process (time limit, crash isolation); only
    ``timeout=0`` with one worker runs in this process."""
    with make_evaluator(lag_spec, workers=1, timeout=0) as ev:
        assert type(ev) is SerialEvaluator
    with make_evaluator(lag_spec, workers=1) as ev:
        assert isinstance(ev, PoolEvaluator) and ev.workers == 1 and ev.time_limit == 300
    with make_evaluator(lag_spec, workers=1, timeout=5.0) as ev:
        assert isinstance(ev, PoolEvaluator) and ev.workers == 1
    monkeypatch.setattr("tsid_fmu.evaluate.factory.available_cores", lambda: 1)
    with make_evaluator(lag_spec) as ev:  # one usable core
        assert isinstance(ev, PoolEvaluator) and ev.workers == 1
    assert available_cores() >= 1


def test_startup_errors_are_raised_like_serial(lag_spec, lag_crash_fmus):
    bad = dataclasses.replace(lag_spec, parameter_names=("tua",))
    with pytest.raises(FMUError, match=r"unknown parameter 'tua'.*Did you mean 'tau'"):
        SerialEvaluator(bad)
    with pytest.raises(FMUError, match=r"unknown parameter 'tua'.*Did you mean 'tau'"):
        PoolEvaluator(bad, workers=2)
    with pytest.raises(StudyError, match="workers must be at least 1"):
        PoolEvaluator(lag_spec, workers=0)


@pytest.fixture
def own_tmp(tmp_path, monkeypatch) -> Path:
    """A temporary folder of the test's own for everything the evaluators extract."""
    d = tmp_path / "tmp"
    d.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(d))
    return d


def test_crashing_rows_fail_alone_and_workers_are_replaced(crash_spec, own_tmp):
    sets = [{"gain": 1.0}, {"gain": 15.0}, {"gain": 2.0}, {"gain": 25.0}, {"gain": 0.5}]
    with SerialEvaluator(crash_spec) as ev:
        good = ev.evaluate([sets[0], sets[2], sets[4]])
        later = ev.evaluate([{"gain": 3.0}])
    with PoolEvaluator(crash_spec, workers=2) as pe:
        got = pe.evaluate(sets)
        after = pe.evaluate([{"gain": 3.0}])  # the pool still works (a set not seen yet)
        # each worker extracts the FMU into a folder of its own, which the parent owns
        scratch = list(own_tmp.glob("tsid-worker-*"))
        assert len(scratch) == 2 and all(list(d.glob("tsid-fmu-*")) for d in scratch)
    np.testing.assert_array_equal(got.costs[[0, 2, 4]], good.costs)
    assert np.all(np.isinf(got.costs[[1, 3]]))
    assert "worker crashed (signal 6 SIGABRT)" in got.errors[1]
    assert "worker crashed (signal 11 SIGSEGV)" in got.errors[3]
    # retried once in a fresh worker before it is scored as failed; both attempts named
    assert got.errors[3].count("SIGSEGV") == 2 and "on the retry in a fresh worker" in got.errors[3]
    assert got.errors[1].startswith("experiment: replicate 1: ")  # the measured input first
    assert got.errors[0] is None and got.errors[2] is None and got.errors[4] is None
    assert got.residuals[1] is None and got.residuals[3] is None
    np.testing.assert_array_equal(after.costs, later.costs)
    # a crashed set counts the simulation that crashed, as a failed one would
    assert got.nfev == good.nfev + 2 and after.nfev == later.nfev == 2
    # crashed workers' extracted FMUs are removed as well as the stopped ones'; what is
    # left is this process's own extraction, kept for its next session of the FMU
    assert not list(own_tmp.glob("tsid-worker-*"))
    assert set(own_tmp.glob("tsid-*")) <= set(extraction.folders())


def test_hanging_row_is_stopped_by_the_time_limit(crash_spec, own_tmp):
    sets = [{"gain": 1.0}, {"gain": 35.0}, {"gain": 2.0}]
    with PoolEvaluator(crash_spec, workers=2, timeout=1.0) as pe:
        got = pe.evaluate(sets)
    assert math.isinf(got.costs[1, 0]) and math.isinf(got.costs[1, 1])
    assert "time limit of 1 s per simulation exceeded" in got.errors[1]
    assert np.all(np.isfinite(got.costs[[0, 2]]))
    assert not list(own_tmp.glob("tsid-*"))  # the killed worker's folder is removed too


def test_missing_dask_is_a_clear_error(lag_spec, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(StudyError, match=r"pip install tsid-fmu\[dask\]"):
        DaskEvaluator(lag_spec, "tcp://127.0.0.1:1")
    with pytest.raises(StudyError, match=r"pip install tsid-fmu\[dask\]"):
        make_evaluator(lag_spec, scheduler="tcp://127.0.0.1:1")


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_costs(lag_spec, serial, tmp_path):
    distributed = pytest.importorskip("distributed")
    expected, clean = serial
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        with DaskEvaluator(lag_spec, cluster.scheduler_address) as pe:
            got = pe.evaluate(SETS)
            sim = pe.simulate([SETS[1]])[0]
    np.testing.assert_array_equal(got.costs, expected.costs)
    assert got.errors == expected.errors and got.nfev == expected.nfev
    for a, b in zip(got.residuals, expected.residuals, strict=True):
        assert (a is None and b is None) or np.array_equal(a, b)
    np.testing.assert_array_equal(sim[0].outputs, clean[0].outputs)


@pytest.mark.slow
def test_script_without_main_guard_can_run_workers(lag_crash_fmus, tmp_path):
    """Workers do not re-run the user's script (no ``if __name__ == "__main__"`` needed)."""
    import subprocess
    from pathlib import Path

    script = tmp_path / "unguarded.py"
    script.write_text(
        "import numpy as np\n"
        "from tsid_fmu.evaluate import EvaluationSpec, PoolEvaluator, PreparedExperiment\n"
        "t = np.arange(101) * 1e-2\n"
        "e = PreparedExperiment(name='e', time=t, input_names=('u',), output_names=('y',),\n"
        "    inputs=np.sin(t)[:, None], measured=np.sin(t)[:, None], weights=np.ones(1),\n"
        "    scale=np.ones(1))\n"
        f"spec = EvaluationSpec(fmu={str(lag_crash_fmus['lag'])!r}, parameter_names=('tau',),\n"
        "    experiments=(e,))\n"
        "with PoolEvaluator(spec, workers=2) as pe:\n"
        "    print('COST', pe.evaluate([{'tau': 0.1}]).costs[0, 0])\n"
    )
    repo = Path(__file__).resolve().parents[1]
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, cwd=repo, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("COST") == 1


@pytest.mark.slow
def test_dask_isolates_crashes_and_hangs(crash_spec):
    distributed = pytest.importorskip("distributed")
    sets = [{"gain": 1.0}, {"gain": 25.0}, {"gain": 35.0}, {"gain": 2.0}]
    with SerialEvaluator(crash_spec) as ev:
        good = ev.evaluate([sets[0], sets[3]])
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        with DaskEvaluator(crash_spec, cluster.scheduler_address, timeout=1.0) as pe:
            got = pe.evaluate(sets)
    np.testing.assert_array_equal(got.costs[[0, 3]], good.costs)
    assert "worker crashed (signal 11 SIGSEGV)" in got.errors[1]
    assert "time limit of 1 s per simulation exceeded" in got.errors[2]
