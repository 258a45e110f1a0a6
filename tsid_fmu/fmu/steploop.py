"""The Co-Simulation step loops, written once per FMI version.

The hot path of a study is the per-step loop of :class:`~tsid_fmu.fmu.FMUSession`.  Each
loop below is plain Python that calls the FMU's C functions through raw function
pointers and reads and writes numpy buffers by address.  The *same* function runs in
two ways:

- **interpreted**: :func:`ptr` is the identity and :func:`seq` turns the time array
  into a list, so the calls go through :mod:`ctypes` (a few microseconds per step);
- **compiled**: :mod:`tsid_fmu.fmu._numba` gives :func:`ptr` and :func:`seq` Numba
  implementations (an integer-to-``void*`` cast and the array itself) and compiles
  these very functions with ``njit(cache=True)``, so a step costs what the FMU costs.

:mod:`tsid_fmu.fmu.compiled` picks the mode.  Both modes make the same FMI calls in the
same order and return the same ``(status, step, call)`` triple.

Order of the calls (the FMI Co-Simulation order, so that an output with direct
feed-through sees the input of its own time):

- before the loop the inputs of ``t_0`` are set (during initialization, by the session)
  and the outputs of ``t_0`` are read into row 0;
- step ``k``: [inputs held over the step given apart: set them], [FMI 2.0, inputs
  interpolated by the FMU: set the input derivatives for ``t_k -> t_{k+1}``],
  ``doStep(t_k, t_{k+1} - t_k)``, set the inputs of ``t_{k+1}``, get the outputs of
  ``t_{k+1}`` into row ``k + 1``.

Every status is checked: a status >= Discard ends the loop and is returned with the
step index at which the failing call was made and the call's index into
:data:`CALL_NAMES`.
"""

from __future__ import annotations

import ctypes
from ctypes import CFUNCTYPE, c_bool, c_double, c_int, c_size_t, c_void_p
from typing import Any

import numpy as np

__all__ = [
    "CALL_DER",
    "CALL_GET",
    "CALL_NAMES",
    "CALL_SET",
    "CALL_STEP",
    "FMI2_DOSTEP",
    "FMI2_SETDER",
    "FMI2_SETGET",
    "FMI3_DOSTEP",
    "FMI3_SETGET",
    "STATUS_TERMINATE",
    "ptr",
    "raw",
    "seq",
]

#: lowest failing FMI status (fmi2Discard / fmi3Discard)
DISCARD = 2
#: status the FMI 3.0 loop reports when the FMU sets ``terminateSimulation``
STATUS_TERMINATE = 100
#: index of the failing call, the loops' third return value
CALL_SET, CALL_STEP, CALL_GET, CALL_DER = 1, 2, 3, 4
#: names of the calls by FMI major version and call index
CALL_NAMES = {
    2: ("", "fmi2SetReal", "fmi2DoStep", "fmi2GetReal", "fmi2SetRealInputDerivatives"),
    3: ("", "fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64", ""),
}

# C prototypes of the functions the loops call; every pointer argument is an address
FMI2_SETGET = CFUNCTYPE(c_int, c_void_p, c_void_p, c_size_t, c_void_p)
FMI2_DOSTEP = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_int)
FMI2_SETDER = CFUNCTYPE(c_int, c_void_p, c_void_p, c_size_t, c_void_p, c_void_p)
FMI3_SETGET = CFUNCTYPE(c_int, c_void_p, c_void_p, c_size_t, c_void_p, c_size_t)
FMI3_DOSTEP = CFUNCTYPE(
    c_int, c_void_p, c_double, c_double, c_bool, c_void_p, c_void_p, c_void_p, c_void_p
)


def raw(dll: ctypes.CDLL, name: str, prototype: Any) -> Any:
    """Return ``dll.<name>`` as a function pointer of ``prototype`` (address arguments)."""
    return prototype(ctypes.cast(getattr(dll, name), c_void_p).value)


def ptr(address: int) -> int:
    """Return ``address`` as the pointer argument of a C call.

    The identity in Python (ctypes converts the integer); compiled by Numba, a cast of
    the integer to ``void*`` (see :mod:`tsid_fmu.fmu._numba`).
    """
    return address


def seq(values: np.ndarray) -> Any:
    """Return the time points in the fastest form to index one by one.

    A list in Python (indexing a list is several times faster than indexing an
    array); compiled by Numba, the array itself.
    """
    return values.tolist()


Buffers = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""``(vr_in, vr_out, inputs, held, out)``, the buffers both loops read and fill.

vr_in, vr_out : C-contiguous ``uint32`` value references of the inputs and outputs.
inputs : C-contiguous ``float64``, shape ``(n, len(vr_in))``; row ``k + 1`` is set after
    the step to ``time[k + 1]`` (row 0 is set by the caller during initialization).
held : C-contiguous ``float64``, shape ``(n - 1, len(vr_in))``: row ``k`` is set just
    before step ``k`` and held over it (after the outputs of ``time[k]`` were read with
    ``inputs[k]``); or no rows, when each step holds ``inputs[k]``.
out : C-contiguous ``float64``, shape ``(n, len(vr_out))``, filled in place: row 0 right
    away, row ``k + 1`` after step ``k`` and the inputs of ``time[k + 1]``.
