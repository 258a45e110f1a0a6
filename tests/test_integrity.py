"""Issue 13, careless use: an owned, locked study folder and a trail that detects damage.

The attacks of the issue, each a test:

* another study (another seed, other parameters, phases instead of one stage, another
  data file or FMU) run into a study's ``--out`` folder: exit 2 naming the keys that
  differ, and the folder byte-identical afterwards; the same with ``--resume``;
* a folder holding files tsid-fmu did not write: exit 2, untouched;
* two ``tsid identify`` processes on one folder: the second exits 2 naming the lock;
* a valid-JSON edit of ``record.json`` (``best_cost``), a truncated ``runs.csv`` or
  ``decision.json``, a missing plot, an edited ``stage.json``: ``--resume`` names the
  file and continues nothing; a person's edit of ``next_levels.toml`` stays allowed;
* every exit status from a real ``tsid`` process: 0, 1, 2, 3, 4 (a full disk and a
  read-only folder, as one line naming the path), 130, and a closed pipe, with no
  traceback; a bug (an unexpected exception) exits with 70, not with 1 as a result
  stopped at its limit does.

On the code before this change (commit 7e0d910) the other-study, foreign-file, lock,
tamper and exit-4/pipe tests fail (it overwrote, trusted the files, and ended in a
traceback); the exit statuses 0, 1, 2, 3 and 130 guard what the lead built.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, lag_response

from tsid_fmu.cli import main
from tsid_fmu.trail.owner import LOCK, FolderLock

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 120.0

STUDY = """\
[study]
fmu = "Lag.fmu"
[data]
file = "{data}"
inputs = {{ u = "u" }}
outputs = {{ y = "y" }}
[method]
seed = {seed}
replicates = 1
max_iterations = 10
cost = "iae"  # the SISO paper's cost: these tests were written for it
weighting = "none"

