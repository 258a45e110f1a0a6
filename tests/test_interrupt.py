"""Interrupting a study: SIGKILL or SIGINT loses at most the iteration in progress.

A real ``tsid identify`` subprocess runs a small study on the lag FMU.  It is killed
once the first iteration's ``record.json`` appears, resumed with ``--resume``, killed
again later, resumed again, and must end with the same ``x`` (bit for bit), the same
number of iterations and simulations as an uninterrupted run.  Every file left behind
by a kill is complete (files are written atomically).  SIGINT exits with status 130
and says how to continue.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmu_factory import LAG_TOML, build_c_fmu, lag_response

POLL = 0.002
TIMEOUT = 120.0

STUDY = LAG_TOML

# every test runs a whole study on the CLI and interrupts it
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("interrupt")
    build_c_fmu(d, "Lag", interfaces=("cs",))
    t = np.arange(0, 20.0 + 1e-9, 0.002)  # 10,001 samples: ~0.2 s per iteration
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5) + 0.3 * np.sin(3 * t)
    y = lag_response(t, u, 0.37, 0.8) + np.random.default_rng(0).normal(0, 0.005, t.shape)
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(d / "d.csv", index=False)
    (d / "study.toml").write_text(STUDY)
    return d / "study.toml"


def _env(tmp: Path) -> dict[str, str]:
    tmp.mkdir(parents=True, exist_ok=True)
    root = Path(__file__).resolve().parents[1]
    path = os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")]))
    return {**os.environ, "PYTHONPATH": path, "TMPDIR": str(tmp)}


def _cmd(study: Path, out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "tsid_fmu", "identify", str(study), "--out", str(out),
            "-q", "--no-plots", *extra]  # fmt: skip


def _run(study: Path, out: Path, tmp: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        _cmd(study, out, *extra),
        env=_env(tmp),
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
        check=False,
    )


def _start_and_signal(
    study: Path, out: Path, tmp: Path, wait_for: int, sig: int, *extra: str
) -> subprocess.Popen:
    """Start a study, send ``sig`` once ``iteration_<wait_for>/record.json`` exists."""
    proc = subprocess.Popen(
        _cmd(study, out, *extra),
        env=_env(tmp),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    marker = out / f"iteration_{wait_for:02d}" / "record.json"
    deadline = time.monotonic() + TIMEOUT
    while not marker.exists():
        if proc.poll() is not None:
            out_, err = proc.communicate()
            pytest.fail(f"the study ended before {marker} appeared:\n{out_}\n{err}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"{marker} did not appear within {TIMEOUT} s")
        time.sleep(POLL)
    assert proc.poll() is None, "the study finished before it could be interrupted"
    proc.send_signal(sig)
    proc.wait(timeout=TIMEOUT)
    return proc


def _complete_records(out: Path) -> list[Path]:
    return sorted(out.glob("iteration_*/record.json"))


def _assert_trail_is_whole(out: Path) -> None:
    """Every file in the trail parses: a kill never leaves half a file."""
    for path in out.rglob("*"):
        if not path.is_file() or path.name.startswith("."):
            continue  # .<name>.<random>.tmp: an atomic write cut short, ignored on resume
        if path.suffix == ".json":
            json.loads(path.read_text())
        elif path.suffix == ".toml":
            tomllib.loads(path.read_text())
        elif path.suffix == ".csv":
            pd.read_csv(path)
    records = _complete_records(out)
    # complete iterations are numbered 1..k without gaps
    assert [p.parent.name for p in records] == [
        f"iteration_{i:02d}" for i in range(1, len(records) + 1)
    ]


@pytest.fixture(scope="module")
def uninterrupted(study, tmp_path_factory) -> dict:
    d = tmp_path_factory.mktemp("full")
    proc = _run(study, d / "out", d / "tmp")
    assert proc.returncode in (0, 1), proc.stderr
    result = json.loads((d / "out" / "result.json").read_text())
    assert result["nit"] >= 4, "the study must run several iterations to be interrupted"
    return {"rc": proc.returncode, "result": result}


def test_sigkill_twice_then_resume_gives_the_same_result(study, uninterrupted, tmp_path):
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    proc = _start_and_signal(study, out, tmp, 1, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL
    _assert_trail_is_whole(out)
    kept = {p: p.read_bytes() for p in _complete_records(out)}
    assert kept and not (out / "result.json").exists()

    # killed again while resuming, two iterations later
    k = len(kept)
    proc = _start_and_signal(study, out, tmp, k + 2, signal.SIGKILL, "--resume")
    assert proc.returncode == -signal.SIGKILL
    _assert_trail_is_whole(out)
    for path, content in kept.items():  # finished iterations are never rewritten
        assert path.read_bytes() == content
    kept = {p: p.read_bytes() for p in _complete_records(out)}

    final = _run(study, out, tmp, "--resume")
    assert final.returncode == uninterrupted["rc"], final.stderr
    for path, content in kept.items():
        assert path.read_bytes() == content
    _assert_trail_is_whole(out)
    result = json.loads((out / "result.json").read_text())
    expected = uninterrupted["result"]
    assert result["x"] == expected["x"]  # bit-identical floats (JSON round-trips repr)
    assert result["fun"] == expected["fun"]
    assert (result["nit"], result["nfev"]) == (expected["nit"], expected["nfev"])


def test_sigint_exits_130_and_says_how_to_resume(study, uninterrupted, tmp_path):
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    proc = _start_and_signal(study, out, tmp, 1, signal.SIGINT)
    err = proc.stderr.read()
    assert proc.returncode == 130, err
    assert "interrupted" in err and "--resume" in err and "Traceback" not in err
    _assert_trail_is_whole(out)
    # a clean interruption also removes the FMU's extraction folder
    assert not list(tmp.glob("tsid-*")), "temporary folders (FMU extractions, workers) left"

    final = _run(study, out, tmp, "--resume")
    assert final.returncode == uninterrupted["rc"], final.stderr
    result = json.loads((out / "result.json").read_text())
    assert result["x"] == uninterrupted["result"]["x"]
    assert result["nfev"] == uninterrupted["result"]["nfev"]


def test_resume_of_a_finished_study_changes_nothing(study, uninterrupted, tmp_path):
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    assert _run(study, out, tmp, "--max-iterations", "2").returncode == 1
    again = _run(study, out, tmp, "--resume", "--max-iterations", "2")
    assert again.returncode == 1, again.stderr
    assert len(_complete_records(out)) == 2
