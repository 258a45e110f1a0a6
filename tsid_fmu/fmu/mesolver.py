"""Model Exchange runs on the project's own integrator (:mod:`tsid_fmu.fmu.meloop`).

:class:`MESolver` finds the FMU's Model Exchange functions once, keeps the work
buffers of the loop, and runs it (compiled by Numba when available, see
:func:`tsid_fmu.fmu.compiled.me_loop`) on an initialized instance.  FMPy's CVode
remains available to the session as ``me_solver="cvode"``
(:mod:`tsid_fmu.fmu.exchange`).

Settings
--------
``rtol`` (default :data:`DEFAULT_RTOL`) and ``atol`` (default :data:`DEFAULT_ATOL`,
times each state's nominal value) bound the local error of each step; ``max_step``
(the session's ``step_size``) bounds the step; switching times are located to
:data:`LOCATION_TOLERANCE` seconds.
"""

from __future__ import annotations

import ctypes
import math
from ctypes import CFUNCTYPE, c_bool, c_double, c_int, c_size_t, c_void_p
from typing import Any

import numpy as np

import tsid_fmu.fmu.meloop as meloop
from tsid_fmu.errors import FMUError, SimulationError
from tsid_fmu.fmu.compiled import me_loop
from tsid_fmu.fmu.instance import CallFailed
from tsid_fmu.fmu.steploop import FMI2_SETGET, FMI3_SETGET, raw

__all__ = [
    "CALL_NAMES",
    "DEFAULT_ATOL",
    "DEFAULT_RTOL",
    "LOCATION_TOLERANCE",
    "PROTOTYPES",
    "STATS",
    "MESolver",
    "me_functions",
]

DEFAULT_RTOL = 1e-8
"""Relative tolerance of the local error of a step."""
DEFAULT_ATOL = 1e-10
"""Absolute tolerance, multiplied by each state's nominal value."""
LOCATION_TOLERANCE = 1e-12
"""Bisection of a switching time stops when it is known to within this many seconds."""

# prototypes: every pointer argument is an address
_TIME = CFUNCTYPE(c_int, c_void_p, c_double)
_ARRAY = CFUNCTYPE(c_int, c_void_p, c_void_p, c_size_t)
_MODE = CFUNCTYPE(c_int, c_void_p)
_DONE2 = CFUNCTYPE(c_int, c_void_p, c_int, c_void_p, c_void_p)
_DONE3 = CFUNCTYPE(c_int, c_void_p, c_bool, c_void_p, c_void_p)
_DISC2 = CFUNCTYPE(c_int, c_void_p, c_void_p)
_DISC3 = CFUNCTYPE(c_int, *([c_void_p] * 7))

#: (FMI 2.0 name, FMI 3.0 name, prototype) of each entry of the loop's function tuple;
#: an empty name: a stand-in for the other version (never called)
PROTOTYPES: tuple[tuple[str, str, Any], ...] = (
    ("fmi2SetTime", "fmi3SetTime", _TIME),
    ("fmi2SetContinuousStates", "fmi3SetContinuousStates", _ARRAY),
    ("fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives", _ARRAY),
    ("fmi2GetEventIndicators", "fmi3GetEventIndicators", _ARRAY),
    ("fmi2GetContinuousStates", "fmi3GetContinuousStates", _ARRAY),
    ("fmi2GetNominalsOfContinuousStates", "fmi3GetNominalsOfContinuousStates", _ARRAY),
    ("fmi2EnterEventMode", "fmi3EnterEventMode", _MODE),
    ("fmi2EnterContinuousTimeMode", "fmi3EnterContinuousTimeMode", _MODE),
    ("fmi2CompletedIntegratorStep", "", _DONE2),
    ("", "fmi3CompletedIntegratorStep", _DONE3),
    ("fmi2NewDiscreteStates", "", _DISC2),
    ("", "fmi3UpdateDiscreteStates", _DISC3),
    ("fmi2SetReal", "", FMI2_SETGET),
    ("fmi2GetReal", "", FMI2_SETGET),
    ("", "fmi3SetFloat64", FMI3_SETGET),
    ("", "fmi3GetFloat64", FMI3_SETGET),
)

