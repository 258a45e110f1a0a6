"""Imported first by the package: Ctrl-C held while the command line ``tsid`` starts.

Importing tsid-fmu takes a good part of a second (numpy, pandas, scipy, matplotlib);
Ctrl-C in that time raised :class:`KeyboardInterrupt` inside the import machinery, with
a traceback and death by SIGINT. When this process *is* the command line (``tsid ...``
or ``python -m tsid_fmu ...``, judged from :data:`sys.orig_argv`), Ctrl-C and SIGTERM are
held from here until :func:`tsid_fmu.cli.main` takes them
(:func:`tsid_fmu.interrupt.take_startup_interrupt`) and exits with 130 or 143. A program
that imports tsid-fmu is left alone.

This module imports nothing but built-in modules, so that the hold starts within
microseconds of the package's first line.
"""

import _signal as signal  # the C module: `signal` builds its enums first (milliseconds)
import os
import sys

HELD: list[int] = []
"""Ctrl-C or SIGTERM that came while the command line started (signal numbers)."""


def hold(signum: int, frame: object) -> None:
    """Signal handler: remember the signal, raise nothing."""
    HELD.append(signum)


def starting_cli() -> bool:
    """Return True if this process was started as the command line ``tsid``."""
    argv = list(getattr(sys, "orig_argv", []))
    if "-m" in argv[:-1]:
        return argv[argv.index("-m") + 1] in ("tsid_fmu", "tsid_fmu.cli")
    script = next((a for a in argv[1:] if not a.startswith("-")), "")
    return bool(script) and os.path.basename(script) in ("tsid", "tsid.exe", "tsid-script.py")


def hold_startup_signals() -> None:
    """If this process is the command line starting, hold Ctrl-C and SIGTERM until taken.

    Does nothing in a program that imports tsid-fmu or outside the main thread; a signal
    that already has a handler other than Python's default one keeps it.
    """
    if not starting_cli():
        return
    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, hold)
        if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
            signal.signal(signal.SIGTERM, hold)
    except ValueError:  # not the main thread
        pass


hold_startup_signals()