[leveling]
{leveling}
[parameters]
tau = {{ levels = [0.1, 0.4, 1.0], min = 0 }}
x0 = {{ levels = [-1.0, 0.0, 2.0] }}
{extra}"""

LEVELING = "tolerance = 0.2\nsignificance_db = 0.5"
PHASES = '[[phases]]\nparameters = ["tau"]\n[[phases]]\nparameters = ["x0"]\n'


def _data(path: Path, seconds: float) -> None:
    t = np.arange(0, seconds + 1e-9, 0.01)
    u = np.where((t % 1.0) < 0.5, 1.0, -0.5)
    y = lag_response(t, u, 0.37, 0.8) + np.random.default_rng(0).normal(0, 0.005, t.shape)
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(path, index=False)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("integrity")
    build_c_fmu(d, "Lag", interfaces=("cs",))
    _data(d / "d.csv", 2.0)
    _data(d / "slow.csv", 100.0)
    endless = "tolerance = 1e-12\nsignificance_db = 0.0\nstall = 0"  # runs until stopped
    for name, kw in {
        "a": {},
        "seed": {"seed": 8},
        "phases": {"extra": PHASES},
        "slow": {"data": "slow.csv", "leveling": endless},
    }.items():
        args = {"data": "d.csv", "seed": 7, "extra": "", "leveling": LEVELING} | kw
        (d / f"{name}.toml").write_text(STUDY.format(**args))
    return d


def identify(study: Path, out: Path, *extra: str) -> int:
    return main(["identify", str(study), "--out", str(out), "-q", "--no-plots",
                 "--workers", "1", *extra])  # fmt: skip


def snapshot(out: Path) -> dict[str, tuple[bytes | None, int]]:
    """Every path under ``out`` with its bytes and mode."""
    return {
        str(p.relative_to(out)): (p.read_bytes() if p.is_file() else None, p.stat().st_mode)
        for p in sorted(out.rglob("*"))
    }


def one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.startswith("tsid: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


@pytest.fixture(scope="module")
def done(folder, tmp_path_factory) -> Path:
    """A finished study A (stopped by the iteration limit after 2 iterations).

    Exit status 0: the local probes at the study's tolerance (0.2 of a first range) find
    no lower cost, so the answer is shown stationary at that resolution (exit status 1
    is only for an answer not shown to be an optimum).
    """
    out = tmp_path_factory.mktemp("done") / "out"
    assert identify(folder / "a.toml", out, "--max-iterations", "2") == 0
    saved = json.loads((out / "result.json").read_text())
    assert saved["message"].startswith("converged: ")  # the verdict; the account says why
    assert any("iteration limit (2)" in line for line in saved["account"])
    return out


# ---------------------------------------------------------------- owned folders


@pytest.mark.parametrize(
    ("study", "resume", "message"),
    [
        ("seed", False, r"holds another study; keys that differ: method\.seed: 7 -> 8"),
        ("seed", True, r"--resume: the study changed since .* method\.seed: 7 -> 8"),
        ("phases", False, r"holds another study; keys that differ: .*phases\.1\.experiments"),
        ("phases", True, r"the study changed .* phases\.1\.parameters \(added\)"),
        ("slow", False, r"keys that differ: experiments: \[\"d\"\] -> \[\"slow\"\]"),
    ],
)  # fmt: skip
def test_another_study_is_refused_and_the_folder_stays_byte_identical(
    folder, done, capsys, study, resume, message
):
    before = snapshot(done)
    rc = identify(folder / f"{study}.toml", done, *(["--resume"] if resume else []))
    err = one_line(capsys)
    assert rc == 2 and re.search(message, err), err
    assert snapshot(done) == before


def test_a_changed_fmu_or_data_file_is_named(folder, tmp_path, capsys):
    d = tmp_path / "copy"
    d.mkdir()
    for name in ("Lag.fmu", "d.csv", "a.toml"):
        (d / name).write_bytes((folder / name).read_bytes())
    out = tmp_path / "out"
    assert identify(d / "a.toml", out, "--pause-after", "1") == 3
    capsys.readouterr()
    with open(d / "Lag.fmu", "ab") as fh:  # a rebuilt FMU: other bytes
        fh.write(b"\0")
    with open(d / "d.csv", "a") as fh:
        fh.write("\n")
    assert identify(d / "a.toml", out, "--resume") == 2
    err = one_line(capsys)
    assert "fmu.sha256" in err and "experiments.d.data.sha256" in err


def test_a_folder_with_files_tsid_did_not_write_is_refused(folder, tmp_path, capsys):
    out = tmp_path / "mine"
    (out / "sub").mkdir(parents=True)
    (out / "notes.txt").write_text("my notes")
    before = snapshot(out)
    for extra in ([], ["--resume"]):
        assert identify(folder / "a.toml", out, *extra) == 2
        err = one_line(capsys)
        assert "holds files tsid-fmu did not write ('notes.txt', 'sub/')" in err
        assert snapshot(out) == before
    # a trail without a fingerprint (older tsid-fmu, or copied by hand) is not trusted
    (out / "notes.txt").unlink()
    (out / "sub").rename(out / "iteration_01")
    assert identify(folder / "a.toml", out, "--resume") == 2
    assert "'iteration_01/'" in one_line(capsys)


def test_a_folder_a_study_left_before_any_result_may_be_reused(folder, tmp_path, capsys):
    out = tmp_path / "out"
    bad = (folder / "a.toml").read_text().replace("x0 = {", "x00 = {")
    (folder / "bad.toml").write_text(bad)
    assert identify(folder / "bad.toml", out) == 2  # fails at the start: unknown parameter
    assert "unknown parameter 'x00'" in one_line(capsys)
    assert identify(folder / "a.toml", out, "--max-iterations", "1") == 1
    assert "x00" not in (out / "study.toml").read_text()
    fingerprint = json.loads((out / "fingerprint.json").read_text())
    assert fingerprint["study"]["parameters"] == ["tau", "x0"]


def test_the_lock_stops_a_second_writer(folder, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    holder = FolderLock(out)
    holder.acquire()
    try:
        assert identify(folder / "a.toml", out) == 2
        err = one_line(capsys)
        assert f"is in use: process {os.getpid()} holds its lock {out / LOCK}" in err
    finally:
        holder.release()
    assert identify(folder / "a.toml", out, "--max-iterations", "1") == 1


# ---------------------------------------------------------------- tampering


def _edit_record(path: Path) -> None:
    data = json.loads(path.read_text())
    data["best_cost"] = 1.0  # valid JSON, a plausible number
    path.write_text(json.dumps(data))


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])


TAMPER = [
    ("iteration_01/record.json", _edit_record, r"record\.json: the iteration record was changed"),
    ("iteration_02/runs.csv", _truncate, r"iteration_02/runs\.csv: changed or damaged since"),
    ("iteration_01/decision.json", _truncate, r"decision\.json: changed or damaged since"),
    ("iteration_02/levels.csv", Path.unlink, r"iteration_02/levels\.csv: missing, but"),
]  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize(("name", "damage", "message"), TAMPER, ids=[t[0] for t in TAMPER])
def test_a_damaged_or_changed_trail_file_is_named_on_resume(
    folder, tmp_path, capsys, name, damage, message
):
    out = tmp_path / "out"
    assert identify(folder / "a.toml", out, "--pause-after", "2") == 3
    capsys.readouterr()
    damage(out / name)
    before = snapshot(out)
    assert identify(folder / "a.toml", out, "--resume") == 2
    err = one_line(capsys)
    assert re.search(message, err) and "redo" in err, err
    assert snapshot(out) == before  # nothing half-trusted, nothing written


def test_an_edited_stage_record_is_named(folder, done):
    from tsid_fmu.errors import StudyError
    from tsid_fmu.study import load_study
    from tsid_fmu.trail import Trail

    data = json.loads((done / "stage.json").read_text())
    assert "digest" in data
    with Trail(done, load_study(folder / "a.toml"), resume=True) as trail:
        assert trail.stage("").cost == data["cost"]
        path = done / "refinement" / "stage.json"
        path.parent.mkdir()
        try:
            path.write_text(json.dumps({**data, "cost": 1e-9}))  # an edited copy
            with pytest.raises(StudyError, match=r"stage\.json: the stage record was changed"):
                trail.stage("refinement")
        finally:
            path.unlink()
            path.parent.rmdir()


@pytest.mark.slow
def test_a_person_may_still_edit_next_levels(folder, tmp_path, capsys):
    out = tmp_path / "out"
    assert identify(folder / "a.toml", out, "--pause-after", "1") == 3
    (out / "iteration_01" / "next_levels.toml").write_text(
        "[levels]\ntau = [0.3, 0.35, 0.4]\nx0 = [0.7, 0.8, 0.9]\n"
    )
    # exit status 0: at the limit, the probes at the study's tolerance find nothing lower
    assert identify(folder / "a.toml", out, "--resume", "--max-iterations", "2") == 0
    record = json.loads((out / "iteration_02" / "record.json").read_text())
    assert record["frame"]["factors"][0]["values"] == [0.3, 0.35, 0.4]
    assert set(record["files"]) >= {"runs.csv", "decision.json", "next_levels.toml"}


# ---------------------------------------------------------------- real processes


def _env(tmp: Path, **extra: str) -> dict[str, str]:
    tmp.mkdir(parents=True, exist_ok=True)
    path = os.pathsep.join(filter(None, [str(ROOT), *extra.pop("PATHS", "").split(os.pathsep)]))
    return {**os.environ, "PYTHONPATH": path, "TMPDIR": str(tmp), **extra}


def _tsid(*args: str, env: dict[str, str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tsid_fmu", *args], env=env,
                          capture_output=True, text=True, timeout=TIMEOUT, **kw)  # fmt: skip


def _identify(study: Path, out: Path, env: dict[str, str], *extra: str):
    return _tsid("identify", str(study), "--out", str(out), "-q", "--no-plots",
                 "--workers", "1", *extra, env=env)  # fmt: skip


FAULTS = """\
import errno, os, tempfile
_fault = os.environ.get("TSID_TEST_FAULT")
_after = [int(os.environ.get("TSID_TEST_FAULT_AFTER", "0"))]
if _fault == "ENOSPC":  # a disk that fills up: the n-th write of a file fails
    _fsync = os.fsync
    def fsync(fd):
        _after[0] -= 1
        if _after[0] < 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return _fsync(fd)
    os.fsync = fsync
