"""Ctrl-C that never lands inside an import.

In CPython a :class:`KeyboardInterrupt` raised while a module is being imported, or while
code compiled from a string runs (``exec``/``eval``, which ``collections.namedtuple`` and
Numba use at import time), is not safe to catch:

- a bare ``except:`` in the library being imported can swallow it, and the study then
  runs on and ignores Ctrl-C;
- one that leaves an ``exec`` of a string marks the interpreter, which then ends killed
  by SIGINT (exit status -2) even after the command line caught the interrupt, kept the
  finished iterations and returned 130.

Both were seen when Ctrl-C came during the first simulation, which imports Numba. The
command line therefore runs under :func:`interrupts_outside_imports`: an interrupt that
arrives inside an import is postponed by a few milliseconds, until the main thread is out
of it, and then raised as usual.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["interrupts_outside_imports"]

RETRY_S = 0.02
"""Seconds after which a postponed interrupt is tried again."""


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
def interrupts_outside_imports() -> Iterator[None]:
    """Within the block, raise Ctrl-C's :class:`KeyboardInterrupt` only outside imports.

    Does nothing outside the main thread or when SIGINT already has a handler other than
    Python's default one (a caller that handles Ctrl-C itself keeps doing so). The
    previous handler is restored on exit.
    """
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    main = threading.main_thread().ident
    assert main is not None
    postponed: list[threading.Timer] = []
    resent: list[bool] = []

    def resend() -> None:
        resent.append(True)
        signal.pthread_kill(main, signal.SIGINT)

    def handler(signum: int, frame: FrameType | None) -> None:
        if _inside_import(frame):
            retry = threading.Timer(RETRY_S, resend)
            retry.daemon = True
            postponed.append(retry)
            retry.start()
            return
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        for retry in postponed:
            retry.cancel()
        if len(resent) < len(postponed) and sys.exc_info()[0] is None:
            raise KeyboardInterrupt  # the block ended before a postponed Ctrl-C came back
