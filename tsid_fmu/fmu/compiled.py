"""Choose how the step loops run: compiled by Numba, or interpreted.

The loops of :mod:`tsid_fmu.fmu.steploop` are one Python source per FMI version.  With
Numba installed (``pip install tsid-fmu[fast]``) :func:`cs_loop` returns them compiled
to machine code that calls the FMU's C functions directly; without it, when the
environment variable ``TSID_FMU_LOOP=python`` is set, or if compiling fails, it returns
the same functions to be interpreted.  Same arguments, same ``(status, step, call)``
return, every FMI status checked, so the session reports a failure naming the FMI call,
the step and the time whichever mode ran.

Compiled code is cached on disk (Numba's ``cache=True``), so only the first process on
a machine pays the compile time (about a second); worker processes load it from the
cache, ideally in :func:`warm_up` while they start.

The Model Exchange integrator of :mod:`tsid_fmu.fmu.meloop` is chosen the same way by
:func:`me_loop` (compiled on its first use only, so Co-Simulation studies never pay for
it).
"""

from __future__ import annotations

import logging
import os
import threading
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

import tsid_fmu.fmu.meloop as meloop
import tsid_fmu.fmu.steploop as steploop

__all__ = [
    "LOOP_ENV",
    "CompileNotice",
    "backend",
    "cs_loop",
    "me_loop",
    "numba_available",
    "warm_up",
]

LOOP_ENV = "TSID_FMU_LOOP"
"""Environment variable: ``python`` forces the interpreted loops (default: compiled)."""

Loop = Callable[..., tuple[int, int, int]]

_log = logging.getLogger(__name__)
_lock = threading.Lock()
_PYTHON: dict[int, Loop] = {2: steploop._cs_loop_fmi2, 3: steploop._cs_loop_fmi3}
_compiled: dict[int, Loop] | None = None
_failed: str | None = None  # why the compiled loops are unavailable, once known


def numba_available() -> bool:
    """Return True if Numba can be imported."""
    try:
        import numba  # noqa: F401
    except Exception:  # ImportError, or a broken install (e.g. a NumPy it does not support)
        return False
    return True


def _build() -> dict[int, Loop]:
    """Import (compile on first call, or load from Numba's cache) the compiled loops."""
    import tsid_fmu.fmu._numba as _numba  # imports Numba: only when it is wanted

    return {2: _numba.loop2, 3: _numba.loop3}


def _wrap(compiled: Loop, major: int) -> Loop:
    """Call the compiled loop; on a Numba typing/compile error use the Python one for good."""
    fallback = _PYTHON[major]

    def loop(*args: Any) -> tuple[int, int, int]:
        global _failed
        if _failed is None:
            try:
                status, k, call = compiled(*args)
            except Exception as exc:  # numba.core.errors.NumbaError: compile/typing failed
                if "numba" not in type(exc).__module__:
                    raise
                _failed = f"compiling the FMI {major} loop failed: {exc}"
                warnings.warn(
                    f"tsid_fmu.fmu.compiled: {_failed}; using the slower Python loop",
                    RuntimeWarning,
                    stacklevel=2,
                )
            else:
                return int(status), int(k), int(call)
        return fallback(*args)

    loop.__name__ = f"cs_loop_fmi{major}_numba"
    loop.__doc__ = f"Numba-compiled FMI {major} step loop (see tsid_fmu.fmu.steploop)."
    return loop


def _loops() -> dict[int, Loop] | None:
    """Return the compiled loops (built once per process), or None if unavailable."""
    global _compiled, _failed
    if os.environ.get(LOOP_ENV, "").strip().lower() == "python":
        return None
    if _compiled is not None or _failed is not None:
        return _compiled
    with _lock:
        if _compiled is None and _failed is None:
            if not numba_available():
                _failed = "Numba is not installed (pip install tsid-fmu[fast])"
                _log.info("tsid_fmu.fmu.compiled: %s; using the Python loop", _failed)
                return None
            try:
                built = _build()
            except Exception as exc:  # a Numba/llvmlite that cannot build the loops
                _failed = f"Numba cannot build the loops: {exc}"
                _log.warning("tsid_fmu.fmu.compiled: %s; using the Python loop", _failed)
                return None
            _compiled = {m: _wrap(built[m], m) for m in (2, 3)}
    return _compiled


def cs_loop(major: int) -> Loop:
    """Return the Co-Simulation step loop for FMI ``major`` (2 or 3).

    Parameters
    ----------
    major : int
        FMI major version.

    Returns
    -------
    callable
        The loop of :mod:`tsid_fmu.fmu.steploop` for that version
        (``_cs_loop_fmi2`` or ``_cs_loop_fmi3``): compiled by Numba when available,
        else the Python function itself.
    """
    loops = _loops()
    if loops is None or _failed is not None:
        return _PYTHON[major]
    return loops[major]


def backend() -> str:
    """Return ``"numba"`` if :func:`cs_loop` gives compiled loops, else ``"python"``.

    The answer triggers compilation on first use; the reason for ``"python"`` is
    logged (``logging.getLogger("tsid_fmu.fmu.compiled")``).
    """
    return "numba" if _loops() is not None and _failed is None else "python"


