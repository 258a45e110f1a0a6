"""Ctrl-C that is neither lost nor raised inside an import.

Python raises :class:`KeyboardInterrupt` wherever the main thread happens to be, and in a
few places that is not safe:

- **inside a ctypes callback** (Numba's llvmlite calls one while it loads its cache, an
  FMU calls its logger) **or a finalizer** (``__del__``, a generator closed by the
  garbage collector): CPython prints "Exception ignored ..." with a traceback and drops
  the interrupt, so the study runs on and ignores Ctrl-C;
- **inside an import**, where a bare ``except:`` of the library can swallow it;
- **inside code compiled from text** (``exec``/``eval``, which ``namedtuple`` and Numba
  use at import time): an interrupt that leaves it marks the interpreter, which then
  ends killed by SIGINT (exit status -2) even after the command line caught the
  interrupt, kept the finished iterations and returned 130.

All three were seen when Ctrl-C came during the first simulation, which imports Numba.
The command line therefore runs under :func:`delivered_interrupts`. Once Ctrl-C has come,
SIGINT is sent again to the main thread every :data:`RETRY_S` seconds until the block is
left; each time, the interrupt is raised unless the main thread is inside an import or
``exec``'d text (it waits for the next time) or is already unwinding a
:class:`KeyboardInterrupt` (the cleanup of ``finally`` blocks is left alone). An interrupt
that CPython drops is dropped silently (:data:`sys.unraisablehook`): the next repeat
brings it again.

Two more ways the command line can be stopped are handled the same way:

- **Ctrl-C while** ``tsid`` **starts**: importing the package (numpy, pandas, scipy,
  matplotlib) takes a good part of a second, before any code of the command line runs.
  When this process *is* the command line (``tsid ...`` or ``python -m tsid_fmu ...``,
  judged from :data:`sys.orig_argv`), :mod:`tsid_fmu._startup`, imported first thing
  by the package, holds Ctrl-C until :func:`~tsid_fmu.cli.main` takes it
  (:func:`take_startup_interrupt`) and exits with 130. A program that merely imports
  tsid-fmu is left alone.
- **SIGTERM** (``kill``, a batch system's time limit): under :func:`terminated_as_interrupt`
  it is delivered as Ctrl-C is, so the same cleanup runs (workers, the FMU's
  extraction folder, the folder's lock) and the command line exits with 143.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

__all__ = [
    "RETRY_S",
    "delivered_interrupts",
    "take_startup_interrupt",
    "terminated_as_interrupt",
]

RETRY_S = 0.05
"""Seconds between the repeats of SIGINT after Ctrl-C, until the interrupt is out."""


def _inside_import(frame: FrameType | None) -> bool:
    """Return True if ``frame`` or a caller is the import machinery or ``exec``'d text."""
    while frame is not None:
        name = frame.f_code.co_filename
        if name.startswith("<frozen importlib"):
            return True
        if name == "<string>" and frame.f_back is not None:  # not ``python -c`` itself
            return True
        frame = frame.f_back
    return False


@contextmanager
def delivered_interrupts() -> Iterator[None]:
    """Within the block, Ctrl-C raises :class:`KeyboardInterrupt` where it can be caught.

    Does nothing outside the main thread or when SIGINT already has a handler other than
    Python's default one (a caller that handles Ctrl-C itself keeps doing so). If Ctrl-C
    came but the block ended without an exception (the interrupt was swallowed at its
    very end), :class:`KeyboardInterrupt` is raised on leaving it. The previous handler
    is restored.
    """
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    main = threading.main_thread().ident
    assert main is not None
    stop = threading.Event()
    repeater: list[threading.Thread] = []

    def repeat() -> None:
        while not stop.wait(RETRY_S):
            signal.pthread_kill(main, signal.SIGINT)

    def handler(signum: int, frame: FrameType | None) -> None:
        if not repeater:
            repeater.append(threading.Thread(target=repeat, name="tsid-ctrl-c", daemon=True))
            repeater[0].start()
        if (
            stop.is_set()
            or isinstance(sys.exc_info()[1], KeyboardInterrupt)  # on its way out already
            or _inside_import(frame)  # not safe here: the next repeat will do
        ):
            return
        raise KeyboardInterrupt

    previous_hook = sys.unraisablehook

    def unraisable(info: Any) -> None:
        if not (repeater and isinstance(info.exc_value, KeyboardInterrupt)):
            previous_hook(info)  # else one that CPython dropped: a repeat brings it again

    signal.signal(signal.SIGINT, handler)
    sys.unraisablehook = unraisable
    try:
        yield
    finally:
        stop.set()  # the handler now lets a repeat still on its way pass
        for thread in repeater:
            thread.join()
        signal.signal(signal.SIGINT, signal.default_int_handler)
        sys.unraisablehook = previous_hook
    if repeater:
        raise KeyboardInterrupt  # Ctrl-C came, and the block ended before it got out


def take_startup_interrupt() -> int | None:
    """Stop holding Ctrl-C and SIGTERM (the defaults again); return the first that came.

    They are held while the command line starts (:mod:`tsid_fmu._startup`).
    """
    from tsid_fmu import _startup

    if signal.getsignal(signal.SIGINT) is _startup.hold:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if signal.getsignal(signal.SIGTERM) is _startup.hold:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    return _startup.HELD[0] if _startup.HELD else None


@contextmanager
def terminated_as_interrupt() -> Iterator[list[int]]:
    """Within the block, SIGTERM interrupts as Ctrl-C does; yield the signals that came.

    The handler hands SIGTERM to SIGINT's handler (that of :func:`delivered_interrupts`
    when the block is inside it, so it is not raised inside an import either) and
    records it in the yielded list, for the exit status. Does nothing outside the main
    thread or when SIGTERM already has a handler. The previous handler is restored.
    """
    came: list[int] = []
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL
    ):
        yield came
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        came.append(signum)
        on_sigint = signal.getsignal(signal.SIGINT)
        if callable(on_sigint):
            on_sigint(signal.SIGINT, frame)
        else:
            raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield came
    finally:
        signal.signal(signal.SIGTERM, previous)
