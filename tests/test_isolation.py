"""Every simulation under the time limit, and isolated, on one core or one worker too.

Issue 25: an FMU that hangs on every call stalled the study (the fidelity check ran in
the study's process with no limit); with one usable core or ``--workers 1`` the study
ran in its own process, so a hanging FMU hung it and a segfaulting one ended it with exit
139; and a crashed row was scored as failed without a second try. The FMUs are built
here with the C factory (:mod:`crash_factory`).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from crash_factory import build_crash_fmu
from spec_helpers import experiment, lag_frame, make_spec

import tsid_fmu
from tsid_fmu import Experiment, Method, Parameter, Study
from tsid_fmu.evaluate import PoolEvaluator
from tsid_fmu.evaluate.workers import _SINCE

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 2.0  # --timeout of the hanging studies
PLANNED = 3  # the fidelity check at the start point, then two start points, one by one


@pytest.fixture(scope="module")
def crashy(tmp_path_factory) -> tuple[Path, Path]:
    """The crash FMU and a data file for it."""
    d = tmp_path_factory.mktemp("crashy")
    lag_frame(3).to_csv(d / "data.csv", index=False)
    return build_crash_fmu(d), d / "data.csv"


def _study(tmp_path: Path, crashy: tuple[Path, Path], start_values: str) -> Path:
    fmu, data = crashy
    path = tmp_path / "study.toml"
    path.write_text(
        f'[study]\nfmu = "{fmu.as_posix()}"\nstart_values = {{ {start_values} }}\n'
        f'[data]\nfile = "{data.as_posix()}"\ninputs = {{ u = "u" }}\noutputs = {{ y = "y" }}\n'
        "[method]\nmax_iterations = 1\n"
        "[parameters]\ngain = { levels = [0.5, 1.0, 2.0] }\n"
    )
    return path


def _one_core() -> None:
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def _tsid(study: Path, *more: str, one_core: bool = False) -> tuple[int, str, float]:
    """Run ``python -m tsid_fmu identify`` on this checkout; return status, stderr, seconds."""
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "tsid_fmu", "identify", str(study), "--out",
         str(study.parent / "out"), "-q", "--no-plots", *more],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=_one_core if one_core else None,
    )  # fmt: skip
    return proc.returncode, proc.stderr, time.monotonic() - t0


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs sched_setaffinity")
@pytest.mark.parametrize(
    "how", [("--workers", "1"), ("--workers", "2"), ()], ids=["workers1", "workers2", "one-core"]
)
def test_an_fmu_that_hangs_on_every_call_ends_the_study(crashy, tmp_path, how):
    """Within 2 x the limit per planned check (plus start-up), one line, exit 2."""
    study = _study(tmp_path, crashy, "hang_above = -1e300")
    status, err, seconds = _tsid(study, "--timeout", str(LIMIT), *how, one_core=not how)
    assert status == 2, err
    assert err.startswith("tsid: error: taguchi: no start point finished a simulation within")
    assert err.count("\n") == 1 and "time limit of 2 s per simulation exceeded" in err
    startup = 15.0  # interpreter, imports, the worker processes, on a loaded machine
    assert seconds < 2 * LIMIT * PLANNED + startup, seconds


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs sched_setaffinity")
def test_a_segfaulting_fmu_on_one_core_gives_failed_rows_and_a_result(crashy, tmp_path):
    study = _study(tmp_path, crashy, "segv_above = 0.7")  # gain 1 and 2 crash, 0.5 runs
    status, err, _ = _tsid(study, one_core=True)
    assert status in (0, 1), err
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["params"]["gain"] < 0.7  # the answer lies where the FMU runs
    check = result["extra"]["fidelity"]["start"]["message"]
    assert "not checked" in check and "signal 11 SIGSEGV" in check  # the check crashed alone
    assert "signal 11 SIGSEGV" in (tmp_path / "out" / "report.md").read_text()


@pytest.mark.slow
def test_a_check_past_the_time_limit_says_so_and_the_result_is_written(crashy, tmp_path):
    """The fidelity reference (4 x finer steps) passes the limit; the study's runs do not."""
    fmu, data = crashy
    import pandas as pd

    study = Study(
        fmu=fmu,
        parameters=[Parameter("gain", [0.5, 1.0, 2.0])],
        experiments=[Experiment(data=pd.read_csv(data), inputs={"u": "u"}, outputs={"y": "y"})],
        start_values={"delay": -0.0005},  # 0.5 ms asleep per step: ~0.4 s a run, 4x finer ~1.6 s
        method=Method(cost="iae", max_iterations=1, refine="none"),
    )
    res = tsid_fmu.identify(study, tmp_path / "out", workers=1, timeout=1.2, plots=False)
    saved = json.loads((tmp_path / "out" / "result.json").read_text())
    answer = saved["extra"]["fidelity"]["answer"]["message"]
    assert answer.startswith("solver fidelity (answer): not checked")
    assert "time limit of 1.2 s per simulation exceeded" in answer
    assert answer in res.warnings and saved["params"] == res.params


@pytest.mark.slow
def test_a_crashed_row_is_retried_once_in_a_fresh_worker(crashy):
    """A worker killed in the middle of a set (a crash not due to the parameters): the set
    runs again in a fresh worker, succeeds, and the first attempt is noted."""
    fmu, data = crashy
    import pandas as pd

    spec = make_spec(
        fmu,
        ["gain"],
        [experiment(pd.read_csv(data), {"u": "u"}, {"y": "y"})],
        cost="iae",
        start_values={"delay": -0.0005},
    )
    with PoolEvaluator(spec, workers=1, timeout=30) as pe:
        clean = pe.evaluate([{"gain": 1.0}])
        worker = pe._pool.workers[0]

        def crash_it() -> None:  # as a vendor library would, once, mid-simulation
            while worker.state[_SINCE] == 0:
                time.sleep(0.01)
            os.kill(worker.process.pid, signal.SIGSEGV)

        killer = threading.Thread(target=crash_it)
        killer.start()
        got = pe.evaluate([{"gain": 1.5}])
        killer.join()
        again = pe.evaluate([{"gain": 2.0}])
        retried = pe.retried
    assert got.errors == [None] and np.all(np.isfinite(got.costs)), got.errors
    assert got.nfev == clean.nfev == again.nfev  # the last attempt's count alone
    assert len(retried) == 1 and "gain=1.5" in retried[0]
    assert "worker crashed (signal 11 SIGSEGV)" in retried[0] and "retry" in retried[0]
