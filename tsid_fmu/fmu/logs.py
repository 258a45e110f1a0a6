"""The FMU's log messages: keep the last few per session, forward them to a logger.

FMI 2.0 loggers are variadic, which ctypes cannot receive; FMPy's native proxy formats
the message and forwards it to *one* Python callback that it keeps in a static C
variable.  Installing a callback per session would redirect every FMU's messages in
the process to the newest session and leave a dangling pointer (a segfault on the
next message) once that session is gone.  So one dispatcher, alive for the whole
process, is installed once; each session's callbacks carry their own id as the
``componentEnvironment``, and the dispatcher hands a message to the session with that
id.  Messages of FMUs not opened by a session (plain FMPy use) go to FMPy's printer.

FMI 3.0 loggers are not variadic: the session passes :meth:`LogCapture.fmi3` to FMPy.

A message is kept as the characters it means: the XML references some tools leave in
their text (Dymola's ``Failed condition: T &gt;= 200``) are read (:func:`unescape_xml`),
so that a report escapes the text once, not twice.
"""

from __future__ import annotations

import html
import itertools
import logging
import re
from collections import deque
from collections.abc import Callable
from ctypes import byref
from typing import Any

__all__ = ["STATUS_NAMES", "LogCapture", "Logger", "fmi2_callbacks", "unescape_xml"]

#: FMI status names by value
STATUS_NAMES = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
#: number of messages a session keeps for its error messages
N_KEPT = 8

Logger = logging.Logger | Callable[[str], None]

_XML_REFERENCE = re.compile(r"&(?:lt|gt|amp|quot|apos|#[0-9]{1,7}|#[xX][0-9a-fA-F]{1,6});")
"""XML's five named references and its character references (with their ``;``)."""


def unescape_xml(text: str) -> str:
    """Return ``text`` with the XML references in it as the characters they stand for.

    ``T &gt;= 200`` gives ``T >= 200``, ``&amp;gt;`` gives ``&gt;`` (one pass: what a
    tool escaped once is read once); HTML's other names (``&copy;``), a reference
    without its ``;`` and a bare ``&`` stay as written.
    """
    return _XML_REFERENCE.sub(lambda m: html.unescape(m.group(0)), text)


_TARGETS: dict[int, LogCapture] = {}
_IDS = itertools.count(1)
_FMI2_PROXY: Any = None


class LogCapture:
    """Receive an FMU's log messages, keep the last few, forward them to a logger.

    Parameters
    ----------
    logger : logging.Logger or callable, optional
        Receives every message as one line (``[Status] category: text``).
    """

    def __init__(self, logger: Logger | None) -> None:
        self.messages: deque[str] = deque(maxlen=N_KEPT)
        self.logger = logger
        self.env_id = 0  # key of this capture in _TARGETS (FMI 2.0), once registered

    def release(self) -> None:
        """Stop receiving FMI 2.0 messages (after the instance is freed)."""
        _TARGETS.pop(self.env_id, None)
        self.env_id = 0

    def add(self, status: int, category: bytes | None, message: bytes | None) -> None:
        """Keep and forward one message."""
        label = STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else str(status)
        text = unescape_xml((message or b"").decode("utf-8", errors="replace").strip())
        cat = unescape_xml((category or b"").decode("utf-8", errors="replace"))
        line = f"[{label}] {cat + ': ' if cat else ''}{text}"
        self.messages.append(line)
        if self.logger is None:
            return
        if isinstance(self.logger, logging.Logger):
            level = logging.WARNING if status >= 1 else logging.DEBUG
            self.logger.log(level if status < 3 else logging.ERROR, "%s", line)
        else:
            self.logger(line)

    def fmi3(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        """FMI 3.0 ``logMessage`` callback."""
        self.add(status, category, message)

    def text(self) -> str:
        """Return the kept messages as the tail of an error message."""
        if not self.messages:
            return " The FMU logged no messages."
        return " Last FMU log messages: " + " | ".join(self.messages)


def _fmi2_dispatch(env: Any, instance: bytes, status: int, category: bytes, message: bytes) -> None:
    target = _TARGETS.get(env or 0)
    if target is not None:
        target.add(status, category, message)
    else:
        from fmpy.fmi2 import printLogMessage

        printLogMessage(env, instance, status, category, message)


def fmi2_callbacks(capture: LogCapture) -> Any:
    """Return FMI 2.0 callbacks (``fmi2CallbackFunctions``) whose messages reach ``capture``.

    The caller keeps the returned structure alive as long as the instance.
    """
    global _FMI2_PROXY
    from fmpy import calloc, free
    from fmpy.fmi2 import (
        fmi2CallbackAllocateMemoryTYPE,
        fmi2CallbackFreeMemoryTYPE,
        fmi2CallbackFunctions,
        fmi2CallbackLoggerTYPE,
    )

    if _FMI2_PROXY is None:
        from fmpy.logging import addLoggerProxy

        dispatcher = fmi2CallbackLoggerTYPE(_fmi2_dispatch)
        holder = fmi2CallbackFunctions()
        holder.logger = dispatcher
        addLoggerProxy(byref(holder))  # holder.logger is now the native proxy
        _FMI2_PROXY = (holder, dispatcher)  # both stay alive for the whole process
    if capture.env_id == 0:
        capture.env_id = next(_IDS)
        _TARGETS[capture.env_id] = capture
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _FMI2_PROXY[0].logger
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = capture.env_id
    return callbacks