#: names of the calls by FMI major version, indexed by the loop's ``call`` result
CALL_NAMES = {
    m: (
        "",
        *(p[m - 2] for p in PROTOTYPES[:8]),
        f"fmi{m}CompletedIntegratorStep",
        "fmi2NewDiscreteStates" if m == 2 else "fmi3UpdateDiscreteStates",
        "fmi2SetReal" if m == 2 else "fmi3SetFloat64",
        "fmi2GetReal" if m == 2 else "fmi3GetFloat64",
    )
    for m in (2, 3)
}

#: the counters of :attr:`MESolver.stats`, in the order of the loop's ``stats`` array
STATS = (
    "steps",
    "rejected",
    "derivatives",
    "state_events",
    "input_events",
    "step_events",
    "time_events",
)


def _not_called(*args: Any) -> int:
    return 3  # fmi2Error / fmi3Error: a call of the other FMI version


_STAND_INS: dict[int, Any] = {}


def _stand_in(prototype: Any) -> Any:
    key = id(prototype)
    if key not in _STAND_INS:
        _STAND_INS[key] = prototype(_not_called)
    return _STAND_INS[key]


def me_functions(dll: ctypes.CDLL, major: int, fmu: str) -> tuple[Any, ...]:
    """Return the loop's function tuple for an FMU's Model Exchange library.

    Parameters
    ----------
    dll : ctypes.CDLL
        The loaded library.
    major : {2, 3}
        FMI major version.
    fmu : str
        The FMU's name, for messages.

    Raises
    ------
    FMUError
        The library lacks a Model Exchange function (named).
    """
    funcs = []
    for *names, prototype in PROTOTYPES:
        name = names[major - 2]
        if not name:
            funcs.append(_stand_in(prototype))
            continue
        try:
            funcs.append(raw(dll, name, prototype))
        except AttributeError:
            raise FMUError(f"{fmu}: the Model Exchange library does not export {name}") from None
    return tuple(funcs)