"""


def _addresses(buffers: Buffers) -> tuple[int, ...]:
    """Return what the loops need of ``buffers``, once per run.

    ``(n_in, n_out, a_vin, a_vout, a_in, s_in, n_held, a_held, s_held, a_out, s_out)``:
    the numbers of inputs and outputs, the addresses (``a_``) of the buffers, the row
    strides (``s_``) of the tables, and the number of held values (0: no held rows).
    """
    vr_in, vr_out, inputs, held, out = buffers
    n_in = vr_in.size
    return (
        n_in,
        vr_out.size,
        vr_in.ctypes.data,
        vr_out.ctypes.data,
        inputs.ctypes.data,
        inputs.strides[0],
        held.shape[0] * n_in,
        held.ctypes.data,
        held.strides[0],
        out.ctypes.data,
        out.strides[0],
    )


def _cs_loop_fmi2(
    funcs: tuple[Any, Any, Any, Any],
    component: int,
    time: np.ndarray,
    buffers: Buffers,
    derivatives: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[int, int, int]:
    """Step an initialized FMI 2.0 Co-Simulation instance along ``time``.

    Parameters
    ----------
    funcs : tuple
        Raw ``(fmi2SetReal, fmi2DoStep, fmi2GetReal, fmi2SetRealInputDerivatives)``
        function pointers taking addresses (see :func:`raw`).
    component : int
        The ``fmi2Component`` address.
    time : numpy.ndarray
        Communication points, ``float64``, shape ``(n,)``.
    buffers : Buffers
        The inputs, the outputs and their value references (see :data:`Buffers`).
    derivatives : tuple of numpy.ndarray
        ``(vr_der, order, slopes)``: inputs the FMU interpolates (``uint32``, may be
        empty), ``int32`` ones (at least one), and their derivatives for each step,
        ``float64`` of shape ``(n - 1, len(vr_der))``, set before step ``k``.

    Returns
    -------
    status : int
        0 on success, else the failing FMI status (>= Discard).
    index : int
        The step index at which the failing call was made (``n - 1`` on success).
    call : int
        Index into ``CALL_NAMES[2]`` of the failing call (0 on success).
    """
    set_real, do_step, get_real, set_der = funcs
    vr_der, order, slopes = derivatives
    t = seq(time)
    n = len(t)
    n_in, n_out, a_vin, a_vout, a_in, s_in, n_held, a_held, s_held, a_out, s_out = _addresses(
        buffers
    )
    n_der = vr_der.size
    comp, p_vin, p_vout = ptr(component), ptr(a_vin), ptr(a_vout)
    p_vder, p_order = ptr(vr_der.ctypes.data), ptr(order.ctypes.data)
    a_der, s_der = slopes.ctypes.data, slopes.strides[0]
    status = get_real(comp, p_vout, n_out, ptr(a_out))
    if status >= DISCARD:
        return status, 0, CALL_GET
    for k in range(n - 1):
        if n_held:
            status = set_real(comp, p_vin, n_in, ptr(a_held + k * s_held))
            if status >= DISCARD:
                return status, k, CALL_SET
        if n_der:
            status = set_der(comp, p_vder, n_der, p_order, ptr(a_der + k * s_der))
            if status >= DISCARD:
                return status, k, CALL_DER
        status = do_step(comp, t[k], t[k + 1] - t[k], 1)
        if status >= DISCARD:
            return status, k, CALL_STEP
        if n_in:
            status = set_real(comp, p_vin, n_in, ptr(a_in + (k + 1) * s_in))
            if status >= DISCARD:
                return status, k + 1, CALL_SET
        status = get_real(comp, p_vout, n_out, ptr(a_out + (k + 1) * s_out))
        if status >= DISCARD:
            return status, k + 1, CALL_GET
    return 0, n - 1, 0


def _cs_loop_fmi3(
    funcs: tuple[Any, Any, Any],
    component: int,
    time: np.ndarray,
    buffers: Buffers,
    flags: np.ndarray,
) -> tuple[int, int, int]:
    """Step an initialized FMI 3.0 Co-Simulation instance along ``time``.

    Same contract as :func:`_cs_loop_fmi2` with ``(fmi3SetFloat64, fmi3DoStep,
    fmi3GetFloat64)``, without input derivatives.  ``flags`` is a ``uint8`` buffer of at
    least 16 bytes that receives ``fmi3DoStep``'s output arguments
    (``eventHandlingNeeded``, ``terminateSimulation``, ``earlyReturn`` in bytes 0-2,
    ``lastSuccessfulTime`` in bytes 8-15).  A step that sets ``terminateSimulation``
    ends the loop with status :data:`STATUS_TERMINATE`.
    """
    set_real, do_step, get_real = funcs
    t = seq(time)
    n = len(t)
    n_in, n_out, a_vin, a_vout, a_in, s_in, n_held, a_held, s_held, a_out, s_out = _addresses(
        buffers
    )
    comp, p_vin, p_vout = ptr(component), ptr(a_vin), ptr(a_vout)
    a_flags = flags.ctypes.data
    p_event, p_term = ptr(a_flags), ptr(a_flags + 1)
    p_early, p_last = ptr(a_flags + 2), ptr(a_flags + 8)
    status = get_real(comp, p_vout, n_out, ptr(a_out), n_out)
    if status >= DISCARD:
        return status, 0, CALL_GET
    for k in range(n - 1):
        if n_held:
            status = set_real(comp, p_vin, n_in, ptr(a_held + k * s_held), n_in)
            if status >= DISCARD:
                return status, k, CALL_SET
        status = do_step(comp, t[k], t[k + 1] - t[k], True, p_event, p_term, p_early, p_last)
        if status >= DISCARD:
            return status, k, CALL_STEP
        if flags[1]:
            return STATUS_TERMINATE, k, CALL_STEP
        if n_in:
            status = set_real(comp, p_vin, n_in, ptr(a_in + (k + 1) * s_in), n_in)
            if status >= DISCARD:
                return status, k + 1, CALL_SET
        status = get_real(comp, p_vout, n_out, ptr(a_out + (k + 1) * s_out), n_out)
        if status >= DISCARD:
            return status, k + 1, CALL_GET
    return 0, n - 1, 0
