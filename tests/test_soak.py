"""Long studies: thousands of simulations through one session stay flat in memory and time.

A Taguchi study runs the same FMU hundreds to thousands of times (FMPy users report
crashes after ~1000 instantiations and slow parameter loops).  These tests run 5,000
short simulations through one :class:`~tsid_fmu.fmu.FMUSession`, with a failing run
now and then, and many sessions opened and closed one after another, and check that
resident memory, open file descriptors and the time per simulation do not grow.
"""

from __future__ import annotations

import gc
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from fmu_factory import build_c_fmu, lag_response

import tsid_fmu.fmu.extraction as extraction
from tsid_fmu.errors import SimulationError
from tsid_fmu.fmu import FMUSession

N_SIM = 5_000
N_STEPS = 100
MIB = 1 << 20
PAGE = os.sysconf("SC_PAGE_SIZE")


def rss() -> int:
    """Resident set size of this process in bytes (Linux ``/proc/self/statm``)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * PAGE


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


pytestmark = pytest.mark.skipif(
    not Path("/proc/self/statm").exists(), reason="needs Linux /proc for RSS"
)


@pytest.fixture(scope="module")
def lag(tmp_path_factory) -> Path:
    return build_c_fmu(tmp_path_factory.mktemp("soak"), "Lag", interfaces=("cs",))


def test_5000_simulations_in_one_session_stay_flat(lag):
    t = np.linspace(0.0, 1.0, N_STEPS + 1)
    u = np.sin(7 * t)
    taus = 0.05 + 0.9 * np.random.default_rng(1).random(N_SIM)
    durations = np.empty(N_SIM)
    memory = {}
    failures = 0
    with FMUSession(lag, ["u"], ["y"], parameters=["tau", "t_fail"]) as session:
        for i in range(N_SIM):
            # every 97th run fails mid-way (fmi2DoStep returns Error); the session recovers
            t_fail = 0.5 if i % 97 == 96 else 1e300
            start = time.perf_counter()
            try:
                y = session.simulate(t, u, {"tau": taus[i], "t_fail": t_fail})
            except SimulationError as exc:
                assert "fmi2DoStep" in str(exc)
                failures += 1
            else:
                if i % 1000 == 0:
                    np.testing.assert_allclose(y[:, 0], lag_response(t, u, taus[i]), rtol=1e-9)
            durations[i] = time.perf_counter() - start
            if i + 1 in (1_000, N_SIM):
                gc.collect()
                memory[i + 1] = rss()
        assert session.nfev == N_SIM
    assert failures == N_SIM // 97
    growth = memory[N_SIM] - memory[1_000]
    assert growth < 4 * MIB, f"RSS grew by {growth / MIB:.2f} MiB over 4,000 simulations"
    first, last = np.mean(durations[:500]), np.mean(durations[-500:])
    assert last / first < 3.0, f"time per simulation grew from {first:.2e} s to {last:.2e} s"


@pytest.mark.slow
def test_many_sessions_opened_and_closed_leave_nothing_behind(lag, tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    t = np.linspace(0.0, 0.1, 11)

    def cycle() -> None:
        with FMUSession(lag, ["u"], ["y"], parameters=["tau"]) as session:
            session.simulate(t, np.ones(11), {"tau": 0.3})

    for _ in range(20):  # warm up caches and lazy imports
        cycle()
    gc.collect()
    fds, mem = open_fds(), rss()
    for _ in range(300):
        cycle()
    gc.collect()
    assert open_fds() == fds, "file descriptors leak per session"
    assert rss() - mem < 8 * MIB, f"RSS grew by {(rss() - mem) / MIB:.2f} MiB over 300 sessions"
    # one extraction for all 320 sessions, kept for the next one until the process exits
    left = set(tmp_path.iterdir())
    assert len(left) <= 1 and left <= set(extraction.folders()), "extraction folders leak"
