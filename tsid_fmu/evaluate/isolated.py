"""One child process that runs calls of a function, each under a time limit.

The study's checks outside the evaluators (the solver-fidelity check of
:mod:`tsid_fmu.uncertainty.fidelity`) simulate the FMU too. :class:`IsolatedCalls` runs
those simulations in a child process of their own, one call at a time, so that an FMU
that hangs is stopped at the time limit and one that crashes ends only the child: either
way the call raises :class:`~tsid_fmu.errors.SimulationError` with the reason, and the
study goes on.

Examples
--------
>>> with IsolatedCalls(limit=5.0, what="Model.fmu") as calls:  # doctest: +SKIP
...     y = calls.call(simulate_one, spec, x)
"""

from __future__ import annotations

import shutil
import signal
import tempfile
from collections.abc import Callable
from multiprocessing.connection import Connection, wait
from typing import Any

from tsid_fmu.errors import SimulationError
from tsid_fmu.evaluate.processes import (
    error_reason,
    exit_reason,
    main_module_hidden,
    portable_error,
    worker_context,
)

__all__ = ["IsolatedCalls"]

STOP_GRACE = 2.0  # seconds the child gets to close its FMUs before it is killed


def _child_main(conn: Connection, scratch: str) -> None:
    """Entry point of the child: run ``(function, args)`` requests until told to stop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's business
    tempfile.tempdir = scratch
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        function, args = msg
        try:
            reply: tuple[str, Any] = ("ok", function(*args))
        except Exception as exc:  # the reason crosses back; the child stays usable
            reply = ("error", portable_error(exc) if _ours(exc) else error_reason(exc))
        conn.send(reply)


def _ours(exc: BaseException) -> bool:
    return type(exc).__module__ == "tsid_fmu.errors"


class IsolatedCalls:
    """A child process that runs one call at a time under a time limit (context manager).

    The process starts at the first call and is replaced after a call that it did not
    survive (a crash, or killed at the time limit).

    Parameters
    ----------
    limit : float or None
        Seconds a call may take; None: no limit.
    what : str
        What the calls simulate, for the messages (the FMU's file name).
    """

    def __init__(self, limit: float | None, what: str) -> None:
        self.limit, self.what = limit, what
        self._ctx = worker_context()
        self._process: Any = None
        self._conn: Connection | None = None
        self._scratch: str | None = None

    def _start(self) -> Connection:
        if self._conn is None:
            self._scratch = tempfile.mkdtemp(prefix="tsid-check-")
            self._conn, child = self._ctx.Pipe()
            self._process = self._ctx.Process(
                target=_child_main, args=(child, self._scratch), name="tsid-check", daemon=True
            )
            try:
                with main_module_hidden():
                    self._process.start()
            except BaseException:  # Ctrl-C while it starts: nothing is left behind
                child.close()
                self.close(kill=True)
                raise
            child.close()
        return self._conn

    def call(self, function: Callable[..., Any], *args: Any) -> Any:
        """Return ``function(*args)`` run in the child process.

        Raises
        ------
        SimulationError
            The call passed the time limit (the child was killed), the child crashed,
            or ``function`` raised (its message kept; a tsid-fmu error keeps its type).
        """
        conn = self._start()
        conn.send((function, args))
        sentinel = self._process.sentinel
        try:
            ready = wait([conn, sentinel], timeout=self.limit)
        except BaseException:  # Ctrl-C: the child goes with the call it runs
            self.close(kill=True)
            raise
        if conn in ready:
            try:
                status, value = conn.recv()
            except (EOFError, OSError):
                status, value = "dead", None
            if status == "ok":
                return value
            if status == "error":
                raise value if isinstance(value, Exception) else SimulationError(str(value))
        if not ready:
            self.close(kill=True)
            raise SimulationError(
                f"{self.what}: time limit of {self.limit:g} s per simulation exceeded; the "
                "check's process was killed"
            )
        self._process.join(5)
        reason = exit_reason(self._process.exitcode).replace("worker", "the check's process")
        self.close(kill=True)
        raise SimulationError(f"{self.what}: {reason}")

    def close(self, kill: bool = False) -> None:
        """Stop the child (kill it with ``kill``) and remove its temporary folder."""
        conn, process, scratch = self._conn, self._process, self._scratch
        self._conn = self._process = self._scratch = None
        if process is not None and process.pid is None:  # never started
            process = None
        if process is not None:
            if not kill and conn is not None:
                try:
                    conn.send(None)
                except (OSError, EOFError, BrokenPipeError):
                    pass
                process.join(STOP_GRACE)
            if process.is_alive():
                process.kill()
            process.join(5)
        if conn is not None:
            conn.close()
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)

    def __enter__(self) -> IsolatedCalls:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close(kill=True)
        except Exception:
            pass
