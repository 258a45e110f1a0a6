"""Ctrl-C is neither lost nor raised inside an import (tsid_fmu.interrupt).

Seen before the fix, when Ctrl-C came during the first simulation (which imports Numba):
the interrupt was raised inside llvmlite's ctypes callback and dropped by CPython (the
study ran on), or it left CPython marked by an interrupted ``exec`` so that the process
ended killed by SIGINT (-2) instead of with 130.
"""

from __future__ import annotations

import ctypes
import importlib
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from tsid_fmu.interrupt import delivered_interrupts

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
        with delivered_interrupts():
            module = importlib.import_module("tsid_test_swallower")
            reached.append(module.done)
            time.sleep(2.0)  # the postponed Ctrl-C arrives here
            reached.append("slept")
    assert reached == [True]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_interrupt_dropped_in_a_ctypes_callback_comes_again(monkeypatch):
    """qsort calls back into Python from C; an exception there is dropped by CPython,
    which would print it with a traceback; the drop is silent and Ctrl-C comes again."""
    dropped = []
    monkeypatch.setattr(sys, "unraisablehook", dropped.append)
    compare_type = ctypes.CFUNCTYPE(
        ctypes.c_int, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int)
    )
    calls = []

    def compare(a, b):
        calls.append(1)
        if len(calls) == 1:
            signal.raise_signal(signal.SIGINT)  # the handler runs here, inside the callback
        return a[0] - b[0]

    values = (ctypes.c_int * 5)(5, 1, 4, 2, 3)
    reached = []
    with pytest.raises(KeyboardInterrupt):
        with delivered_interrupts():
            ctypes.CDLL(None).qsort(values, 5, ctypes.sizeof(ctypes.c_int), compare_type(compare))
            reached.append("sorted")
            time.sleep(2.0)  # the repeated Ctrl-C arrives here
            reached.append("slept")
    assert reached == ["sorted"] and len(calls) > 1
    assert dropped == [] and sys.unraisablehook == dropped.append  # silent, and restored
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_the_handler_is_restored_and_a_plain_interrupt_still_raises():
    with pytest.raises(KeyboardInterrupt):
        with delivered_interrupts():
            assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler
            signal.raise_signal(signal.SIGINT)
            time.sleep(2.0)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


SCRIPT = """
import sys, time
from tsid_fmu.interrupt import delivered_interrupts
try:
    with delivered_interrupts():
        exec("import signal, time\\nsignal.raise_signal(signal.SIGINT)\\ntime.sleep(0.2)\\n")
        time.sleep(2.0)
except KeyboardInterrupt:
    sys.exit(130)
sys.exit(1)
"""


@pytest.mark.slow
def test_an_interrupt_inside_exec_text_leaves_the_exit_status_alone(tmp_path):
    # run with -m, as ``python -m tsid_fmu``: there CPython turns the mark into -2
    (tmp_path / "tsid_test_exec.py").write_text(textwrap.dedent(SCRIPT))
    done = subprocess.run(
        [sys.executable, "-m", "tsid_test_exec"], cwd=tmp_path, capture_output=True, timeout=60
    )
    assert done.returncode == 130, done.stderr.decode()
