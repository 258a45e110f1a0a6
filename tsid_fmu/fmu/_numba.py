"""Compile the step loops of :mod:`tsid_fmu.fmu.steploop` with Numba (imports Numba).

Nothing here is a second copy of a loop: the two helpers the loops use,
:func:`~tsid_fmu.fmu.steploop.ptr` and :func:`~tsid_fmu.fmu.steploop.seq`, get Numba
implementations (``@overload``), their shared set-up ``_addresses`` is registered as
jitable (``register_jitable``: it stays a plain Python function that compiled code can
call), and the loop functions themselves are handed to ``njit``.  Numba's on-disk
cache (``cache=True``) keys the compiled code on ``steploop.py``, so every process
after the first loads it instead of compiling.

Do not import this module directly; :mod:`tsid_fmu.fmu.compiled` does, when Numba is
installed and wanted.
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic, overload, register_jitable

import tsid_fmu.fmu.steploop as steploop

__all__ = ["loop2", "loop3"]


@intrinsic
def _inttoptr(typingctx: Any, address: Any) -> Any:
    """Reinterpret an integer address as ``void*`` (no instruction at run time)."""
    if not isinstance(address, types.Integer):
        return None
    sig = types.voidptr(address)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.inttoptr(args[0], ir.IntType(8).as_pointer())

    return sig, codegen


@overload(steploop.ptr, jit_options={"nogil": True})
def _ptr(address: Any) -> Any:
    if isinstance(address, types.Integer):

        def impl(address: Any) -> Any:
            return _inttoptr(address)

        return impl
    return None


@overload(steploop.seq, jit_options={"nogil": True})
def _seq(values: Any) -> Any:
    if isinstance(values, types.Array):

        def impl(values: Any) -> Any:
            return values

        return impl
    return None


def _jit(fn: Any) -> Any:
    try:
        return njit(cache=True, nogil=True)(fn)
    except Exception:  # no writable cache location: compile in each process instead
        return njit(nogil=True)(fn)


register_jitable(steploop._addresses)
loop2 = _jit(steploop._cs_loop_fmi2)
loop3 = _jit(steploop._cs_loop_fmi3)