elif _fault == "EROFS":  # a folder that turns read-only: creating a file fails
    _mkstemp = tempfile.mkstemp
    def mkstemp(*args, dir=None, **kw):
        _after[0] -= 1
        if _after[0] < 0:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), dir)
        return _mkstemp(*args, dir=dir, **kw)
    tempfile.mkstemp = mkstemp
elif _fault == "BUG":  # a bug in tsid-fmu: any exception it does not expect
    def fsync(fd):
        raise ZeroDivisionError("injected")
    os.fsync = fsync
"""


def _single_error(proc: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.startswith("tsid: error: ") and proc.stderr.count("\n") == 1, proc.stderr
    return proc.stderr


@pytest.mark.slow
def test_each_exit_status_from_a_real_cli_run(folder, tmp_path):
    env = _env(tmp_path / "tmp")
    a = folder / "a.toml"
    assert _identify(a, tmp_path / "o0", env).returncode == 0  # converged
    assert _identify(a, tmp_path / "o1", env, "--max-iterations", "1").returncode == 1
    proc = _identify(folder / "phases.toml", tmp_path / "o1", env)  # another study
    assert proc.returncode == 2 and "holds another study" in _single_error(proc)
    assert _identify(a, tmp_path / "o3", env, "--pause-after", "1").returncode == 3
    (tmp_path / "inject").mkdir()
    (tmp_path / "inject" / "sitecustomize.py").write_text(FAULTS)
    faults = [("ENOSPC", "6", "(the disk is full)"),
              ("EROFS", "3", "(the folder is on a read-only file system)")]  # fmt: skip
    for fault, after, words in faults:
        bad = _env(tmp_path / "tmp", PATHS=str(tmp_path / "inject"), TSID_TEST_FAULT=fault,
                   TSID_TEST_FAULT_AFTER=after)  # fmt: skip
        proc = _identify(a, tmp_path / f"o4{fault}", bad)
        err = _single_error(proc)
        assert proc.returncode == 4 and words in err, err
        assert f"cannot write or read {tmp_path / f'o4{fault}'}" in err, err
    # a bug is told apart from every result: exit 70, with the traceback to report
    bug = _env(tmp_path / "tmp", PATHS=str(tmp_path / "inject"), TSID_TEST_FAULT="BUG")
    proc = _identify(a, tmp_path / "o70", bug)
    assert proc.returncode == 70 and "ZeroDivisionError: injected" in proc.stderr
    assert proc.stderr.rstrip().splitlines()[-1].startswith("tsid: internal error: this is a bug")
    # a closed pipe (tsid info FMU | head): quiet, no traceback
    proc = subprocess.Popen([sys.executable, "-m", "tsid_fmu", "info", str(folder / "Lag.fmu")],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
    proc.stdout.close()  # the reader goes away before tsid writes
    assert proc.wait(timeout=TIMEOUT) == 141
    assert proc.stderr.read() == b""


def _unwritable(path: Path) -> bool:
    try:
        (path / "probe").touch()
    except OSError:
        return True
    (path / "probe").unlink()
    return False


@contextlib.contextmanager
def _read_only(out: Path) -> Iterator[str]:
    """Make the empty folder ``out`` unwritable for this process, even as root.

    Without root a mode of 0555 does; root writes through modes (and CI runs as root),
    so there the folder is made immutable (``chattr +i``), else a read-only tmpfs is
    mounted on it. Skips, naming what was tried, where neither works.
    """
    if os.geteuid() != 0:
        out.chmod(0o555)
        try:
            yield "mode 0555"
        finally:
            out.chmod(0o755)
        return
    ways = [
        ("chattr +i", ["chattr", "+i", str(out)], ["chattr", "-i", str(out)]),
        ("a read-only tmpfs", ["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(out)],
         ["umount", str(out)]),
    ]  # fmt: skip
    tried = []
    for name, on, off in ways:
        try:
            done = subprocess.run(on, capture_output=True, text=True, timeout=30)
        except (OSError, subprocess.TimeoutExpired) as exc:
            tried.append(f"{name}: {exc}")
            continue
        if done.returncode != 0 or not _unwritable(out):
            if done.returncode == 0:
                subprocess.run(off, capture_output=True, timeout=30)
            tried.append(f"{name}: {(done.stderr or 'root could still write').strip()}")
            continue
        try:
            yield name
        finally:
            subprocess.run(off, capture_output=True, timeout=30, check=True)
        return
    pytest.skip("as root no folder could be made unwritable; tried " + "; ".join(tried))


@pytest.mark.slow
def test_a_read_only_folder_is_exit_4(folder, tmp_path):
    out = tmp_path / "ro"
    out.mkdir()
    with _read_only(out):
        proc = _identify(folder / "a.toml", out, _env(tmp_path / "tmp"))
    assert proc.returncode == 4 and str(out) in _single_error(proc)


@pytest.mark.slow
def test_two_processes_on_one_folder_and_an_interrupt(folder, tmp_path):
    out, env = tmp_path / "out", _env(tmp_path / "tmp")
    cmd = [sys.executable, "-m", "tsid_fmu", "identify", str(folder / "slow.toml"),
           "--out", str(out), "-q", "--no-plots", "--workers", "1",
           "--max-iterations", "100000"]  # fmt: skip
    first = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)  # fmt: skip
    deadline = time.monotonic() + TIMEOUT
    while not (out / LOCK).is_file() or not (out / LOCK).read_text().strip():
        assert first.poll() is None, first.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.01)
    second = _identify(folder / "slow.toml", out, env)
    assert first.poll() is None, "the first study ended too soon to test the lock"
    assert second.returncode == 2
    assert f"is in use: process {first.pid} holds its lock {out / LOCK}" in _single_error(second)
    first.send_signal(signal.SIGINT)
    _, err = first.communicate(timeout=TIMEOUT)
    assert first.returncode == 130 and "--resume" in err and "Traceback" not in err, err
