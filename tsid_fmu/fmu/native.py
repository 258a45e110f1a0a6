"""What an FMU prints natively during a run: captured, echoed on stderr, kept on record.

An FMU's runtime may write to file descriptors 1 and 2 directly (OpenModelica's
``assert | debug | division by zero ...``, a Python FMU's warnings), bypassing the FMI
logger that :mod:`tsid_fmu.fmu.logs` receives. :class:`NativeOutput` points both
descriptors at a private file for the length of one FMU call, then puts them back,
echoes what was written on stderr (so a person still sees it) and keeps it as
:attr:`NativeOutput.text`: a failed run's reason quotes its tail, and a study records
every run's text in its folder (:func:`recording`, :func:`record`).

The descriptors belong to the process, so only one capture is active at a time, and
only in the main thread; a call made while another capture is active (another
thread) runs uncaptured.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

from tsid_fmu.errors import TsidError

__all__ = ["TAIL", "NativeOutput", "record", "recording"]

T = TypeVar("T")

#: characters of printed output a failed run's reason quotes (its end)
TAIL = 600
#: characters of one run's output kept at most (its end)
KEPT = 20000
#: what a run printed when the FMU closed the descriptors of the capture
CLOSED_NOTE = "[tsid: the FMU closed its output descriptor; what it printed in this call is lost]\n"

_ACTIVE = threading.Lock()  # one capture of the process's descriptors at a time
_SINK_LOCK = threading.Lock()
_SINK: list[Path] = []  # the study folder's record, while a study runs (innermost last)

try:  # the C library's stdio buffers: an FMU's printf lands in the file only when flushed
    _LIBC: ctypes.CDLL | None = ctypes.CDLL(None)
except OSError:  # pragma: no cover - no C library to flush (not seen on Linux/macOS)
    _LIBC = None


def _flush_c() -> None:
    if _LIBC is not None:
        with contextlib.suppress(AttributeError, OSError):
            _LIBC.fflush(None)


def tail(text: str, n: int = TAIL) -> str:
    """Return the last ``n`` characters of ``text``, marked as cut when cut."""
    text = text.strip()
    return text if len(text) <= n else "..." + text[-n:]


class NativeOutput:
    """Capture descriptors 1 and 2 around FMU calls (one object per FMU session).

    Parameters
    ----------
    enabled : bool
        Capture at all (otherwise the blocks run as they are).
    echo : bool
        Write what was captured on stderr after each call.
    """

    def __init__(self, enabled: bool = True, echo: bool = True) -> None:
        self.enabled = enabled
        self.echo = echo
        self.text = ""  # what the last captured call printed
        self._fd: int | None = None  # the private file, a raw descriptor (see _restore)

    @contextlib.contextmanager
    def capture(self) -> Iterator[None]:
        """Capture what native code prints inside the block into :attr:`text`."""
        self.text = ""
        if not self.enabled or threading.current_thread() is not threading.main_thread():
            yield
            return
        if not _ACTIVE.acquire(blocking=False):
            yield
            return
        try:
            saved = self._redirect()
            if saved is None:
                yield
                return
            try:
                yield
            finally:
                self._restore(saved)
        finally:
            _ACTIVE.release()

    def _redirect(self) -> tuple[int, int] | None:
        try:
            for stream in (sys.stdout, sys.stderr):
                with contextlib.suppress(Exception):
                    stream.flush()
            _flush_c()
            if self._fd is None:
                fd, name = tempfile.mkstemp(prefix="tsid-fmu-output-")
                os.unlink(name)
                self._fd = fd
            saved = os.dup(1), os.dup(2)
        except (OSError, ValueError):
            return None
        os.dup2(self._fd, 1)
        os.dup2(self._fd, 2)
        return saved

    def _restore(self, saved: tuple[int, int]) -> None:
        """Put descriptors 1 and 2 back and read what was printed.

        An FMU may close descriptors it does not own (a runtime that closes every one
        above 2): the private file's or the saved copies of 1 and 2. Then what it
        printed is lost, and :attr:`text` says so in one line; the file is made anew at
        the next call. Its descriptor is never closed again by tsid: the number may
        already be another file's.
        """
        _flush_c()
        lost = False
        for fd, copy in zip((1, 2), saved, strict=True):
            try:
                os.dup2(copy, fd)
            except OSError:  # the FMU closed the copy: the descriptor cannot be put back
                lost = True
                with contextlib.suppress(OSError):
                    null = os.open(os.devnull, os.O_WRONLY)
                    os.dup2(null, fd)
                    os.close(null)
                continue
            with contextlib.suppress(OSError):
                os.close(copy)
        fd, data = self._fd, b""
        try:
            if fd is None:
                raise OSError("closed")
            size = os.fstat(fd).st_size  # written through descriptors 1 and 2
            if size:
                os.lseek(fd, max(0, size - KEPT), os.SEEK_SET)
                data = os.read(fd, KEPT)
                os.ftruncate(fd, 0)
                os.lseek(fd, 0, os.SEEK_SET)
        except OSError:
            self._fd, lost = None, True  # not closed: the FMU did; the number may be reused
        if lost:
            data = CLOSED_NOTE.encode() + data
        if not data:
            return
        self.text = data.decode("utf-8", errors="replace")
        if self.echo:
            with contextlib.suppress(OSError):
                os.write(2, data)

    def reason(self) -> str:
        """Return the tail of :attr:`text` as the end of an error message ('' if none)."""
        return f" The FMU printed: {tail(self.text)}" if self.text.strip() else ""

    def call(self, fn: Callable[..., T], *args: Any) -> T:
        """Return ``fn(*args)`` run under :meth:`capture`.

        A :class:`~tsid_fmu.errors.TsidError` it raises is raised again with the tail
        of what was printed added to its message (:meth:`amended`).
        """
        with self.capture():
            try:
                return fn(*args)
            except TsidError as exc:
                failed = exc
        raise self.amended(failed) from failed.__cause__

    def amended(self, exc: BaseException) -> BaseException:
        """Return ``exc`` with :meth:`reason` added to its message (the same type)."""
        extra = self.reason()
        if not extra or len(exc.args) != 1 or not isinstance(exc.args[0], str):
            return exc
        try:
            new = type(exc)(exc.args[0] + extra)
        except TypeError:  # pragma: no cover - an error type with other arguments
            return exc
        new.__cause__ = exc.__cause__
        return new

    def close(self) -> None:
        """Close the private file."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None


@contextlib.contextmanager
def recording(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Record, while the block runs, what the FMU printed in each run into ``path``.

    The file is made at the first run that printed something; nothing is written
    otherwise.
    """
    target = Path(path)
    with _SINK_LOCK:
        _SINK.append(target)
    try:
        yield target
    finally:
        with _SINK_LOCK:
            _SINK.remove(target)


def record(parameters: Mapping[str, float], text: str) -> None:
    """Append one parameter set's printed output to the active record (if any)."""
    if not text.strip():
        return
    with _SINK_LOCK:
        if not _SINK:
            return
        target = _SINK[-1]
        values = ", ".join(f"{k} = {v:.10g}" for k, v in parameters.items())
        with contextlib.suppress(OSError), target.open("a", encoding="utf-8") as f:
            f.write(f"== parameter set: {values}\n{text.rstrip()}\n")