_me: dict[str, Any] = {"loop": None, "failed": None}


def me_loop() -> Callable[..., tuple[int, int, int, float]]:
    """Return the Model Exchange loop: compiled by Numba when available, else Python.

    Returns
    -------
    callable
        ``_me_loop`` of :mod:`tsid_fmu.fmu.meloop`, compiled (built on the first call,
        or loaded from Numba's cache) or the Python function itself; same arguments
        and ``(status, index, call, time)`` result.
    """
    python = meloop._me_loop
    if _loops() is None or _me["failed"] is not None:
        return python
    if _me["loop"] is None:
        with _lock:
            if _me["loop"] is None and _me["failed"] is None:
                try:
                    import tsid_fmu.fmu._numba_me as _numba_me
                except Exception as exc:  # a Numba that cannot build it
                    _me["failed"] = f"Numba cannot build the Model Exchange loop: {exc}"
                    _log.warning("tsid_fmu.fmu.compiled: %s; using Python", _me["failed"])
                    return python
                _me["loop"] = _wrap_me(_numba_me.me_loop)
    return _me["loop"] or python


def _wrap_me(compiled: Any) -> Callable[..., tuple[int, int, int, float]]:
    """Call the compiled ME loop; on a Numba typing/compile error use Python for good."""

    def loop(*args: Any) -> tuple[int, int, int, float]:
        if _me["failed"] is None:
            try:
                status, k, call, t = compiled(*args)
            except Exception as exc:  # numba.core.errors.NumbaError
                if "numba" not in type(exc).__module__:
                    raise
                _me["failed"] = f"compiling the Model Exchange loop failed: {exc}"
                warnings.warn(
                    f"tsid_fmu.fmu.compiled: {_me['failed']}; using the slower Python loop",
                    RuntimeWarning,
                    stacklevel=2,
                )
            else:
                return int(status), int(k), int(call), float(t)
        return meloop._me_loop(*args)

    loop.__name__ = "me_loop_numba"
    return loop


def _reset_for_tests() -> None:
    """Forget the compiled loops and any failure (tests switch backends)."""
    global _compiled, _failed
    _compiled = None
    _failed = None
    _me.update(loop=None, failed=None)


def _fail(*args: Any) -> int:
    return 3  # fmi2Error / fmi3Error


def warm_up() -> str:
    """Load (or compile) the compiled loops now, without touching any FMU.

    Worker processes call this while they start, so that the first simulation of a
    worker does not pay Numba's import and cache loading (which would count against
    a per-simulation time limit).  The loops are called once with stand-in function
    pointers of the FMI prototypes that return an error at once, with arguments of the
    types the session passes.

    Returns
    -------
    str
        :func:`backend` after the warm-up.
    """
    if backend() != "numba":
        return "python"
    sl = steploop
    fmi2 = (sl.FMI2_SETGET(_fail), sl.FMI2_DOSTEP(_fail), sl.FMI2_SETGET(_fail))
    fmi3 = (sl.FMI3_SETGET(_fail), sl.FMI3_DOSTEP(_fail), sl.FMI3_SETGET(_fail))
    vr = np.zeros(1, dtype=np.uint32)
    time = np.array([0.0, 1.0])
    u, held, out = np.zeros((2, 1)), np.zeros((0, 1)), np.zeros((2, 1))
    buffers = (vr, vr, u, held, out)
    derivatives = (vr, np.ones(1, dtype=np.int32), np.zeros((1, 1)))
    cs_loop(2)((*fmi2, sl.FMI2_SETDER(_fail)), 0, time, buffers, derivatives)
    cs_loop(3)(fmi3, 0, time, buffers, np.zeros(16, dtype=np.uint8))
    return backend()


class CompileNotice:
    """Call ``notify()`` once when Numba starts compiling a loop of this package.

    Loading the loops from Numba's on-disk cache does not count: only a real compile
    (the first run on a machine, or after an upgrade) does, which takes seconds.
    Listens from creation until :meth:`close`; does nothing without Numba or when
    :data:`LOOP_ENV` forces the Python loops.

    Parameters
    ----------
    notify : callable
        Called with no arguments, at most once, as the first compile starts.
    """

    def __init__(self, notify: Callable[[], None]) -> None:
        self.notify: Callable[[], None] | None = notify
        self._listener: Any = None
        if os.environ.get(LOOP_ENV, "").strip().lower() == "python" or not numba_available():
            return
        from numba.core import event

        owner = self

        class _Listener(event.Listener):  # type: ignore[misc]
            def on_start(self, ev: Any) -> None:
                func = getattr(ev.data.get("dispatcher"), "py_func", None)
                if getattr(func, "__module__", "").startswith("tsid_fmu."):
                    owner._fire()

            def on_end(self, ev: Any) -> None:
                return None

        self._listener = _Listener()
        event.register("numba:compile", self._listener)

    def _fire(self) -> None:
        notify, self.notify = self.notify, None
        if notify is not None:
            notify()

    def close(self) -> None:
        """Stop listening."""
        if self._listener is not None:
            from numba.core import event

            event.unregister("numba:compile", self._listener)
            self._listener = None
