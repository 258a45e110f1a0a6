"""Run an FMU for one parameter set against measured inputs, many times over.

A Taguchi study simulates the same FMU hundreds of times with different parameter
values.  :class:`FMUSession` therefore does all the expensive work once -- extract the
archive, read ``modelDescription.xml``, check the variable names, load the shared
library and instantiate -- and only *resets* the instance between runs.

Co-Simulation FMUs (FMI 2.0 and 3.0) are stepped by one small function per FMI version
(:func:`_cs_loop_fmi2`, :func:`_cs_loop_fmi3`) that calls the raw C function pointers
and reads and writes numpy buffers in place; it is the hot path and is kept isolated
so that a compiled loop can replace it.  Model Exchange FMUs are integrated with
FMPy's own solver (CVode), reusing the session's instance and extracted folder.

Setup (instantiate, initialization, reset, terminate) goes through FMPy's
``FMU2Slave``/``FMU2Model``/``FMU3Slave``/``FMU3Model`` wrappers, whose FMI status
checks raise ``FMICallException``; the session turns them into
:class:`~tsid_fmu.errors.SimulationError` naming the FMI function, the time and the
FMU's last log messages.

Examples
--------
>>> with FMUSession("plant.fmu", inputs=["u"], outputs=["y"],
...                 parameters=["tau"]) as session:          # doctest: +SKIP
...     y = session.simulate(t, u[:, None], {"tau": 0.2})
"""

from __future__ import annotations

import ctypes
import difflib
import itertools
import logging
import math
import os
import re
import shutil
import tempfile
import zipfile
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from ctypes import CFUNCTYPE, byref, c_bool, c_double, c_int, c_size_t, c_void_p
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from tsid_fmu.errors import FMUError, SimulationError
from tsid_fmu.safety import safe_extract

__all__ = ["FMUSession", "VariableInfo", "fmu_info"]

_STATUS_NAMES = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
_FMI_DISCARD = 2
_FMI_FATAL = 4
#: status the FMI 3.0 loop reports when the FMU sets ``terminateSimulation``
_STATUS_TERMINATE = 100
#: FMI calls made by the step loops, indexed by the loop's third return value
_LOOP_CALLS = ("", "fmi{v}SetReal", "fmi{v}DoStep", "fmi{v}GetReal")
_CALL_SET, _CALL_STEP, _CALL_GET = 1, 2, 3
_N_LOG = 8

_REAL_TYPES = {"Real", "Float64"}
_INT_TYPES = {
    "Integer",
    "Enumeration",
    "Int8",
    "UInt8",
    "Int16",
    "UInt16",
    "Int32",
    "UInt32",
    "Int64",
    "UInt64",
}
_BOOL_TYPES = {"Boolean"}

Logger = logging.Logger | Callable[[str], None]


@dataclass(frozen=True)
class VariableInfo:
    """What the session knows about one model variable.

    Attributes
    ----------
    name, value_reference, type, causality, variability, initial, unit, description
        As in ``modelDescription.xml`` (``type`` is FMPy's: ``"Real"``, ``"Float64"``,
        ``"Integer"``, ``"Boolean"``, ...).
    start : str or None
        The start value as written in the model description.
    """

    name: str
    value_reference: int
    type: str
    causality: str | None
    variability: str | None
    initial: str | None
    start: str | None
    unit: str | None
    description: str | None


# ---------------------------------------------------------------------------------------
# The step loops (hot path).  Pure functions of raw function pointers, addresses and
# numpy arrays, so that a compiled implementation can be dropped in.
# ---------------------------------------------------------------------------------------

_FMI2_SETGET = CFUNCTYPE(c_int, c_void_p, c_void_p, c_size_t, c_void_p)
_FMI2_DOSTEP = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_int)
_FMI3_SETGET = CFUNCTYPE(c_int, c_void_p, c_void_p, c_size_t, c_void_p, c_size_t)
_FMI3_DOSTEP = CFUNCTYPE(
    c_int, c_void_p, c_double, c_double, c_bool, c_void_p, c_void_p, c_void_p, c_void_p
)


def _raw(dll: ctypes.CDLL, name: str, prototype: Any) -> Any:
    """Return ``dll.<name>`` as a function pointer of ``prototype`` (address arguments)."""
    return prototype(ctypes.cast(getattr(dll, name), c_void_p).value)


