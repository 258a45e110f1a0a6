"""Native-speed Co-Simulation step loops (Numba), with the Python loops as fallback.

The hot path of a study is the per-step *set inputs / do step / get outputs* loop of
:class:`~tsid_fmu.driver.FMUSession`.  In Python each step costs three ctypes calls
through the interpreter (a few microseconds); here the same loop is compiled by Numba
to machine code that calls the FMU's C functions directly through their raw function
pointers, so a step costs what the FMU itself costs.

The compiled loops keep the contract of :func:`tsid_fmu.driver._cs_loop_fmi2` and
:func:`tsid_fmu.driver._cs_loop_fmi3` exactly -- same arguments, same ``(status, step,
call)`` return, every FMI status checked -- so the session reports a failure naming the
FMI call, the step and the time whichever loop ran.

Numba is optional (``pip install tsid-fmu[fast]``).  Without it, or when the environment
variable ``TSID_FMU_LOOP=python`` is set, or if compiling fails, :func:`cs_loop` returns
the Python loops of :mod:`tsid_fmu.driver`.  Compiled code is cached on disk (Numba's
``cache=True``), so only the first process on a machine pays the compile time (about a
second); worker processes load it from the cache.

Model Exchange FMUs are integrated by FMPy and never use these loops.
"""

from __future__ import annotations

import logging
import os
import threading
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["LOOP_ENV", "backend", "cs_loop", "numba_available", "warm_up"]

LOOP_ENV = "TSID_FMU_LOOP"
"""Environment variable: ``python`` forces the Python loops, ``numba`` (default) the compiled."""

_log = logging.getLogger(__name__)
_lock = threading.Lock()
_compiled: dict[int, Callable[..., tuple[int, int, int]]] | None = None
_failed: str | None = None  # why the compiled loops are unavailable, once known

Loop = Callable[..., tuple[int, int, int]]


def numba_available() -> bool:
    """Return True if Numba can be imported."""
    try:
        import numba  # noqa: F401
    except Exception:  # ImportError, or a broken install (e.g. a NumPy it does not support)
        return False
    return True


def _build() -> dict[int, Loop]:
    """Import (compile on first call, or load from Numba's cache) the compiled loops."""
    from tsid_fmu import _fastloop_numba as nb

    return {2: nb.loop2, 3: nb.loop3}


def _wrap(compiled: Loop, fallback: Loop, major: int) -> Loop:
    """Call the compiled loop; on a Numba typing/compile error use ``fallback`` for good."""

    def loop(
        funcs: tuple[Any, Any, Any],
        component: Any,
        vr_in: np.ndarray,
        vr_out: np.ndarray,
        time: np.ndarray,
        inputs: np.ndarray,
        out: np.ndarray,
    ) -> tuple[int, int, int]:
        global _failed
        if _failed is None:
            address = int(getattr(component, "value", component) or 0)
            try:
                status, k, call = compiled(funcs, address, vr_in, vr_out, time, inputs, out)
            except Exception as exc:  # numba.core.errors.NumbaError: compile/typing failed
                if "numba" not in type(exc).__module__:
                    raise
                _failed = f"compiling the FMI {major} loop failed: {exc}"
                warnings.warn(
                    f"tsid_fmu.fastloop: {_failed}; using the slower Python loop",
                    RuntimeWarning,
                    stacklevel=2,
                )
            else:
                return int(status), int(k), int(call)
        return fallback(funcs, component, vr_in, vr_out, time, inputs, out)

    loop.__name__ = f"cs_loop_fmi{major}_numba"
    loop.__doc__ = f"Numba-compiled FMI {major} step loop (see tsid_fmu.driver)."
    return loop


def _python_loops() -> dict[int, Loop]:
    from tsid_fmu.driver import _cs_loop_fmi2, _cs_loop_fmi3

    return {2: _cs_loop_fmi2, 3: _cs_loop_fmi3}


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
                _log.info("tsid_fmu.fastloop: %s; using the Python loop", _failed)
                return None
            try:
                built = _build()
            except Exception as exc:  # a Numba/llvmlite that cannot build the loops
                _failed = f"Numba cannot build the loops: {exc}"
                _log.warning("tsid_fmu.fastloop: %s; using the Python loop", _failed)
                return None
            python = _python_loops()
            _compiled = {m: _wrap(built[m], python[m], m) for m in (2, 3)}
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
        ``loop(funcs, component, vr_in, vr_out, time, inputs, out) -> (status, step,
        call)`` with the contract of :func:`tsid_fmu.driver._cs_loop_fmi2`: the
        Numba-compiled loop when available, else the Python loop.
    """
    loops = _loops()
    if loops is None or _failed is not None:
        return _python_loops()[major]
    return loops[major]


def backend() -> str:
    """Return ``"numba"`` if :func:`cs_loop` gives compiled loops, else ``"python"``.

    The answer triggers compilation on first use; the reason for ``"python"`` is
    logged (``logging.getLogger("tsid_fmu.fastloop")``).
    """
    return "numba" if _loops() is not None and _failed is None else "python"


def _reset_for_tests() -> None:
    """Forget the compiled loops and any failure (tests switch backends)."""
    global _compiled, _failed
    _compiled = None
    _failed = None


def warm_up() -> str:
    """Load (or compile) the compiled loops now, without touching any FMU.

    Worker processes call this while they start, so that the first simulation of a
    worker does not pay Numba's import and cache loading (which would count against
    a per-simulation time limit).  The loops are called once with stand-in function
    pointers of the FMI prototypes that return ``fmi2Error`` at once.

    Returns
    -------
    str
        :func:`backend` after the warm-up.
    """
    if backend() != "numba":
        return "python"
    from tsid_fmu import driver

    def fail(*args: Any) -> int:
        return 3

    dummies = {
        2: (driver._FMI2_SETGET(fail), driver._FMI2_DOSTEP(fail), driver._FMI2_SETGET(fail)),
        3: (driver._FMI3_SETGET(fail), driver._FMI3_DOSTEP(fail), driver._FMI3_SETGET(fail)),
    }
    vr = np.zeros(1, dtype=np.uint32)
    time = np.array([0.0, 1.0])
    for major, funcs in dummies.items():
        cs_loop(major)(funcs, 0, vr, vr, time, np.zeros((2, 1)), np.zeros((2, 1)))
    return backend()
