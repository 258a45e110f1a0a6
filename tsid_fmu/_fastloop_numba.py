"""The Numba-compiled step loops used by :mod:`tsid_fmu.fastloop` (imports Numba).

Kept at module level so that Numba's on-disk cache (``cache=True``) finds them again in
every process; do not import this module directly, use :func:`tsid_fmu.fastloop.cs_loop`.
Status codes are those of :mod:`tsid_fmu.driver`: a status >= 2 (Discard) ends the loop;
the third return value names the call (1 set, 2 step, 3 get); 100 means the FMI 3.0 FMU
asked to terminate.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["loop2", "loop3"]


@intrinsic
def _ptr(typingctx: Any, addr: Any) -> Any:
    """Reinterpret an integer address as ``void*`` (no-op at run time)."""
    sig = types.voidptr(addr)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        return builder.inttoptr(args[0], ir.IntType(8).as_pointer())

    return sig, codegen


def _jit(fn: Any) -> Any:
    try:
        return njit(cache=True, nogil=True)(fn)
    except Exception:  # no writable cache location: compile in each process instead
        return njit(nogil=True)(fn)


@_jit
def loop2(
    funcs: Any,
    component: int,
    vr_in: np.ndarray,
    vr_out: np.ndarray,
    time: np.ndarray,
    inputs: np.ndarray,
    out: np.ndarray,
) -> tuple[int, int, int]:
    """FMI 2.0 loop; the contract of :func:`tsid_fmu.driver._cs_loop_fmi2`."""
    set_real, do_step, get_real = funcs
    n_in = vr_in.size
    n_out = vr_out.size
    comp = _ptr(component)
    p_vin = _ptr(vr_in.ctypes.data)
    p_vout = _ptr(vr_out.ctypes.data)
    a_in = inputs.ctypes.data
    s_in = inputs.strides[0]
    a_out = out.ctypes.data
    s_out = out.strides[0]
    n = time.size
    status = get_real(comp, p_vout, n_out, _ptr(a_out))
    if status >= 2:
        return status, 0, 3
    for k in range(n - 1):
        if n_in:
            status = set_real(comp, p_vin, n_in, _ptr(a_in + k * s_in))
            if status >= 2:
                return status, k, 1
        status = do_step(comp, time[k], time[k + 1] - time[k], 1)
        if status >= 2:
            return status, k, 2
        status = get_real(comp, p_vout, n_out, _ptr(a_out + (k + 1) * s_out))
        if status >= 2:
            return status, k + 1, 3
    return 0, n - 1, 0


@_jit
def loop3(
    funcs: Any,
    component: int,
    vr_in: np.ndarray,
    vr_out: np.ndarray,
    time: np.ndarray,
    inputs: np.ndarray,
    out: np.ndarray,
) -> tuple[int, int, int]:
    """FMI 3.0 loop; the contract of :func:`tsid_fmu.driver._cs_loop_fmi3`."""
    set_real, do_step, get_real = funcs
    n_in = vr_in.size
    n_out = vr_out.size
    comp = _ptr(component)
    p_vin = _ptr(vr_in.ctypes.data)
    p_vout = _ptr(vr_out.ctypes.data)
    a_in = inputs.ctypes.data
    s_in = inputs.strides[0]
    a_out = out.ctypes.data
    s_out = out.strides[0]
    flags = np.zeros(3, dtype=np.uint8)  # eventHandlingNeeded, terminateSimulation, early
    last = np.zeros(1, dtype=np.float64)
    a_flags = flags.ctypes.data
    p_last = _ptr(last.ctypes.data)
    n = time.size
    status = get_real(comp, p_vout, n_out, _ptr(a_out), n_out)
    if status >= 2:
        return status, 0, 3
    for k in range(n - 1):
        if n_in:
            status = set_real(comp, p_vin, n_in, _ptr(a_in + k * s_in), n_in)
            if status >= 2:
                return status, k, 1
        status = do_step(
            comp,
            time[k],
            time[k + 1] - time[k],
            True,
            _ptr(a_flags),
            _ptr(a_flags + 1),
            _ptr(a_flags + 2),
            p_last,
        )
        if status >= 2:
            return status, k, 2
        if flags[1]:
            return 100, k, 2
        status = get_real(comp, p_vout, n_out, _ptr(a_out + (k + 1) * s_out), n_out)
        if status >= 2:
            return status, k + 1, 3
    return 0, n - 1, 0