def _cs_loop_fmi2(
    funcs: tuple[Any, Any, Any],
    component: int,
    vr_in: np.ndarray,
    vr_out: np.ndarray,
    time: np.ndarray,
    inputs: np.ndarray,
    out: np.ndarray,
) -> tuple[int, int, int]:
    """Step an initialized FMI 2.0 Co-Simulation instance along ``time``.

    Parameters
    ----------
    funcs : tuple
        Raw ``(fmi2SetReal, fmi2DoStep, fmi2GetReal)`` function pointers taking addresses.
    component : int
        The ``fmi2Component`` address.
    vr_in, vr_out : numpy.ndarray
        C-contiguous ``uint32`` value references of the inputs and outputs.
    time : numpy.ndarray
        Communication points, ``float64``, shape ``(n,)``.
    inputs : numpy.ndarray
        C-contiguous ``float64`` array of shape ``(n, len(vr_in))``; row ``k`` is set
        before the step from ``time[k]`` to ``time[k + 1]``.
    out : numpy.ndarray
        C-contiguous ``float64`` array of shape ``(n, len(vr_out))``, filled in place:
        row 0 right away (after initialization), row ``k + 1`` after step ``k``.

    Returns
    -------
    status : int
        0 on success, else the failing FMI status (>= Discard).
    index : int
        The step index at which the failing call was made (``n - 1`` on success).
    call : int
        Index into ``_LOOP_CALLS`` of the failing call (0 on success).
    """
    set_real, do_step, get_real = funcs
    t = time.tolist()
    n_in, n_out = vr_in.size, vr_out.size
    a_vin, a_vout = vr_in.ctypes.data, vr_out.ctypes.data
    a_in, s_in = inputs.ctypes.data, inputs.strides[0]
    a_out, s_out = out.ctypes.data, out.strides[0]
    status = get_real(component, a_vout, n_out, a_out)
    if status >= _FMI_DISCARD:
        return status, 0, _CALL_GET
    if n_in:
        for k in range(len(t) - 1):
            status = set_real(component, a_vin, n_in, a_in + k * s_in)
            if status >= _FMI_DISCARD:
                return status, k, _CALL_SET
            status = do_step(component, t[k], t[k + 1] - t[k], 1)
            if status >= _FMI_DISCARD:
                return status, k, _CALL_STEP
            status = get_real(component, a_vout, n_out, a_out + (k + 1) * s_out)
            if status >= _FMI_DISCARD:
                return status, k + 1, _CALL_GET
    else:
        for k in range(len(t) - 1):
            status = do_step(component, t[k], t[k + 1] - t[k], 1)
            if status >= _FMI_DISCARD:
                return status, k, _CALL_STEP
            status = get_real(component, a_vout, n_out, a_out + (k + 1) * s_out)
            if status >= _FMI_DISCARD:
                return status, k + 1, _CALL_GET
    return 0, len(t) - 1, 0


def _cs_loop_fmi3(
    funcs: tuple[Any, Any, Any],
    component: int,
    vr_in: np.ndarray,
    vr_out: np.ndarray,
    time: np.ndarray,
    inputs: np.ndarray,
    out: np.ndarray,
) -> tuple[int, int, int]:
    """Step an initialized FMI 3.0 Co-Simulation instance along ``time``.

    Same contract as :func:`_cs_loop_fmi2` with ``(fmi3SetFloat64, fmi3DoStep,
    fmi3GetFloat64)``; a step that sets ``terminateSimulation`` ends the loop with
    status ``_STATUS_TERMINATE``.
    """
    set_real, do_step, get_real = funcs
    t = time.tolist()
    n_in, n_out = vr_in.size, vr_out.size
    a_vin, a_vout = vr_in.ctypes.data, vr_out.ctypes.data
    a_in, s_in = inputs.ctypes.data, inputs.strides[0]
    a_out, s_out = out.ctypes.data, out.strides[0]
    flags = (c_bool * 3)()
    last = c_double()
    a_event, a_term, a_early = (
        ctypes.addressof(flags) + i * ctypes.sizeof(c_bool) for i in range(3)
    )
    a_last = ctypes.addressof(last)
    status = get_real(component, a_vout, n_out, a_out, n_out)
    if status >= _FMI_DISCARD:
        return status, 0, _CALL_GET
    for k in range(len(t) - 1):
        if n_in:
            status = set_real(component, a_vin, n_in, a_in + k * s_in, n_in)
            if status >= _FMI_DISCARD:
                return status, k, _CALL_SET
        status = do_step(component, t[k], t[k + 1] - t[k], True, a_event, a_term, a_early, a_last)
        if status >= _FMI_DISCARD:
            return status, k, _CALL_STEP
        if flags[1]:
            return _STATUS_TERMINATE, k, _CALL_STEP
        status = get_real(component, a_vout, n_out, a_out + (k + 1) * s_out, n_out)
        if status >= _FMI_DISCARD:
            return status, k + 1, _CALL_GET
    return 0, len(t) - 1, 0


def _cs_loop(major: int) -> Callable[..., tuple[int, int, int]]:
    """Return the step loop to use: Numba-compiled if available, else the Python one above.

    See :mod:`tsid_fmu.fastloop` (``TSID_FMU_LOOP=python`` forces the Python loop).
    """
    from tsid_fmu.fastloop import cs_loop

    return cs_loop(major)


# ---------------------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------------------


#: read-only (time, inputs) pairs a session remembers as checked
_MAX_CHECKED = 32


def _frozen(a: Any) -> bool:
    """Return True for a read-only, C-contiguous float64 array (checked only once).

    A read-only view of a writeable array can still change, so every array it is a
    view of must be read-only too.
    """
    if not (isinstance(a, np.ndarray) and a.flags.c_contiguous and a.dtype == np.float64):
        return False
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return True


def _suggest(name: str, candidates: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, candidates, n=3, cutoff=0.6)
    return f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""


_DEP_RE = re.compile(r"([^\s:]+\.(?:so|dylib|dll)(?:\.[0-9.]+)?): cannot open shared object")


def _missing_dependency(message: str, library: Path) -> str | None:
    """Name the dependency a ``dlopen`` error message complains about, if any."""
    for match in _DEP_RE.finditer(message):
        name = match.group(1)
        if Path(name).name != library.name:
            return name
    return None


