"""Parallel and Dask evaluation: same costs as serial, crash and hang isolation."""

from __future__ import annotations

import math
import sys

import numpy as np
import pandas as pd
import pytest
from crash_factory import build_crash_fmu
from fmu_factory import build_c_fmu

from tsid_fmu.errors import FMUError, StudyError
from tsid_fmu.parallel import ParallelEvaluator, available_cores, make_evaluator
from tsid_fmu.runner import Evaluator
from tsid_fmu.study import Experiment, Parameter, Study


def _frame(seed: int, n: int = 801) -> pd.DataFrame:
    t = np.arange(n) * 1e-3
    rng = np.random.default_rng(seed)
    u = np.sin(9 * t) + (t > 0.3) + 0.05 * rng.standard_normal(n)
    y = np.interp(t, t, np.convolve(u, np.ones(40) / 40, mode="same"))
    return pd.DataFrame({"time": t, "u": u, "y": y, "y2": 0.5 * y})


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("parallel")
    return {
        "lag": build_c_fmu(d, "PLag", interfaces=("cs",)),
        "crash": build_crash_fmu(d, "PCrash"),
    }


@pytest.fixture(scope="module")
def lag_study(fmus):
    return Study(
        fmu=fmus["lag"],
        parameters=[Parameter("tau", [0.01, 0.03, 0.1]), Parameter("x0", [-0.5, 0.0, 0.5])],
        experiments=[
            Experiment(data=_frame(1), inputs={"u": "u"}, outputs={"y": "y"}, name="a"),
            Experiment(data=_frame(2), inputs={"u": "u"}, outputs={"y": "y2"}, name="b"),
        ],
        replicates=3,
        input_noise=0.02,
        seed=11,
    )


