"""Child processes that run an FMU's native code away from the study's own process.

The helpers every process-isolating evaluator shares (:mod:`tsid_fmu.evaluate.workers`,
:mod:`tsid_fmu.evaluate.isolated`): how child processes start (``forkserver`` where
available, with tsid-fmu preloaded, never a fork of the calling process), how their end
is described (``"worker crashed (signal 11 SIGSEGV)"``), and how an error crosses back.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import pickle
import signal
import sys
import types
from collections.abc import Iterator
from typing import Any

from tsid_fmu.errors import FMUError, TsidError

__all__ = [
    "children_allowed",
    "error_reason",
    "exit_reason",
    "main_module_hidden",
    "portable_error",
    "worker_context",
]


def worker_context(start_method: str | None = None) -> Any:
    """Return the multiprocessing context child processes start from.

    ``forkserver`` where available (a fork of a small server process that has imported
    tsid-fmu and loaded the compiled loops, never of the calling process), else
    ``spawn``.
    """
    if start_method is None:
        start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
    ctx = mp.get_context(start_method)
    if start_method == "forkserver":
        ctx.set_forkserver_preload(["tsid_fmu.evaluate._preload"])
    return ctx


def error_reason(exc: BaseException) -> str:
    """Text of an exception for a set's error (type named unless it is our own)."""
    return str(exc) if isinstance(exc, TsidError) else f"{type(exc).__name__}: {exc}"


def portable_error(exc: BaseException) -> TsidError:
    """Turn an exception into a picklable TsidError of the same kind, message kept."""
    if isinstance(exc, TsidError):
        try:
            pickle.loads(pickle.dumps(exc))
            return exc
        except Exception:
            return (
                type(exc)(str(exc))
                if type(exc).__module__ == "tsid_fmu.errors"
                else FMUError(str(exc))
            )
    return FMUError(f"the worker could not start: {type(exc).__name__}: {exc}")


def exit_reason(code: int | None) -> str:
    """Describe how a worker process ended (``"worker crashed (signal 11 SIGSEGV)"``)."""
    if code is None:
        return "worker stopped responding"
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = "unknown signal"
        return f"worker crashed (signal {-code} {name})"
    return f"worker exited with status {code}"


@contextlib.contextmanager
def main_module_hidden() -> Iterator[None]:
    """Start a process without it re-importing the ``__main__`` script.

    ``spawn``/``forkserver`` children normally re-run the parent's main script, which
    starts the study again in a script without an ``if __name__ == "__main__":``
    guard. Workers need nothing from ``__main__`` (their target and arguments are
    tsid-fmu objects), so the main module is hidden while the process starts.
    """
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__tsid_worker_main__")
    try:
        yield
    finally:
        if main is not None:
            sys.modules["__main__"] = main


@contextlib.contextmanager
def children_allowed() -> Iterator[None]:
    """Let a daemonic process (a Dask worker) start worker processes of its own."""
    config = mp.current_process()._config  # type: ignore[attr-defined]
    daemon = config.get("daemon")
    config["daemon"] = False
    try:
        yield
    finally:
        if daemon is not None:
            config["daemon"] = daemon