def _declared_unit(variable: Any) -> str | None:
    unit = getattr(variable, "unit", None)
    if unit is None and getattr(variable, "declaredType", None) is not None:
        unit = getattr(variable.declaredType, "unit", None)
    return unit


def _info(variable: Any) -> VariableInfo:
    return VariableInfo(
        name=variable.name,
        value_reference=int(variable.valueReference),
        type=variable.type,
        causality=variable.causality,
        variability=variable.variability,
        initial=variable.initial,
        start=None if variable.start is None else str(variable.start),
        unit=_declared_unit(variable),
        description=variable.description,
    )


def _parse_start(info: VariableInfo) -> float | None:
    if info.start is None:
        return None
    text = info.start.strip()
    if info.type in _BOOL_TYPES:
        return 1.0 if text.lower() in ("true", "1") else 0.0
    try:
        return float(text.split()[0])
    except (ValueError, IndexError):
        return None


_MAX_DESCRIPTION_BYTES = 256 * 1024**2
"""Largest modelDescription.xml that ``fmu_info`` reads into memory."""

_MAX_SUBSTEPS = 1_000_000
"""Largest number of communication steps a ``step_size`` may split one sample into."""


# FMI 2.0 loggers are variadic, which ctypes cannot receive; FMPy's native proxy formats
# the message and forwards it to *one* Python callback that it keeps in a static C
# variable. Installing a callback per session would redirect every FMU's messages in
# the process to the newest session and leave a dangling pointer (a segfault on the
# next message) once that session is gone. So one dispatcher, alive for the whole
# process, is installed once; each session's callbacks carry their own id as the
# componentEnvironment, and the dispatcher hands a message to the session with that id.
# Messages of FMUs not opened by a session (plain FMPy use) go to FMPy's printer.
_LOG_TARGETS: dict[int, _LogCapture] = {}
_LOG_IDS = itertools.count(1)
_FMI2_PROXY: Any = None


def _fmi2_dispatch(env: Any, instance: bytes, status: int, category: bytes, message: bytes) -> None:
    target = _LOG_TARGETS.get(env or 0)
    if target is not None:
        target.add(status, category, message)
    else:
        from fmpy.fmi2 import printLogMessage

        printLogMessage(env, instance, status, category, message)


def _fmi2_callbacks(capture: _LogCapture) -> Any:
    """Return FMI 2.0 callbacks whose log messages reach ``capture``."""
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
        capture.env_id = next(_LOG_IDS)
        _LOG_TARGETS[capture.env_id] = capture
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _FMI2_PROXY[0].logger
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = capture.env_id
    return callbacks


