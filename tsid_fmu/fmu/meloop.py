"""The Model Exchange integrator, written once for FMI 2.0 and 3.0.

A Model-Exchange-only FMU has no ``doStep``: the importer integrates its states.  The
loop below does this over the FMU's own functions, in the style of the Co-Simulation
loops of :mod:`tsid_fmu.fmu.steploop`: plain Python that calls the C functions through
raw function pointers and reads and writes numpy buffers by address, interpreted or
compiled by Numba (:mod:`tsid_fmu.fmu._numba_me`), with every FMI status checked.

The method
----------
- **Integrator**: the embedded Runge-Kutta pair of Cash and Karp (fifth order, error
  estimate of fourth order, six derivative evaluations a step) with step-size control
  on the weighted RMS norm of the error, tolerance ``rtol * |x| + atol * nominal`` per
  state.  Steps end on every sample time; the step carries over from one sample
  interval to the next, so a slow model takes one step per sample.
- **Inputs** are set without an event per sample: a held input once at the start of
  each sample interval, a linear one at every stage (``u_k + slope_k * (t - t_k)``).
  An input that jumps at a sample and changes the sign of an event indicator starts an
  event there (as FMPy's input events do, but only when something switches).
- **State events**: after every accepted step the event indicators are compared with
  those at its start (domains ``z > 0`` and ``z <= 0``); on a change the switching time
  is located by bisection (to ``loc_tol`` seconds) with fresh steps from the start of
  the step, the step is cut there and Event Mode is entered (``fmi2EnterEventMode``,
  ``fmi2NewDiscreteStates`` / ``fmi3UpdateDiscreteStates`` until no more is needed,
  ``EnterContinuousTimeMode``, states read back when the FMU changed them).
- **Step events** (``CompletedIntegratorStep`` asks for Event Mode) and **time events**
  (``nextEventTime``; steps are cut there) are handled the same way.

One loop serves both FMI versions: the function tuple always has both variants of
the calls that differ (``fmi2GetReal``/``fmi3GetFloat64``, ...), the FMU's own for its
version and stand-ins for the other, and ``major`` picks; so both versions share one
compiled specialisation.

Every status >= Discard ends the loop and is returned with the sample index, the call
(an index into :data:`CALL_NAMES`) and the time at which the failing call was made.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tsid_fmu.fmu.steploop import ptr, seq

__all__ = ["STATUS_EVENT_LOOP", "STATUS_STEP_SIZE", "STATUS_TERMINATE"]

DISCARD = 2
STATUS_TERMINATE = 100
"""The FMU set ``terminateSimulation``."""
STATUS_STEP_SIZE = 101
"""The step size fell below the resolution of the time."""
STATUS_EVENT_LOOP = 102
"""Event iteration did not settle within :data:`MAX_EVENT_ITERATIONS`."""
MAX_EVENT_ITERATIONS = 100

#: entries of the function tuple (see :data:`tsid_fmu.fmu.mesolver.PROTOTYPES`)
(F_TIME, F_SETX, F_DER, F_IND, F_GETX, F_NOM, F_EVENT, F_CONT) = range(8)
(F_DONE2, F_DONE3, F_DISC2, F_DISC3, F_SET2, F_GET2, F_SET3, F_GET3) = range(8, 16)
#: the failing call, the loop's third return value (see ``mesolver.CALL_NAMES``)
(CALL_TIME, CALL_SETX, CALL_DER, CALL_IND, CALL_GETX, CALL_NOM, CALL_EVENT, CALL_CONT) = range(1, 9)
CALL_DONE, CALL_DISC, CALL_SET, CALL_GET = 9, 10, 11, 12

# ctx: int64 addresses and sizes
(C_COMP, C_VIN, C_NIN, C_VOUT, C_NOUT, C_NX, C_NZ, C_MAJOR, C_LIN) = range(9)
(C_W, C_WS, C_Z, C_ZS, C_UB, C_EV, C_K) = range(9, 16)
CTX_SIZE = 16
# rows of the work array w (shape (ROWS, max(nx, 1)))
X, Y, K1, XN, XB, ATOL = 0, 1, 2, 8, 9, 10
ROWS = 11
# the arrays of the tuple arr
A_W, A_Z, A_U, A_SLOPES, A_UB, A_EV, A_EVD, A_OPTS, A_STATS = range(9)
# rows of the indicator array z (shape (3, max(nz, 1)))
ZP, ZN, ZB = 0, 1, 2
# opts (float64): settings, then the start of the current sample interval and the step
O_RTOL, O_ATOL, O_MAX_STEP, O_LOC_TOL, O_TK, O_DT, O_NEXT = range(7)
OPTS_SIZE = 7
#: counters in ``stats`` (int64): see ``mesolver.STATS``
S_STEPS, S_REJECTED, S_RHS, S_STATE, S_INPUT, S_STEP, S_TIME = range(7)
# event buffer ev (uint8, 64 bytes) and evd (its float64 view): byte offsets
E_INFO2 = 0  # fmi2EventInfo: five fmi2Boolean (int) then nextEventTime (double, evd[3])
E_DISC3 = 32  # fmi3UpdateDiscreteStates: five bools (32..36), nextEventTime at evd[5]
E_DONE = 48  # CompletedIntegratorStep: enterEventMode, terminateSimulation
EV_SIZE = 64

# Cash-Karp coefficients
_A = (
    (0.2, 0.0, 0.0, 0.0, 0.0),
    (3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0),
    (0.3, -0.9, 1.2, 0.0, 0.0),
    (-11.0 / 54.0, 2.5, -70.0 / 27.0, 35.0 / 27.0, 0.0),
    (1631.0 / 55296.0, 175.0 / 512.0, 575.0 / 13824.0, 44275.0 / 110592.0, 253.0 / 4096.0),
)
_C = (0.0, 0.2, 0.3, 0.6, 1.0, 0.875)
_B = (37.0 / 378.0, 0.0, 250.0 / 621.0, 125.0 / 594.0, 0.0, 512.0 / 1771.0)
_E = (
    37.0 / 378.0 - 2825.0 / 27648.0,
    0.0,
    250.0 / 621.0 - 18575.0 / 48384.0,
    125.0 / 594.0 - 13525.0 / 55296.0,
    -277.0 / 14336.0,
    512.0 / 1771.0 - 0.25,
)


def _flag(ev: Any, offset: int, major: int) -> bool:
    """Read an fmi2Boolean (4 bytes) or fmi3Boolean (1 byte) from the event buffer."""
    if major == 2:
        return (ev[offset] | ev[offset + 1] | ev[offset + 2] | ev[offset + 3]) != 0
    return ev[offset] != 0


def _set_inputs(funcs: Any, ctx: Any, ub: Any) -> int:
    """Set the inputs to the values in ``ub``; return the status."""
    nin = ctx[C_NIN]
    if nin == 0:
        return 0
    comp, vr, p_u = ptr(ctx[C_COMP]), ptr(ctx[C_VIN]), ptr(ctx[C_UB])
    if ctx[C_MAJOR] == 2:
        return funcs[F_SET2](comp, vr, nin, p_u)
    return funcs[F_SET3](comp, vr, nin, p_u, nin)


def _time_and_states(funcs: Any, ctx: Any, row: int, t: float) -> tuple[int, int]:
    """Set the time ``t`` and the states of row ``row`` of w; return (status, call)."""
    comp = ptr(ctx[C_COMP])
    status = funcs[F_TIME](comp, t)
    if status >= DISCARD:
        return status, CALL_TIME
    if ctx[C_NX]:
        status = funcs[F_SETX](comp, ptr(ctx[C_W] + row * ctx[C_WS]), ctx[C_NX])
        if status >= DISCARD:
            return status, CALL_SETX
    return 0, 0


def _point(funcs: Any, ctx: Any, arr: Any, row: int, t: float) -> tuple[int, int]:
    """Set the time ``t``, the states of row ``row`` of w and the linear inputs at ``t``."""
    u, slopes, ub, opts = arr[A_U], arr[A_SLOPES], arr[A_UB], arr[A_OPTS]
    status, call = _time_and_states(funcs, ctx, row, t)
    if status >= DISCARD:
        return status, call
    if ctx[C_LIN]:
        k, tk = ctx[C_K], opts[O_TK]
        for j in range(ctx[C_NIN]):
            ub[j] = u[k, j] + slopes[k, j] * (t - tk)
        status = _set_inputs(funcs, ctx, ub)
        if status >= DISCARD:
            return status, CALL_SET
    return 0, 0


def _indicators(funcs: Any, ctx: Any, zrow: int) -> int:
    """Read the event indicators at the point set last into row ``zrow`` of z."""
    if ctx[C_NZ] == 0:
        return 0
    return funcs[F_IND](ptr(ctx[C_COMP]), ptr(ctx[C_Z] + zrow * ctx[C_ZS]), ctx[C_NZ])


def _crossed(z: Any, nz: int, row: int) -> bool:
    """Return True if an indicator in row ``row`` is in another domain than in row ZP."""
    for i in range(nz):
        if (z[ZP, i] > 0.0) != (z[row, i] > 0.0):
            return True
    return False


def _copy(w: Any, nx: int, src: int, dst: int) -> None:
    for i in range(nx):
        w[dst, i] = w[src, i]


def _rk_step(funcs: Any, ctx: Any, arr: Any, t: float, dt: float) -> tuple[int, int, float]:
    """One Cash-Karp step of ``dt`` from row X at ``t`` into row XN; return the error norm."""
    w, opts, stats = arr[A_W], arr[A_OPTS], arr[A_STATS]
    nx = ctx[C_NX]
    comp = ptr(ctx[C_COMP])
    for s in range(6):
        if s:
            a = _A[s - 1]
            for i in range(nx):
                acc = 0.0
                for j in range(s):
                    acc += a[j] * w[K1 + j, i]
                w[Y, i] = w[X, i] + dt * acc
        status, call = _point(funcs, ctx, arr, Y if s else X, t + _C[s] * dt)
        if status >= DISCARD:
            return status, call, 0.0
        status = funcs[F_DER](comp, ptr(ctx[C_W] + (K1 + s) * ctx[C_WS]), nx)
        stats[S_RHS] += 1
        if status >= DISCARD:
            return status, CALL_DER, 0.0
    total = 0.0
    for i in range(nx):
        acc, err = 0.0, 0.0
        for j in range(6):
            acc += _B[j] * w[K1 + j, i]
            err += _E[j] * w[K1 + j, i]
        w[XN, i] = w[X, i] + dt * acc
        scale = w[ATOL, i] + opts[O_RTOL] * max(abs(w[X, i]), abs(w[XN, i]))
        total += (dt * err / scale) ** 2
    return 0, 0, (total / nx) ** 0.5 if nx else 0.0


def _discrete(funcs: Any, ctx: Any, ev: Any, evd: Any) -> tuple[int, int, float]:
    """One fmi2NewDiscreteStates / fmi3UpdateDiscreteStates; (status, flag offset, time)."""
    comp, a = ptr(ctx[C_COMP]), ctx[C_EV]
    if ctx[C_MAJOR] == 2:
        return funcs[F_DISC2](comp, ptr(a + E_INFO2)), E_INFO2, evd[3]
    status = funcs[F_DISC3](
        comp,
        ptr(a + E_DISC3),
        ptr(a + E_DISC3 + 1),
        ptr(a + E_DISC3 + 2),
        ptr(a + E_DISC3 + 3),
        ptr(a + E_DISC3 + 4),
        ptr(a + 40),
    )
    return status, E_DISC3, evd[5]


def _event(funcs: Any, ctx: Any, arr: Any, enter: bool) -> tuple[int, int]:
    """Event Mode: iterate the discrete states, back to Continuous-Time Mode.

    Reads the states back if the FMU changed them, and the indicators into row ZP;
    the next time event (or inf) goes into ``opts[O_NEXT]``.
    """
    ev, evd, opts = arr[A_EV], arr[A_EVD], arr[A_OPTS]
    comp, major = ptr(ctx[C_COMP]), ctx[C_MAJOR]
    if enter:
        status = funcs[F_EVENT](comp)
        if status >= DISCARD:
            return status, CALL_EVENT
    size = 4 if major == 2 else 1
    changed, settled = False, False
    for _ in range(MAX_EVENT_ITERATIONS):
        status, off, when = _discrete(funcs, ctx, ev, evd)
        if status >= DISCARD:
            return status, CALL_DISC
        if _flag(ev, off + size, major):
            return STATUS_TERMINATE, CALL_DISC
        changed = changed or _flag(ev, off + 3 * size, major)
        opts[O_NEXT] = when if _flag(ev, off + 4 * size, major) else np.inf
        if not _flag(ev, off, major):
            settled = True
            break
    if not settled:
        return STATUS_EVENT_LOOP, CALL_DISC
    status = funcs[F_CONT](comp)
    if status >= DISCARD:
        return status, CALL_CONT
    if changed and ctx[C_NX]:
        status = funcs[F_GETX](comp, ptr(ctx[C_W] + X * ctx[C_WS]), ctx[C_NX])
        if status >= DISCARD:
            return status, CALL_GETX
    return _indicators(funcs, ctx, ZP), CALL_IND


def _completed(funcs: Any, ctx: Any, ev: Any) -> tuple[int, int, bool]:
    """CompletedIntegratorStep; (status, call, enter Event Mode?)."""
    comp, a, major = ptr(ctx[C_COMP]), ctx[C_EV], ctx[C_MAJOR]
    if major == 2:
        status = funcs[F_DONE2](comp, 1, ptr(a + E_DONE), ptr(a + E_DONE + 4))
        size = 4
    else:
        status = funcs[F_DONE3](comp, True, ptr(a + E_DONE), ptr(a + E_DONE + 1))
        size = 1
    if status >= DISCARD:
        return status, CALL_DONE, False
    if _flag(ev, E_DONE + size, major):
        return STATUS_TERMINATE, CALL_DONE, False
    return 0, 0, _flag(ev, E_DONE, major)


def _locate(funcs: Any, ctx: Any, arr: Any, t: float, dt: float) -> tuple[int, int, float]:
    """Bisect the step ``t -> t + dt`` for the first change of an indicator's domain.

    Row XN and z row ZN hold the end of the step (where an indicator has changed).
    Returns the length ``tau`` of the step to the switch: within ``opts[O_LOC_TOL]``
    after it; row XB holds the state there.
    """
    w, z, opts = arr[A_W], arr[A_Z], arr[A_OPTS]
    nx, nz = ctx[C_NX], ctx[C_NZ]
    _copy(w, nx, XN, XB)
    lo, hi = 0.0, dt
    while hi - lo > opts[O_LOC_TOL]:
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        status, call, _err = _rk_step(funcs, ctx, arr, t, mid)
        if status >= DISCARD:
            return status, call, 0.0
        status, call = _point(funcs, ctx, arr, XN, t + mid)
        if status >= DISCARD:
            return status, call, 0.0
        status = _indicators(funcs, ctx, ZB)
        if status >= DISCARD:
            return status, CALL_IND, 0.0
        if _crossed(z, nz, ZB):
            hi = mid
            _copy(w, nx, XN, XB)
        else:
            lo = mid
    return 0, 0, hi


def _trial(funcs: Any, ctx: Any, arr: Any, t: float, limit: float) -> tuple[int, int, float]:
    """Take one accepted step from ``t`` towards ``limit`` into row XN; return its length.

    The step is the carried step ``opts[O_DT]`` (at most ``opts[O_MAX_STEP]``), cut to
    end exactly on ``limit``; rejected steps shrink it.
    """
    opts, stats = arr[A_OPTS], arr[A_STATS]
    while True:
        dt = min(opts[O_DT], opts[O_MAX_STEP])
        last = limit - t <= dt * (1.0 + 1e-9)
        if last:
            dt = limit - t
        if dt <= 1e-15 * max(1.0, abs(t)):
            return STATUS_STEP_SIZE, 0, 0.0
        status, call, err = _rk_step(funcs, ctx, arr, t, dt)
        if status >= DISCARD:
            return status, call, 0.0
        fac = 5.0 if err < 1e-10 else min(5.0, max(0.2, 0.9 * err**-0.2))
        if err <= 1.0:
            stats[S_STEPS] += 1
            # a step shortened to end on the limit does not shorten the next one
            if not (last and fac >= 1.0 and dt * fac < opts[O_DT]):
                opts[O_DT] = min(dt * fac, opts[O_MAX_STEP])
            return 0, 0, dt
        stats[S_REJECTED] += 1
        opts[O_DT] = dt * fac


def _step(funcs: Any, ctx: Any, arr: Any, t: float, t_end: float) -> tuple[int, int, float]:
    """Integrate from ``t`` by one step towards ``t_end``; handle events; return the new time."""
    w, z, ev, opts, stats = arr[A_W], arr[A_Z], arr[A_EV], arr[A_OPTS], arr[A_STATS]
    nx, nz = ctx[C_NX], ctx[C_NZ]
    t_event = opts[O_NEXT]
    limit = t_end if not t < t_event < t_end else t_event
    status, call, dt = _trial(funcs, ctx, arr, t, limit)
    if status >= DISCARD:
        return status, call, t
    t_new = limit if t + dt >= limit else t + dt
    status, call = _point(funcs, ctx, arr, XN, t_new)
    if status >= DISCARD:
        return status, call, t_new
    status = _indicators(funcs, ctx, ZN)
    if status >= DISCARD:
        return status, CALL_IND, t_new
    event = False
    if nz and _crossed(z, nz, ZN):
        status, call, tau = _locate(funcs, ctx, arr, t, dt)
        if status >= DISCARD:
            return status, call, t
        if tau < dt:
            t_new = t + tau
        status, call = _point(funcs, ctx, arr, XB, t_new)
        if status >= DISCARD:
            return status, call, t_new
        _copy(w, nx, XB, X)
        stats[S_STATE] += 1
        event = True
    else:
        _copy(w, nx, XN, X)
        for i in range(nz):
            z[ZP, i] = z[ZN, i]
    status, call, enter = _completed(funcs, ctx, ev)
    if status >= DISCARD:
        return status, call, t_new
    if not event and enter:
        stats[S_STEP] += 1
        event = True
    elif not event and t_new == t_event:
        stats[S_TIME] += 1
        event = True
    if event:
        status, call = _event(funcs, ctx, arr, True)
        if status >= DISCARD:
            return status, call, t_new
    return 0, 0, t_new


def _boundary(funcs: Any, ctx: Any, arr: Any, out: Any, k: int, t: float) -> tuple[int, int]:
    """At sample ``k`` (time ``t``): set its inputs, handle a switch they cause, record."""
    z, u, ub, stats = arr[A_Z], arr[A_U], arr[A_UB], arr[A_STATS]
    status, call = _time_and_states(funcs, ctx, X, t)
    if status >= DISCARD:
        return status, call
    for j in range(ctx[C_NIN]):
        ub[j] = u[k, j]
    status = _set_inputs(funcs, ctx, ub)
    if status >= DISCARD:
        return status, CALL_SET
    status = _indicators(funcs, ctx, ZN)
    if status >= DISCARD:
        return status, CALL_IND
    if ctx[C_NZ] and _crossed(z, ctx[C_NZ], ZN):
        stats[S_INPUT] += 1
        status, call = _event(funcs, ctx, arr, True)
        if status >= DISCARD:
            return status, call
    comp, p_out = ptr(ctx[C_COMP]), ptr(out.ctypes.data + k * out.strides[0])
    n_out = ctx[C_NOUT]
    if ctx[C_MAJOR] == 2:
        status = funcs[F_GET2](comp, ptr(ctx[C_VOUT]), n_out, p_out)
    else:
        status = funcs[F_GET3](comp, ptr(ctx[C_VOUT]), n_out, p_out, n_out)
    return (status, CALL_GET) if status >= DISCARD else (0, 0)


def _start(funcs: Any, ctx: Any, arr: Any, out: Any, t0: float) -> tuple[int, int]:
    """After initialization (in Event Mode): settle, read states and nominals, record row 0."""
    w, opts = arr[A_W], arr[A_OPTS]
    comp, nx = ptr(ctx[C_COMP]), ctx[C_NX]
    status, call = _event(funcs, ctx, arr, False)
    if status >= DISCARD:
        return status, call
    if nx:
        status = funcs[F_GETX](comp, ptr(ctx[C_W] + X * ctx[C_WS]), nx)
        if status >= DISCARD:
            return status, CALL_GETX
        status = funcs[F_NOM](comp, ptr(ctx[C_W] + ATOL * ctx[C_WS]), nx)
        if status >= DISCARD:
            return status, CALL_NOM
        for i in range(nx):
            nominal = abs(w[ATOL, i])
            w[ATOL, i] = opts[O_ATOL] * (nominal if nominal > 0.0 else 1.0)
    # the inputs of t0 were set during initialization; record like any sample
    return _boundary(funcs, ctx, arr, out, 0, t0)


def _me_loop(
    funcs: Any, ctx: np.ndarray, time: np.ndarray, arr: Any, out: np.ndarray
) -> tuple[int, int, int, float]:
    """Integrate an initialized Model Exchange instance along ``time``.

    Parameters
    ----------
    funcs : tuple
        The 16 raw function pointers of :data:`PROTOTYPES` (stand-ins for the calls of
        the other FMI version).
    ctx : numpy.ndarray
        ``int64`` addresses and sizes, indexed by the ``C_*`` constants (``C_K`` is
        written by the loop).
    time : numpy.ndarray
        Sample times, ``float64``, shape ``(n,)``.
    arr : tuple
        ``(w, z, u, slopes, ub, ev, evd, opts, stats)``: work rows of the states,
        indicator rows, inputs ``(n, n_in)`` and their slopes per interval
        ``(n - 1, n_in)`` (zero for held inputs), the input buffer, the event buffer
        (``uint8``) and its ``float64`` view, the settings and the counters.
    out : numpy.ndarray
        ``(n, n_out)`` outputs, filled in place (row ``k`` at ``time[k]``, after the
        inputs of ``time[k]`` are set and any event they cause is handled).

    Returns
    -------
    status : int
        0 on success, the failing FMI status (>= Discard), or one of
        :data:`STATUS_TERMINATE`, :data:`STATUS_STEP_SIZE`, :data:`STATUS_EVENT_LOOP`.
    index : int
        The sample interval in which it failed (``n - 1`` on success).
    call : int
        Index into ``CALL_NAMES[major]`` of the failing call (0 on success).
    t : float
        The time of the failing call.
    """
    opts = arr[A_OPTS]
    ctx = seq(ctx)  # a list of ints in Python: ctypes takes no numpy integers
    t = seq(time)
    n = len(t)
    status, call = _start(funcs, ctx, arr, out, t[0])
    if status >= DISCARD:
        return status, 0, call, t[0]
    for k in range(n - 1):
        ctx[C_K] = k
        opts[O_TK] = t[k]
        tc = t[k]
        while tc < t[k + 1]:
            status, call, tc = _step(funcs, ctx, arr, tc, t[k + 1])
            if status >= DISCARD:
                return status, k, call, tc
        status, call = _boundary(funcs, ctx, arr, out, k + 1, t[k + 1])
        if status >= DISCARD:
            return status, k + 1, call, t[k + 1]
    return 0, n - 1, 0, t[n - 1]