class MESolver:
    """The integrator's buffers and settings for one session.

    Parameters
    ----------
    funcs : tuple
        From :func:`me_functions`.
    major : {2, 3}
        FMI major version.
    nx, nz : int
        Numbers of continuous states and event indicators.
    vr_in, vr_out : numpy.ndarray
        ``uint32`` value references of the inputs and outputs.
    linear : numpy.ndarray of bool
        Per input: interpolated linearly (else held).
    rtol, atol, max_step : float, optional
        See the module's docstring.

    Attributes
    ----------
    stats : dict of str to int
        The counters of the last run (:data:`STATS`).
    """

    def __init__(
        self,
        funcs: tuple[Any, ...],
        major: int,
        nx: int,
        nz: int,
        vr_in: np.ndarray,
        vr_out: np.ndarray,
        linear: np.ndarray,
        *,
        rtol: float | None = None,
        atol: float | None = None,
        max_step: float | None = None,
    ) -> None:
        self.funcs, self.major = funcs, major
        self.rtol = DEFAULT_RTOL if rtol is None else float(rtol)
        self.atol = DEFAULT_ATOL if atol is None else float(atol)
        self.max_step = math.inf if max_step is None else float(max_step)
        self.vr_in = np.ascontiguousarray(vr_in, dtype=np.uint32)
        self.vr_out = np.ascontiguousarray(vr_out, dtype=np.uint32)
        self.w = np.zeros((meloop.ROWS, max(nx, 1)))
        self.z = np.zeros((3, max(nz, 1)))
        self.ub = np.zeros(max(self.vr_in.size, 1))
        self.evd = np.zeros(meloop.EV_SIZE // 8)
        self.ev = self.evd.view(np.uint8)
        self.opts = np.zeros(meloop.OPTS_SIZE)
        self.counts = np.zeros(len(STATS), dtype=np.int64)
        ctx = np.zeros(meloop.CTX_SIZE, dtype=np.int64)
        ctx[meloop.C_VIN] = self.vr_in.ctypes.data
        ctx[meloop.C_NIN] = self.vr_in.size
        ctx[meloop.C_VOUT] = self.vr_out.ctypes.data
        ctx[meloop.C_NOUT] = self.vr_out.size
        ctx[meloop.C_NX], ctx[meloop.C_NZ], ctx[meloop.C_MAJOR] = nx, nz, major
        ctx[meloop.C_LIN] = int(bool(np.any(linear)))
        ctx[meloop.C_W], ctx[meloop.C_WS] = self.w.ctypes.data, self.w.strides[0]
        ctx[meloop.C_Z], ctx[meloop.C_ZS] = self.z.ctypes.data, self.z.strides[0]
        ctx[meloop.C_UB], ctx[meloop.C_EV] = self.ub.ctypes.data, self.ev.ctypes.data
        self.ctx = ctx

    @property
    def stats(self) -> dict[str, int]:
        """The counters of the last run."""
        return {name: int(v) for name, v in zip(STATS, self.counts, strict=True)}

    def run(
        self, component: int, time: np.ndarray, inputs: np.ndarray, slopes: np.ndarray
    ) -> tuple[np.ndarray, tuple[int, int, int, float]]:
        """Integrate the initialized instance ``component`` along ``time``.

        Parameters
        ----------
        component : int
            The instance's address (after ``exitInitializationMode``, in Event Mode).
        time : numpy.ndarray
            Sample times (writeable, C-contiguous float64).
        inputs, slopes : numpy.ndarray
            Inputs per sample ``(n, n_in)`` and their slopes per interval
            ``(n - 1, n_in)``, zero for held inputs (writeable, C-contiguous).

        Returns
        -------
        out : numpy.ndarray
            ``(n, n_out)`` outputs at the sample times.
        result : tuple
            The loop's ``(status, index, call, time)``; status 0 on success.
        """
        self.ctx[meloop.C_COMP] = component
        self.opts[:] = 0.0
        self.opts[meloop.O_RTOL], self.opts[meloop.O_ATOL] = self.rtol, self.atol
        self.opts[meloop.O_MAX_STEP] = self.max_step
        self.opts[meloop.O_LOC_TOL] = LOCATION_TOLERANCE
        self.opts[meloop.O_DT] = min(self.max_step, float(time[1] - time[0]))
        self.opts[meloop.O_NEXT] = math.inf
        self.counts[:] = 0
        out = np.empty((time.size, self.vr_out.size))
        arr = (self.w, self.z, inputs, slopes, self.ub, self.ev, self.evd, self.opts, self.counts)
        status, k, call, t = me_loop()(self.funcs, self.ctx, time, arr, out)
        return out, (int(status), int(k), int(call), float(t))

    def error(self, inst: Any, result: tuple[int, int, int, float]) -> Exception:
        """Return the SimulationError for a failed run (naming the call, sample and time)."""
        status, k, call, t = result
        names = CALL_NAMES[self.major]
        name = names[call] if 0 < call < len(names) else "the integrator"
        if status == meloop.STATUS_TERMINATE:
            what = f"the FMU requested termination in {name}"
        elif status == meloop.STATUS_STEP_SIZE:
            what = (
                "the step size of the Model Exchange integrator fell below the resolution "
                f"of the time (rtol={self.rtol:g}, atol={self.atol:g}; a stiff model, or a "
                "right-hand side that jumps without an event indicator?)"
            )
        elif status == meloop.STATUS_EVENT_LOOP:
            what = (
                f"event iteration did not settle in {meloop.MAX_EVENT_ITERATIONS} calls of {name}"
            )
        else:
            return inst.error(CallFailed(name, status), "Model Exchange integration", k, t)
        return SimulationError(
            f"{inst.name}: {what} at t={t:g} (sample interval {k}).{inst.log.text()}"
        )

    def simulate(self, inst: Any, grid: Any, values: Any, variables: Any) -> np.ndarray:
        """Initialize ``inst`` with ``values``, integrate along ``grid``, terminate.

        Parameters
        ----------
        inst : tsid_fmu.fmu.instance.Instance
            The session's instance (instantiated or reset).
        grid : tsid_fmu.fmu.grid.Grid
            Sample times, inputs and input slopes (writeable, C-contiguous).
        values : list
            Start values and parameters of the run.
        variables : mapping
            The model's variables.

        Raises
        ------
        SimulationError
            An FMI call failed, the FMU asked to terminate, or the integrator could not
            proceed (the message names the call, the sample interval and the time).
        """
        t, u = grid.time, grid.inputs
        inst.initialize(t[0], t[-1], values, variables, self.vr_in, u[0])
        out, result = self.run(inst.address, t, u, grid.slopes)
        if result[0]:
            raise self.error(inst, result)
        inst.terminate(t.size - 1, t[-1])
        return out