class _LogCapture:
    """Receive the FMU's log messages, keep the last few, forward them to a logger."""

    def __init__(self, logger: Logger | None) -> None:
        self.messages: deque[str] = deque(maxlen=_N_LOG)
        self.logger = logger
        self.env_id = 0  # key of this capture in _LOG_TARGETS (FMI 2.0), once registered

    def release(self) -> None:
        """Stop receiving FMI 2.0 messages (after the instance is freed)."""
        _LOG_TARGETS.pop(self.env_id, None)
        self.env_id = 0

    def add(self, status: int, category: bytes | None, message: bytes | None) -> None:
        label = _STATUS_NAMES[status] if 0 <= status < len(_STATUS_NAMES) else str(status)
        text = (message or b"").decode("utf-8", errors="replace").strip()
        cat = (category or b"").decode("utf-8", errors="replace")
        line = f"[{label}] {cat + ': ' if cat else ''}{text}"
        self.messages.append(line)
        if self.logger is None:
            return
        if isinstance(self.logger, logging.Logger):
            level = logging.WARNING if status >= 1 else logging.DEBUG
            self.logger.log(level if status < 3 else logging.ERROR, "%s", line)
        else:
            self.logger(line)

    def fmi2(self, env: Any, instance: bytes, status: int, category: bytes, message: bytes) -> None:
        self.add(status, category, message)

    def fmi3(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        self.add(status, category, message)

    def text(self) -> str:
        if not self.messages:
            return " The FMU logged no messages."
        return " Last FMU log messages: " + " | ".join(self.messages)


# ---------------------------------------------------------------------------------------
# The session
# ---------------------------------------------------------------------------------------


class FMUSession:
    """An FMU opened once and simulated many times (context manager).

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.fmu`` file (FMI 2.0 or 3.0), or a folder it was extracted to.
    inputs : sequence of str
        Real input variables (causality ``input``), in the column order of the
        ``inputs`` array given to :meth:`simulate`.
    outputs : sequence of str
        Real variables to record, in the column order of the result.
    parameters : sequence of str, optional
        Parameters that will be set per run (causality ``parameter``, variability
        ``fixed`` or ``tunable``); checked here so that a study fails before its first run.
    interface : {"auto", "cs", "me"}, optional
        Co-Simulation or Model Exchange; ``"auto"`` prefers Co-Simulation.
    step_size : float, optional
        Co-Simulation: largest communication step; longer sample intervals are split
        into equal sub-steps (input held).  Model Exchange: the solver's step size hint.
    start_values : mapping of str to float, optional
        Values applied on every run before the parameters (e.g. initial states).
    logger : logging.Logger or callable, optional
        Receives the FMU's log messages (the session always keeps the last few and puts
        them into error messages).

    Attributes
    ----------
    model_description : fmpy.model_description.ModelDescription
        FMPy's model description, read once.
    variables : dict of str to VariableInfo
        Every model variable by name.
    nfev : int
        Number of simulations run (including failed ones).

    Raises
    ------
    FMUError
        The file is missing, not an FMU, lacks a binary for this platform, cannot be
        loaded, or does not have the named variables with the right causality and type.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        inputs: Sequence[str],
        outputs: Sequence[str],
        *,
        parameters: Sequence[str] = (),
        interface: Literal["auto", "cs", "me"] = "auto",
        step_size: float | None = None,
        start_values: Mapping[str, float] | None = None,
        logger: Logger | None = None,
    ) -> None:
        self.path = Path(path)
        self.input_names = tuple(inputs)
        self.output_names = tuple(outputs)
        self.parameter_names = tuple(parameters)
        self.step_size = None if step_size is None else float(step_size)
        self.nfev = 0
        self._tempdir: Path | None = None
        self._fmu: Any = None
        self._component: Any = None
        self._needs_reset = False
        self._checked: dict[tuple[int, int], tuple[Any, Any, np.ndarray, np.ndarray]] = {}
        self._log = _LogCapture(logger)
        self._setters: dict[str, tuple[str, int]] = {}
        if interface not in ("auto", "cs", "me"):
            raise FMUError(
                f"{self.path.name}: interface must be 'auto', 'cs' or 'me', not {interface!r}"
            )
        try:
            self._open(interface, dict(start_values or {}))
        except BaseException:
            self.close()
            raise

    # -- opening --------------------------------------------------------------------------

    def _open(self, interface: str, start_values: dict[str, float]) -> None:
        from fmpy.model_description import read_model_description

        unzipdir = self._extract()
        md_file = unzipdir / "modelDescription.xml"
        if not md_file.is_file():
            raise FMUError(f"{self.path}: not a valid FMU, modelDescription.xml is missing")
        try:
            md = read_model_description(str(md_file), validate=False)
        except Exception as exc:  # FMPy raises bare Exception / lxml errors
            raise FMUError(f"{self.path}: cannot read modelDescription.xml: {exc}") from exc
        self.model_description = md
        self.fmi_version = md.fmiVersion
        if not (md.fmiVersion == "2.0" or md.fmiVersion.startswith("3.")):
            raise FMUError(
                f"{self.path}: FMI version {md.fmiVersion} is not supported (FMI 2.0 and 3.0 are)"
            )
        self._major = 2 if md.fmiVersion == "2.0" else 3
        self.variables: dict[str, VariableInfo] = {v.name: _info(v) for v in md.modelVariables}

        available = [k for k, d in (("cs", md.coSimulation), ("me", md.modelExchange)) if d]
        if interface == "auto":
            if not available:
                raise FMUError(
                    f"{self.path}: the FMU declares neither Co-Simulation nor Model Exchange"
                )
            interface = available[0]
        elif interface not in available:
            names = {"cs": "Co-Simulation", "me": "Model Exchange"}
            raise FMUError(
                f"{self.path}: interface {interface!r} requested but the FMU only supports "
                + (", ".join(names[a] for a in available) or "no interface")
                + f" (use interface={available[0]!r})" * bool(available)
            )
        self.interface = interface

        # variables
        self._vr_in = np.array(
            [self._check_real(n, "input", want_causality="input") for n in self.input_names],
            dtype=np.uint32,
        )
        self._vr_out = np.array(
            [self._check_real(n, "output") for n in self.output_names], dtype=np.uint32
        )
        if not self.output_names:
            raise FMUError(f"{self.path}: at least one output is needed")
        for name in self.parameter_names:
            self._setter(name, role="parameter")
        self._start_values = {}
        for name, value in start_values.items():
            self._setter(name, role="start value")
            self._start_values[name] = value

        self._load(unzipdir)

    def _extract(self) -> Path:
        if self.path.is_dir():
            return self.path
        if not self.path.is_file():
            raise FMUError(f"FMU file not found: {self.path}")
        if not zipfile.is_zipfile(self.path):
            raise FMUError(f"{self.path}: not an FMU (an FMU is a ZIP archive)")
        self._tempdir = Path(tempfile.mkdtemp(prefix="tsid-fmu-"))
        # checks member names, types and sizes; FMUError names the member at fault
        safe_extract(self.path, self._tempdir)
        return self._tempdir

    def _variable(self, name: str, role: str) -> VariableInfo:
        info = self.variables.get(name)
        if info is None:
            raise FMUError(
                f"{self.path.name}: unknown {role} {name!r}: the model has no "
                f"variable of that name.{_suggest(name, list(self.variables))}"
            )
        return info

    def _check_real(self, name: str, role: str, want_causality: str | None = None) -> int:
        info = self._variable(name, role)
        if want_causality is not None and info.causality != want_causality:
            raise FMUError(
                f"{self.path.name}: {role} {name!r} has causality "
                f"{info.causality!r}, not {want_causality!r}"
            )
        if info.type not in _REAL_TYPES:
            raise FMUError(
                f"{self.path.name}: {role} {name!r} is of type {info.type}, "
                "but a Real (Float64) variable is needed"
            )
        return info.value_reference

    def _setter(self, name: str, role: str) -> tuple[str, int]:
        """Check that ``name`` can be set before initialization; cache how to set it."""
        if name in self._setters:
            return self._setters[name]
        info = self._variable(name, role)
        if info.variability == "constant":
            raise FMUError(f"{self.path.name}: {role} {name!r} is a constant and cannot be set")
        if role == "parameter" and info.causality != "parameter":
            hint = (
                " (a calculated parameter is computed by the FMU)"
                if info.causality == "calculatedParameter"
                else ""
            )
            raise FMUError(
                f"{self.path.name}: parameter {name!r} has causality "
                f"{info.causality!r}, not 'parameter'; it cannot be "
                f"identified{hint}"
            )
        if info.causality == "independent" or (
            info.causality != "input" and info.initial == "calculated"
        ):
            raise FMUError(
                f"{self.path.name}: {role} {name!r} (causality "
                f"{info.causality!r}, initial {info.initial!r}) cannot be set"
            )
        if info.type in _REAL_TYPES:
            kind = "real"
        elif info.type in _INT_TYPES:
            kind = "int"
        elif info.type in _BOOL_TYPES:
            kind = "bool"
        else:
            raise FMUError(
                f"{self.path.name}: {role} {name!r} is of type {info.type}; only "
                "Real, Integer and Boolean variables can be set"
            )
        self._setters[name] = (kind, info.value_reference)
        return self._setters[name]

    def _load(self, unzipdir: Path) -> None:
        import fmpy

        md = self.model_description
        desc = md.coSimulation if self.interface == "cs" else md.modelExchange
        identifier = desc.modelIdentifier
        platform_dir = fmpy.platform if self._major == 2 else fmpy.platform_tuple
        library = unzipdir / "binaries" / platform_dir / (identifier + fmpy.sharedLibraryExtension)
        if not library.is_file():
            bindir = unzipdir / "binaries"
            present = sorted(p.name for p in bindir.iterdir()) if bindir.is_dir() else []
            raise FMUError(
                f"{self.path.name}: no binary for this platform: expected "
                f"binaries/{platform_dir}/{library.name}; platforms present: "
                f"{', '.join(present) if present else 'none'}"
                + (
                    " (the FMU only contains sources; compile it for this platform)"
                    if (unzipdir / "sources").is_dir()
                    else ""
                )
            )
        try:
            probe = ctypes.CDLL(str(library))
        except OSError as exc:
            dep = _missing_dependency(str(exc), library)
            reason = (
                f"it needs {dep}, which cannot be found (install it or add its "
                "folder to LD_LIBRARY_PATH)"
                if dep
                else str(exc)
            )
            raise FMUError(
                f"{self.path.name}: cannot load binaries/{platform_dir}/{library.name}: {reason}"
            ) from exc

        cwd = os.getcwd()
        try:
            cls = self._fmpy_class()
            self._fmu = cls(
                guid=md.guid,
                modelIdentifier=identifier,
                unzipDirectory=str(unzipdir),
                instanceName=identifier,
            )
        except Exception as exc:  # FMPy raises bare Exception, AttributeError on symbols
            raise FMUError(
                f"{self.path.name}: cannot load binaries/{platform_dir}/{library.name}: {exc}"
            ) from exc
        finally:
            os.chdir(cwd)
            from fmpy import freeLibrary

            freeLibrary(probe._handle)

        dll = self._fmu.dll
        if self.interface == "cs":
            if self._major == 2:
                self._loop_funcs = (
                    _raw(dll, "fmi2SetReal", _FMI2_SETGET),
                    _raw(dll, "fmi2DoStep", _FMI2_DOSTEP),
                    _raw(dll, "fmi2GetReal", _FMI2_SETGET),
                )
            else:
                self._loop_funcs = (
                    _raw(dll, "fmi3SetFloat64", _FMI3_SETGET),
                    _raw(dll, "fmi3DoStep", _FMI3_DOSTEP),
                    _raw(dll, "fmi3GetFloat64", _FMI3_SETGET),
                )
        self._instantiate()

    def _fmpy_class(self) -> type:
        if self._major == 2:
            from fmpy.fmi2 import FMU2Model, FMU2Slave

            return FMU2Slave if self.interface == "cs" else FMU2Model
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        return FMU3Slave if self.interface == "cs" else FMU3Model

    def _instantiate(self) -> None:
        fmu = self._fmu
        try:
            if self._major == 2:
                callbacks = _fmi2_callbacks(self._log)
                self._callbacks = callbacks  # keep alive as long as the instance
                fmu.instantiate(callbacks=callbacks)
            else:
                fmu.instantiate(logMessage=self._log.fmi3)
        except Exception as exc:  # FMPy raises bare Exception on a NULL instance
            raise FMUError(
                f"{self.path.name}: instantiation failed: {exc}.{self._log.text()}"
            ) from exc
        if not fmu.component:
            raise FMUError(f"{self.path.name}: instantiation failed.{self._log.text()}")
        self._component = fmu.component
        self._needs_reset = False

    def _free_instance(self) -> None:
        if self._fmu is not None and self._component is not None:
            if self._major == 2:
                self._fmu.fmi2FreeInstance(self._component)
            else:
                self._fmu.fmi3FreeInstance(self._component)
        self._component = None

    def _reset(self) -> None:
        """Bring the instance back to the instantiated state (re-instantiate if needed)."""
        if self._component is not None:
            try:
                status = self._fmu.reset()
                if status is None or status < _FMI_DISCARD:
                    self._needs_reset = False
                    return
            except Exception:
                pass
        self._free_instance()
        self._instantiate()

    # -- public API ------------------------------------------------------------------------

    def default_parameters(self) -> dict[str, float]:
        """Return the model description's start values of the session's parameters.

        Returns
        -------
        dict of str to float
            ``name -> start`` (NaN where the model gives no start value).
        """
        out = {}
        for name in self.parameter_names:
            start = _parse_start(self.variables[name])
            out[name] = float("nan") if start is None else start
        return out

    def simulate(
        self,
        time: np.ndarray,
        inputs: np.ndarray | None,
        parameters: Mapping[str, float],
    ) -> np.ndarray:
        """Simulate once with ``parameters`` and return the outputs at ``time``.

        Parameters
        ----------
        time : numpy.ndarray
            Strictly increasing sample times, shape ``(n,)``, ``n >= 2``.
        inputs : numpy.ndarray or None
            Shape ``(n, len(inputs))`` (or ``(n,)`` with one input); row ``k`` is held
            over ``[time[k], time[k+1])``.  ``None`` when the session has no inputs.
        parameters : mapping of str to float
            Values for this run, set after instantiation/reset and before the end of
            initialization (after the construction's ``start_values``).

        Returns
        -------
        numpy.ndarray
            Shape ``(n, len(outputs))``; row ``k`` is the outputs at ``time[k]``.

        Raises
        ------
        SimulationError
            An FMI call failed (the message names the call, step and time and quotes
            the FMU's log) or an output is not finite.  The session stays usable.
        FMUError
            A parameter name is unknown or cannot be set.
        """
        if self._fmu is None:
            raise SimulationError(f"{self.path.name}: the session is closed")
        t, u = self._check_arrays(time, inputs)
        values = [
            (name, *self._setter(name, "parameter"), value)
            for name, value in {**self._start_values, **parameters}.items()
        ]
        if self._needs_reset:
            self._reset()
        self._log.messages.clear()
        self.nfev += 1
        self._needs_reset = True
        if self.interface == "cs":
            out = self._simulate_cs(t, u, values)
        else:
            out = self._simulate_me(t, u, values)
        self._check_finite(t, out)
        return out

    def _check_arrays(
        self, time: np.ndarray, inputs: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        # A study simulates the same (read-only) time and input arrays hundreds of times:
        # the checks below are done once for them. Only arrays that cannot be changed in
        # place (not writeable, already float64 and C-contiguous) are remembered, by
        # identity, holding a reference so that the identity cannot be reused.
        # A study alternates between its replicates' inputs, so several pairs are kept.
        key = (id(time), id(inputs))
        hit = self._checked.get(key)
        if hit is not None and hit[0] is time and hit[1] is inputs:
            return hit[2], hit[3]
        t, u = self._validate_arrays(time, inputs)
        if _frozen(time) and (inputs is None or _frozen(inputs)) and t is time:
            if inputs is None or u is inputs or u.base is inputs:
                if len(self._checked) >= _MAX_CHECKED:
                    self._checked.pop(next(iter(self._checked)))
                self._checked[key] = (time, inputs, t, u)
        return t, u

    def _validate_arrays(
        self, time: np.ndarray, inputs: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        t = np.ascontiguousarray(time, dtype=np.float64)
        name = self.path.name
        if t.ndim != 1 or t.size < 2:
            raise SimulationError(
                f"{name}: time must be a 1-D array of at least 2 samples, got shape {t.shape}"
            )
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise SimulationError(f"{name}: time must be finite and strictly increasing")
        n_in = len(self.input_names)
        if inputs is None:
            if n_in:
                raise SimulationError(f"{name}: inputs missing for {', '.join(self.input_names)}")
            u = np.zeros((t.size, 0))
        else:
            u = np.asarray(inputs, dtype=np.float64)
            if u.ndim == 1 and n_in == 1:
                u = u[:, None]
            if u.shape != (t.size, n_in):
                raise SimulationError(
                    f"{name}: inputs must have shape ({t.size}, {n_in}) "
                    f"for {list(self.input_names)}, got {u.shape}"
                )
            if not np.all(np.isfinite(u)):
                row, col = np.argwhere(~np.isfinite(u))[0]
                raise SimulationError(
                    f"{name}: input {self.input_names[col]!r} is not finite "
                    f"at t={t[row]:g} (row {row})"
                )
            u = np.ascontiguousarray(u)
        return t, u

    def _check_finite(self, t: np.ndarray, out: np.ndarray) -> None:
        # NaN and inf always make the sum non-finite (one pass, no temporary array);
        # only then (or for a sum that overflowed) are the elements looked at
        if math.isfinite(float(out.sum())):
            return
        bad = ~np.isfinite(out)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise SimulationError(
                f"{self.path.name}: output {self.output_names[col]!r} is {out[row, col]} at "
                f"t={t[row]:g} (step {row}); check the parameters of this run"
            )

    def _apply(self, values: list[tuple[str, str, int, float]], t0: float) -> None:
        fmu = self._fmu
        for name, kind, vr, value in values:
            try:
                if kind == "real":
                    (fmu.setReal if self._major == 2 else fmu.setFloat64)([vr], [float(value)])
                elif kind == "int":
                    if float(value) != round(float(value)):
                        raise SimulationError(
                            f"{self.path.name}: {name!r} is an Integer "
                            f"variable, got non-integer {value!r}"
                        )
                    vtype = self.variables[name].type
                    setter = (
                        fmu.setInteger
                        if self._major == 2
                        else getattr(fmu, "set" + ("Int64" if vtype == "Enumeration" else vtype))
                    )
                    setter([vr], [round(float(value))])
                else:
                    fmu.setBoolean([vr], [bool(value)])
            except SimulationError:
                raise
            except Exception as exc:  # FMICallException
                raise self._fmi_error(exc, f"setting {name!r} = {value!r}", 0, t0) from exc

    def _fmi_error(
        self, exc: Exception, what: str, step: int | str, t: float, status: int | None = None
    ) -> SimulationError:
        function = getattr(exc, "function", None) or what
        status = getattr(exc, "status", status)
        label = (
            f" returned {_STATUS_NAMES[status]}"
            if status is not None and 0 <= status < len(_STATUS_NAMES)
            else " failed"
        )
        if status is not None and status >= _FMI_FATAL:
            self._free_instance()
        return SimulationError(
            f"{self.path.name}: {function}{label} at step {step}, "
            f"t={t:g} ({what}).{self._log.text()}"
        )

    def _setup(
        self, t0: float, t_end: float, values: list[tuple[str, str, int, float]], u0: np.ndarray
    ) -> None:
        fmu = self._fmu
        try:
            if self._major == 2:
                fmu.setupExperiment(startTime=t0, stopTime=t_end)
                self._apply(values, t0)
                fmu.enterInitializationMode()
                if u0.size:
                    fmu.setReal(list(self._vr_in), list(u0))
                fmu.exitInitializationMode()
            else:
                self._apply(values, t0)
                fmu.enterInitializationMode(startTime=t0, stopTime=t_end)
                if u0.size:
                    fmu.setFloat64(list(self._vr_in), list(u0))
                fmu.exitInitializationMode()
        except SimulationError:
            raise
        except Exception as exc:  # FMICallException from FMPy's checked wrappers
            raise self._fmi_error(exc, "initialization", 0, t0) from exc

    def _simulate_cs(
        self, t: np.ndarray, u: np.ndarray, values: list[tuple[str, str, int, float]]
    ) -> np.ndarray:
        # optional sub-steps: refine the grid, hold the input, keep the original rows
        keep = None
        if self.step_size is not None:
            ratio = np.diff(t) / self.step_size
            if not np.all(ratio <= _MAX_SUBSTEPS):
                raise SimulationError(
                    f"{self.path.name}: step_size {self.step_size:g} s would split a sample "
                    f"interval into more than {_MAX_SUBSTEPS} steps"
                )
            n_sub = np.maximum(np.ceil(ratio - 1e-9), 1).astype(int)
            if n_sub.max() > 1:
                fine = [
                    np.linspace(a, b, m, endpoint=False)
                    for a, b, m in zip(t[:-1], t[1:], n_sub, strict=True)
                ]
                keep = np.concatenate([[0], np.cumsum(n_sub)])
                u = np.ascontiguousarray(np.repeat(u[:-1], n_sub, axis=0).reshape(-1, u.shape[1]))
                u = np.vstack([u, np.zeros((1, u.shape[1]))])
                t_orig, t = t, np.concatenate([*fine, t[-1:]])
        self._setup(t[0], t[-1], values, u[0])
        out = np.empty((t.size, self._vr_out.size))
        loop = _cs_loop(self._major)
        status, k, call = loop(
            self._loop_funcs, self._component, self._vr_in, self._vr_out, t, u, out
        )
        if status:
            fname = _LOOP_CALLS[call].format(v=self._major)
            if status == _STATUS_TERMINATE:
                raise SimulationError(
                    f"{self.path.name}: the FMU requested termination in fmi3DoStep at step "
                    f"{k}, t={t[k]:g}.{self._log.text()}"
                )
            step_t = t[k]
            what = (
                f"step from t={t[k]:g} to t={t[k + 1]:g}"
                if call == _CALL_STEP
                else "communication point"
            )
            err = _StatusError(fname, status)
            raise self._fmi_error(err, what, k, step_t)
        try:
            self._fmu.terminate()
        except Exception as exc:  # FMICallException
            raise self._fmi_error(exc, "terminate", t.size - 1, t[-1]) from exc
        if keep is not None:
            out = out[keep]
            t = t_orig
        return out

    def _simulate_me(
        self, t: np.ndarray, u: np.ndarray, values: list[tuple[str, str, int, float]]
    ) -> np.ndarray:
        from fmpy import simulate_fmu

        if self.input_names:
            # zero-order hold as FMPy input events: repeat each time stamp
            n = t.size
            signal = np.zeros(
                2 * n - 1,
                dtype=[("time", np.float64)] + [(name, np.float64) for name in self.input_names],
            )
            signal["time"][0::2] = t
            signal["time"][1::2] = t[1:]
            for j, name in enumerate(self.input_names):
                signal[name][0::2] = u[:, j]
                signal[name][1::2] = u[:-1, j]
        else:
            signal = None
        dt = float(np.min(np.diff(t)))
        current = {"t": float(t[0])}

        def step_finished(time: float, recorder: Any) -> bool:
            current["t"] = time
            return True

        start_values = {
            name: (bool(v) if kind == "bool" else round(v) if kind == "int" else float(v))
            for name, kind, _vr, v in values
        }
        try:
            result = simulate_fmu(
                str(self._fmu.unzipDirectory),
                validate=False,
                start_time=float(t[0]),
                stop_time=float(t[-1]),
                step_size=self.step_size,
                output_interval=dt,
                record_events=False,
                start_values=start_values,
                input=signal,
                output=list(self.output_names),
                model_description=self.model_description,
                fmu_instance=self._fmu,
                step_finished=step_finished,
            )
        except Exception as exc:  # FMICallException or bare Exception from FMPy's solver
            raise self._fmi_error(
                exc, f"Model Exchange simulation: {exc}", "?", current["t"]
            ) from exc
        rt = result["time"]
        return np.column_stack([np.interp(t, rt, result[name]) for name in self.output_names])

    # -- closing ---------------------------------------------------------------------------

    def close(self) -> None:
        """Terminate and free the instance, unload the library, delete the temp folder."""
        try:
            if self._fmu is not None:
                try:
                    self._free_instance()
                finally:
                    try:
                        self._fmu.freeLibrary()
                    finally:
                        self._fmu = None
        finally:
            self._log.release()
            if self._tempdir is not None:
                shutil.rmtree(self._tempdir, ignore_errors=True)
                self._tempdir = None

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._fmu is None

    @property
    def tempdir(self) -> Path | None:
        """The folder the FMU was extracted to (removed on close), if the session owns one."""
        return self._tempdir

    def __enter__(self) -> FMUSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if getattr(self, "_tempdir", None) is not None or getattr(self, "_fmu", None):
            try:
                self.close()
            except Exception:
                pass

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"FMI {self.fmi_version} {self.interface}"
        return (
            f"FMUSession({str(self.path)!r}, inputs={list(self.input_names)}, "
            f"outputs={list(self.output_names)}, parameters={list(self.parameter_names)}, "
            f"{state}, nfev={self.nfev})"
        )


class _StatusError(Exception):
    """Carries a failing status out of the step loop (internal)."""

    def __init__(self, function: str, status: int) -> None:
        super().__init__(function)
        self.function = function
        self.status = status


# ---------------------------------------------------------------------------------------
# tsid info
# ---------------------------------------------------------------------------------------


def fmu_info(path: str | os.PathLike[str]) -> str:
    """Return a human-readable summary of an FMU (for ``tsid info FMU``).

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.fmu`` file.

    Returns
    -------
    str
        FMI version, model name, generation tool, interfaces, platforms, and the
        inputs, outputs and parameters with type, unit, start value and description.

    Raises
    ------
    FMUError
        The file is missing or not a readable FMU.
    """
    from fmpy import supported_platforms
    from fmpy.model_description import read_model_description

    path = Path(path)
    if not path.is_file():
        raise FMUError(f"FMU file not found: {path}")
    if not zipfile.is_zipfile(path):
        raise FMUError(f"{path}: not an FMU (an FMU is a ZIP archive)")
    try:
        with zipfile.ZipFile(path) as archive:
            size = archive.getinfo("modelDescription.xml").file_size
    except KeyError:
        raise FMUError(f"{path}: not a valid FMU, modelDescription.xml is missing") from None
    except (zipfile.BadZipFile, OSError) as exc:
        raise FMUError(f"{path}: cannot read the FMU: {exc}") from None
    if size > _MAX_DESCRIPTION_BYTES:
        raise FMUError(
            f"{path}: modelDescription.xml expands to {size} bytes, more than the limit of "
            f"{_MAX_DESCRIPTION_BYTES}; refusing the FMU"
        )
    try:
        md = read_model_description(str(path), validate=False)
        platforms = supported_platforms(str(path))
    except Exception as exc:  # FMPy raises bare Exception, KeyError for a missing member
        raise FMUError(f"{path}: cannot read modelDescription.xml: {exc}") from exc
    interfaces = [
        name
        for name, d in (("Co-Simulation", md.coSimulation), ("Model Exchange", md.modelExchange))
        if d
    ]
    lines = [
        f"FMU              {path}",
        f"FMI version      {md.fmiVersion}",
        f"Model name       {md.modelName}",
        f"Description      {md.description or ''}",
        f"Generation tool  {md.generationTool or ''}",
        f"Interfaces       {', '.join(interfaces) or 'none'}",
        f"Platforms        {', '.join(platforms) or 'none'}",
    ]
    exp = md.defaultExperiment
    if exp is not None:
        lines.append(
            f"Experiment       start={exp.startTime} stop={exp.stopTime} "
            f"step={exp.stepSize} tolerance={exp.tolerance}"
        )
    groups = (
        ("Inputs", lambda v: v.causality == "input"),
        ("Outputs", lambda v: v.causality == "output"),
        ("Parameters", lambda v: v.causality == "parameter" and v.variability != "constant"),
    )
    for title, keep in groups:
        chosen = [_info(v) for v in md.modelVariables if keep(v)]
        lines.append("")
        lines.append(f"{title} ({len(chosen)})")
        if chosen:
            width = max(len(v.name) for v in chosen)
            for v in chosen:
                lines.append(
                    f"  {v.name:<{width}}  {v.type:<8} {v.unit or '':<8} "
                    f"start={v.start if v.start is not None else '-':<10} "
                    f"{v.description or ''}".rstrip()
                )
    return "\n".join(lines)
