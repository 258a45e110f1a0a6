"""Ctrl-C during an import is postponed until the import is over (tsid_fmu.interrupt).

Seen before the fix: Ctrl-C during the first simulation (which imports Numba) was either
swallowed by the library being imported (the study ran on) or left CPython marked so
that the process ended killed by SIGINT (-2) instead of with 130.
"""

from __future__ import annotations

import importlib
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from tsid_fmu.interrupt import interrupts_outside_imports

SWALLOWER = """
import signal, time
signal.raise_signal(signal.SIGINT)
try:  # a library with a bare except, as some have in their import-time code
    time.sleep(0.2)
except:  # noqa: E722
    pass
done = True
"""


def test_an_interrupt_inside_an_import_comes_after_it(tmp_path, monkeypatch):
    (tmp_path / "tsid_test_swallower.py").write_text(SWALLOWER)
    monkeypatch.syspath_prepend(str(tmp_path))
    sys.modules.pop("tsid_test_swallower", None)
    reached = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_outside_imports():
            module = importlib.import_module("tsid_test_swallower")
            reached.append(module.done)
            time.sleep(2.0)  # the postponed Ctrl-C arrives here
            reached.append("slept")
    assert reached == [True]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_the_handler_is_restored_and_a_plain_interrupt_still_raises():
    with pytest.raises(KeyboardInterrupt):
        with interrupts_outside_imports():
            assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler
            signal.raise_signal(signal.SIGINT)
            time.sleep(2.0)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


SCRIPT = """
import sys, time
from tsid_fmu.interrupt import interrupts_outside_imports
try:
    with interrupts_outside_imports():
        exec("import signal, time\\nsignal.raise_signal(signal.SIGINT)\\ntime.sleep(0.2)\\n")
        time.sleep(2.0)
except KeyboardInterrupt:
    sys.exit(130)
sys.exit(1)
"""


def test_an_interrupt_inside_exec_text_leaves_the_exit_status_alone(tmp_path):
    # run with -m, as ``python -m tsid_fmu``: there CPython turns the mark into -2
    (tmp_path / "tsid_test_exec.py").write_text(textwrap.dedent(SCRIPT))
    done = subprocess.run(
        [sys.executable, "-m", "tsid_test_exec"], cwd=tmp_path, capture_output=True, timeout=60
    )
    assert done.returncode == 130, done.stderr.decode()
