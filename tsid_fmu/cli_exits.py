"""How ``tsid`` ends: its exit messages, and stdout kept for its results.

The command line (:mod:`tsid_fmu.cli`) ends through these: one line naming the path for
an environment error, the interrupted study's status and what a person can do next,
nothing more after a closed pipe; and while a command runs, what an FMU prints
natively goes to stderr, so that stdout carries only the result (``--json``).
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys
from collections.abc import Iterator, Sequence

__all__ = [
    "environment",
    "error",
    "interrupted",
    "native_output_to_stderr",
    "quiet_stdout",
    "terminal_safe",
]


def environment(exc: OSError) -> str:
    """One line for an environment error, naming the path."""
    reason = exc.strerror or type(exc).__name__
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        reason += " (the disk is full)"
    elif exc.errno == errno.EROFS:
        reason += " (the folder is on a read-only file system)"
    where = exc.filename if exc.filename is not None else "(path not known)"
    return f"cannot write or read {os.fsdecode(where)!s}: {reason}"


def quiet_stdout() -> None:
    """After a broken pipe: send what is left of stdout nowhere (no second error)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # pragma: no cover - stdout without a descriptor
        pass


@contextlib.contextmanager
def native_output_to_stderr() -> Iterator[None]:
    """Keep stdout for tsid's results: what the FMU prints natively goes to stderr.

    An FMU's runtime may ``printf`` to file descriptor 1 (OpenModelica's ``assert |
    debug | division by zero ...``), in this process or in the workers, which inherit
    it; on stdout that broke ``--json``. Descriptor 1 is pointed at stderr for the
    command's length, and :data:`sys.stdout` writes to a copy of the real stdout.
    Nothing changes where stdout has no descriptor (a test's captured stdout).
    """
    try:
        sys.stdout.flush()
        fd, err = sys.stdout.fileno(), sys.stderr.fileno()
        saved = os.dup(fd)
    except (OSError, ValueError, AttributeError):
        yield
        return
    before = sys.stdout
    sys.stdout = open(  # closed below, after the descriptor is restored
        saved, "w", encoding=before.encoding, errors=before.errors, closefd=False
    )
    os.dup2(err, fd)
    try:
        yield
    finally:
        try:
            sys.stdout.flush()
        finally:
            os.dup2(saved, fd)
            with contextlib.suppress(OSError):  # a closed pipe: said once, by the flush
                sys.stdout.close()
            os.close(saved)
            sys.stdout = before


def terminal_safe(message: str) -> str:
    r"""Return ``message`` with its control and format characters written as escapes.

    An error quotes what an FMU printed, a file's names, a study's text: a raw ESC, OSC,
    BEL or NUL there would drive the terminal (``"\x1b]0;title\x07"`` retitles it).
    Each is written as its Python escape (``\x1b``); the message's own line breaks stay.
    """
    return "\n".join(
        "".join(c if c.isprintable() else repr(c)[1:-1] for c in line)
        for line in str(message).split("\n")
    )


def error(message: str, status: int) -> int:
    """Print ``tsid: error: <message>`` on stderr; return the exit status ``status``.

    Control characters in ``message`` are written as escapes (:func:`terminal_safe`).
    """
    print(f"tsid: error: {terminal_safe(message)}", file=sys.stderr)
    return status


def interrupted(terminated: bool, argv: Sequence[str] | None = None) -> int:
    """Say how an interrupted command line ends; return 130 (Ctrl-C) or 143 (SIGTERM).

    Only ``tsid identify`` keeps its finished iterations and has ``--resume``.
    """
    what = "terminated (SIGTERM)" if terminated else "interrupted"
    words = list(sys.argv[1:] if argv is None else argv)
    command = next((w for w in words if not w.startswith("-")), "")
    then = (
        "finished iterations are kept - continue with --resume"
        if command in ("identify", "")
        else "nothing to resume: run the command again"
    )
    print(f"\ntsid: {what}; {then}", file=sys.stderr)
    return 143 if terminated else 130
