"""Ctrl-C or SIGTERM at any moment of a ``tsid`` run: exit 130 (143) with one line.

Issue 25: Ctrl-C 0.15-0.25 s after start, while ``tsid`` imports its package (numpy,
pandas, scipy, matplotlib), died with a KeyboardInterrupt traceback from importlib and
by the signal (-2), although docs/explanation/architecture.md says Ctrl-C is never raised
inside an import.
SIGTERM (``kill``, a batch system's time limit) ended the process with 143 and no
message, without the cleanup Ctrl-C gets (the FMU's extraction folder was left).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from fmu_factory import lag_case

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = """\
import re
import sys
from tsid_fmu.cli import main
if __name__ == '__main__':
    sys.argv[0] = re.sub(r'(-script\\.pyw|\\.exe)?$', '', sys.argv[0])
    sys.exit(main())
"""  # what pip writes as the ``tsid`` console script

# every test starts ``tsid`` in a fresh interpreter and interrupts it
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("startup")
    fmu = lag_case(d, 0.0002)  # 5,001 samples
    (d / "study.toml").write_text(
        f'[study]\nfmu = "{fmu.name}"\n[data]\nfile = "good.csv"\ninputs = {{ u = "u" }}\n'
        'outputs = { y = "y" }\n[method]\nmax_iterations = 8\nweighting = "none"\n'
        "[leveling]\ntolerance = 0.0001\n"
        "[parameters]\ntau = { levels = [0.1, 0.3, 0.6], min = 0 }\n"
    )
    (d / "tsid").write_text(SCRIPT)
    return d / "study.toml"


def _start(study: Path, out: Path, how: str) -> subprocess.Popen:
    tmp = out.parent / "tmp"
    tmp.mkdir(exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp)}
    head = [sys.executable, "-m", "tsid_fmu"] if how == "-m" else [sys.executable, str(how)]
    cmd = [*head, "identify", str(study), "--out", str(out), "-q", "--no-plots"]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=out.parent)  # fmt: skip


def _signal_after(proc: subprocess.Popen, delay: float, sig: int) -> tuple[int, str]:
    time.sleep(delay)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err


def _before_the_hold(err: str) -> bool:
    """Whether a traceback's tsid-fmu frames are only the loading of ``_startup`` itself.

    That is ``tsid_fmu/__init__.py``'s first import, or ``_startup.py`` before its hold
    (seen: the signal in importlib's ``get_data`` reading ``_startup``'s code).
    """
    frames = re.findall(r'File "([^"]+)", line \d+, in [^\n]*\n(?:    ([^\n]*))?', err)
    ours = [(f, code) for f, code in frames if f"{os.sep}tsid_fmu{os.sep}" in f]
    return all(
        f.endswith(f"{os.sep}_startup.py")
        or (f.endswith(f"{os.sep}__init__.py") and code.startswith("import tsid_fmu._startup"))
        for f, code in ours
    )


def test_only_the_loading_of_the_hold_itself_counts_as_python_starting():
    seen = (
        'Traceback (most recent call last):\n  File "<frozen runpy>", line 189, in _run\n'
        f'  File "{ROOT}{os.sep}tsid_fmu{os.sep}__init__.py", line 20, in <module>\n'
        "    import tsid_fmu._startup  # noqa: F401  # isort: skip\n"
        '  File "<frozen importlib._bootstrap_external>", line 1127, in get_data\n'
        "KeyboardInterrupt\n"
    )
    assert _before_the_hold(seen)
    later = seen.replace("line 20", "line 21").replace(
        "import tsid_fmu._startup  # noqa: F401  # isort: skip", "from tsid_fmu.errors import ("
    )
    assert not _before_the_hold(later)


@pytest.mark.parametrize("delay", [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5])
@pytest.mark.parametrize("how", ["-m", "script"])
def test_ctrl_c_while_tsid_starts_exits_130_with_one_line(study, tmp_path, delay, how):
    script = str(study.parent / "tsid") if how == "script" else "-m"
    rc, err = _signal_after(_start(study, tmp_path / "out", script), delay, signal.SIGINT)
    if "Traceback" in err and _before_the_hold(err):
        # Python itself was still starting (site, runpy), or still reading the module that
        # holds the signal: no line of tsid-fmu had run, so it cannot help it (seen at
        # 0.05 s on a busy machine); any later is asserted
        return
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    if rc in (0, 1):  # finished before the signal came: a clean normal finish
        return
    assert rc == 130, (rc, err)
    assert err.strip().splitlines() == [
        "tsid: interrupted; finished iterations are kept - continue with --resume"
    ], err


@pytest.mark.parametrize("delay", [0.3, 0.5])
def test_sigterm_while_tsid_starts_exits_143_with_one_line(study, tmp_path, delay):
    rc, err = _signal_after(_start(study, tmp_path / "out", "-m"), delay, signal.SIGTERM)
    assert "Traceback" not in err, err
    if rc in (0, 1):  # finished before the signal came
        return
    assert rc == 143, (rc, err)
    assert (
        err.strip()
        == "tsid: terminated (SIGTERM); finished iterations are kept - continue with --resume"
    )


def test_sigterm_mid_study_cleans_up_like_ctrl_c(study, tmp_path):
    import fcntl

    out = tmp_path / "out"
    proc = _start(study, out, "-m")
    marker = out / "iteration_01" / "record.json"
    deadline = time.monotonic() + 120
    while not marker.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    if proc.poll() is not None:
        pytest.fail(f"the study ended before it could be terminated: {proc.communicate()}")
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    if proc.returncode in (0, 1):
        pytest.skip("the study finished before SIGTERM came")
    assert proc.returncode == 143, err
    assert "terminated (SIGTERM)" in err and "--resume" in err and "Traceback" not in err
    # the FMU's extraction folder is removed and the folder's lock is free again
    assert not list((tmp_path / "tmp").glob("tsid-*"))
    with open(out / ".tsid.lock", "a+") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