@pytest.fixture(scope="module")
def crash_study(fmus):
    return Study(
        fmu=fmus["crash"],
        parameters=[Parameter("gain", [0.5, 1.0, 2.0])],
        experiments=[Experiment(data=_frame(3), inputs={"u": "u"}, outputs={"y": "y"})],
        start_values={"abort_above": 10.0, "segv_above": 20.0, "hang_above": 30.0},
        replicates=2,
        seed=5,
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
def serial(lag_study):
    with Evaluator(lag_study) as ev:
        return ev.evaluate(SETS), ev.simulate_clean(SETS[1])


def test_parallel_costs_are_bit_identical_to_serial(lag_study, serial):
    expected, _ = serial
    seen = []
    with ParallelEvaluator(lag_study, workers=2) as pe:
        assert pe.n_replicates == 3
        got = pe.evaluate(SETS, progress=lambda done, total: seen.append((done, total)))
        assert pe.nfev == got.nfev
    np.testing.assert_array_equal(got.costs, expected.costs)
    assert got.errors == expected.errors
    assert "tau must be positive" in got.errors[2] and got.errors[2].startswith("a: ")
    assert seen == [(k, len(SETS)) for k in range(1, len(SETS) + 1)]
    # more work than serial only on the failed row (serial stops it at its first failure)
    assert got.nfev >= expected.nfev


def test_simulate_clean_and_recycling_match_serial(lag_study, serial):
    expected, clean = serial
    with ParallelEvaluator(lag_study, workers=2, recycle_after=2) as pe:
        got = pe.evaluate(SETS)
        again = pe.evaluate(SETS[:2])
        sim = pe.simulate_clean(SETS[1])
    np.testing.assert_array_equal(got.costs, expected.costs)
    np.testing.assert_array_equal(again.costs, expected.costs[:2])
    for (p1, y1, e1), (p2, y2, e2) in zip(sim, clean, strict=True):
        assert p1.experiment.name == p2.experiment.name and e1 is None and e2 is None
        np.testing.assert_array_equal(y1, y2)


def test_make_evaluator_chooses_serial_or_parallel(lag_study):
    with make_evaluator(lag_study, workers=1) as ev:
        assert type(ev) is Evaluator
    with make_evaluator(lag_study, workers=1, timeout=5.0) as ev:
        assert isinstance(ev, ParallelEvaluator) and ev.workers == 1
    assert available_cores() >= 1


def test_startup_errors_are_raised_like_serial(lag_study, fmus):
    import dataclasses

    bad = dataclasses.replace(lag_study, parameters=[Parameter("tua", [1.0, 2.0])])
    with pytest.raises(FMUError, match=r"unknown parameter 'tua'.*Did you mean 'tau'"):
        ParallelEvaluator(bad, workers=2)
    with pytest.raises(StudyError, match="workers must be at least 1"):
        ParallelEvaluator(lag_study, workers=0)


def test_crashing_rows_fail_alone_and_workers_are_replaced(crash_study):
    sets = [{"gain": 1.0}, {"gain": 15.0}, {"gain": 2.0}, {"gain": 25.0}, {"gain": 0.5}]
    with Evaluator(crash_study) as ev:
        good = ev.evaluate([sets[0], sets[2], sets[4]])
    with ParallelEvaluator(crash_study, workers=2) as pe:
        got = pe.evaluate(sets)
        after = pe.evaluate([sets[0]])  # the pool still works
    np.testing.assert_array_equal(got.costs[[0, 2, 4]], good.costs)
    assert np.all(np.isinf(got.costs[[1, 3]]))
    assert "worker crashed (signal 6 SIGABRT)" in got.errors[1]
    assert "worker crashed (signal 11 SIGSEGV)" in got.errors[3]
    assert got.errors[0] is None and got.errors[2] is None and got.errors[4] is None
    np.testing.assert_array_equal(after.costs, good.costs[:1])


def test_hanging_row_is_stopped_by_the_time_limit(crash_study):
    sets = [{"gain": 1.0}, {"gain": 35.0}, {"gain": 2.0}]
    with ParallelEvaluator(crash_study, workers=2, timeout=1.0) as pe:
        got = pe.evaluate(sets)
    assert math.isinf(got.costs[1, 0]) and math.isinf(got.costs[1, 1])
    assert "time limit of 1 s per simulation exceeded" in got.errors[1]
    assert np.all(np.isfinite(got.costs[[0, 2]]))


def test_whole_study_is_bit_identical_serial_and_parallel(lag_study):
    import tsid_fmu.engine as engine

    study = Study(
        fmu=lag_study.fmu,
        parameters=[Parameter("tau", [0.01, 0.03, 0.1]), Parameter("x0", [-0.5, 0.0, 0.5])],
        experiments=lag_study.experiments[:1],
        max_iterations=3,
        seed=2,
    )
    serial = engine.identify(study, plots=False)
    with ParallelEvaluator(study, workers=2) as pe:
        parallel = engine.identify(study, plots=False, evaluator=pe)
    assert parallel.x == serial.x and parallel.fun == serial.fun
    for a, b in zip(serial.iterations, parallel.iterations, strict=True):
        np.testing.assert_array_equal(a.costs, b.costs)


def test_missing_dask_is_a_clear_error(lag_study, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(StudyError, match=r"pip install tsid-fmu\[dask\]"):
        ParallelEvaluator(lag_study, scheduler="tcp://127.0.0.1:1")


def test_dask_local_cluster_gives_the_same_costs(lag_study, serial, tmp_path):
    distributed = pytest.importorskip("distributed")
    expected, clean = serial
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        with ParallelEvaluator(lag_study, scheduler=cluster.scheduler_address) as pe:
            got = pe.evaluate(SETS)
            sim = pe.simulate_clean(SETS[1])
    np.testing.assert_array_equal(got.costs, expected.costs)
    assert got.errors == expected.errors
    np.testing.assert_array_equal(sim[0][1], clean[0][1])


def test_script_without_main_guard_can_run_workers(fmus, tmp_path):
    """Workers do not re-run the user's script (no ``if __name__ == "__main__"`` needed)."""
    import subprocess
    from pathlib import Path

    script = tmp_path / "unguarded.py"
    script.write_text(
        "import numpy as np, pandas as pd\n"
        "from tsid_fmu.parallel import ParallelEvaluator\n"
        "from tsid_fmu.study import Experiment, Parameter, Study\n"
        "t = np.arange(101) * 1e-2\n"
        "df = pd.DataFrame({'time': t, 'u': np.sin(t), 'y': np.sin(t)})\n"
        f"st = Study(fmu={str(fmus['lag'])!r}, parameters=[Parameter('tau', [0.1, 0.2])],\n"
        "           experiments=[Experiment(data=df, inputs={'u': 'u'}, outputs={'y': 'y'})])\n"
        "with ParallelEvaluator(st, workers=2) as pe:\n"
        "    print('COST', pe.evaluate([{'tau': 0.1}]).costs[0, 0])\n"
    )
    repo = Path(__file__).resolve().parents[1]
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, cwd=repo, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("COST") == 1


def test_dask_isolates_crashes_and_hangs(crash_study):
    distributed = pytest.importorskip("distributed")
    sets = [{"gain": 1.0}, {"gain": 25.0}, {"gain": 35.0}, {"gain": 2.0}]
    with Evaluator(crash_study) as ev:
        good = ev.evaluate([sets[0], sets[3]])
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        with ParallelEvaluator(crash_study, scheduler=cluster.scheduler_address, timeout=1.0) as pe:
            got = pe.evaluate(sets)
    np.testing.assert_array_equal(got.costs[[0, 3]], good.costs)
    assert "worker crashed (signal 11 SIGSEGV)" in got.errors[1]
    assert "time limit of 1 s per simulation exceeded" in got.errors[2]


def test_a_study_survives_crashing_rows_and_reports_them(crash_study, tmp_path):
    """Rows whose FMU segfaults are scored worst, the workers are replaced, the study
    finishes, and report.md lists the crashed rows with the signal."""
    import dataclasses

    import tsid_fmu.engine as engine

    study = dataclasses.replace(
        crash_study, parameters=[Parameter("gain", [0.5, 1.0, 25.0])], max_iterations=2
    )
    res = engine.identify(study, tmp_path / "out", plots=False, workers=2, timeout=20.0)
    first = res.iterations[0]
    crashed = [e for e in first.errors if e]
    assert len(crashed) == 3 and all("SIGSEGV" in e for e in crashed)
    assert math.isfinite(res.fun) and res.x["gain"] < 25.0
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Failed runs" in report and "worker crashed (signal 11 SIGSEGV)" in report
