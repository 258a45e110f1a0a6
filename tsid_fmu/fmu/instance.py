"""The life of one FMU instance: instantiate, set values, initialize, reset, free.

Everything here goes through FMPy's checked wrappers (``FMU2Slave``, ``FMU3Model``,
...), whose failures raise ``FMICallException``; :meth:`Instance.error` turns such a
failure into a :class:`~tsid_fmu.errors.SimulationError` naming the FMI function, the
step, the time and the FMU's last log messages.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

import tsid_fmu.fmu.steploop as steploop
from tsid_fmu.errors import FMUError, SimulationError
from tsid_fmu.fmu.logs import STATUS_NAMES, LogCapture, fmi2_callbacks
from tsid_fmu.fmu.variables import VariableInfo

__all__ = ["CallFailed", "Instance", "Values"]

_FMI_DISCARD = 2
STRUCTURAL = "structuralParameter"
_FMI_FATAL = 4

#: ``(name, kind, value_reference, value)`` of the values set before initialization
Values = list[tuple[str, str, int, float]]


class CallFailed(Exception):
    """A failing FMI call of a compiled loop, as :meth:`Instance.error` reads it."""

    def __init__(self, function: str, status: int | None = None) -> None:
        super().__init__(function)
        self.function = function
        self.status = status


class Instance:
    """An FMPy FMU object (its library loaded) and the instance made from it.

    Parameters
    ----------
    fmu : fmpy.fmi2.FMU2Slave or FMU2Model or fmpy.fmi3.FMU3Slave or FMU3Model
        The loaded FMU, not yet instantiated.
    major : {2, 3}
        FMI major version.
    log : LogCapture
        Receives the instance's log messages.
    name : str
        The FMU's file name, for messages.

    Attributes
    ----------
    component : int or None
        The instance as FMPy holds it (None once freed).
    address : int
        The instance's address, for the step loops.
    """

    def __init__(self, fmu: Any, major: int, log: LogCapture, name: str) -> None:
        self.fmu = fmu
        self.major = major
        self.log = log
        self.name = name
        self.component: Any = None
        self.address = 0
        self._callbacks: Any = None
        #: instances made so far (a fresh one per run whose structure changed)
        self.instantiations = 0
        #: the values of the last run that choose the structure (see :meth:`renew`)
        self.structure: tuple[tuple[str, float], ...] = ()
        #: relative tolerance passed to ``fmi2SetupExperiment`` / FMI 3's
        #: ``fmi3EnterInitializationMode`` (None: not defined, the FMU's own default)
        self.tolerance: float | None = None
        #: free and instantiate afresh before every run instead of resetting (an FMU
        #: whose reset is broken, :mod:`tsid_fmu.evaluate.conformance`)
        self.fresh = False

    def instantiate(self) -> None:
        """Make a new instance; FMUError if the FMU refuses.

        An FMU that refuses without a message is asked once more with logging on: many
        exporters say why only then.
        """
        fmu = self.fmu
        failure = self._try_instantiate(False)
        if failure is not None and not self.log.messages:
            failure = self._try_instantiate(True)
            if failure is not None and self.log.messages:
                failure = f"{failure} (asked again with logging on)"
        if failure is not None:
            raise FMUError(f"{self.name}: instantiation failed{failure}.{self.log.text()}")
        self.component = fmu.component
        self.address = int(getattr(fmu.component, "value", fmu.component) or 0)
        self.instantiations += 1

    def _try_instantiate(self, logging_on: bool) -> str | None:
        """Instantiate; return None, or how it failed (``": <exception>"`` or ``""``)."""
        fmu = self.fmu
        try:
            if self.major == 2:
                self._callbacks = fmi2_callbacks(self.log)  # alive as long as the instance
                fmu.instantiate(callbacks=self._callbacks, loggingOn=logging_on)
            else:
                fmu.instantiate(logMessage=self.log.fmi3, loggingOn=logging_on)
        except Exception as exc:  # FMPy raises bare Exception on a NULL instance
            return f": {exc}"
        return None if fmu.component else ""

    def free(self) -> None:
        """Free the instance (if any)."""
        if self.component is not None:
            if self.major == 2:
                self.fmu.fmi2FreeInstance(self.component)
            else:
                self.fmu.fmi3FreeInstance(self.component)
        self.component = None
        self.address = 0

    def reset(self) -> None:
        """Bring the instance back to the instantiated state (re-instantiate if needed)."""
        if self.component is not None:
            try:
                status = self.fmu.reset()
                if status is None or status < _FMI_DISCARD:
                    return
            except Exception:
                pass
        self.free()
        self.instantiate()

    def renew(self, structure: tuple[tuple[str, float], ...]) -> None:
        """Make ready for the next run: reset, or a fresh instance if the structure changed.

        ``structure`` holds the run's values of discrete ``fixed`` variables and FMI 3
        structural parameters (:func:`~tsid_fmu.fmu.variables.restarts_instance`): where
        one differs from the last run's, the instance is freed and made anew, so that an
        FMU that fixes its structure when it is instantiated honours the new value. With
        :attr:`fresh` every run gets a new instance (the library stays loaded).
        """
        if self.fresh or structure != self.structure:
            self.free()
            self.instantiate()
        else:
            self.reset()

    def unload(self) -> None:
        """Free the instance and unload the library."""
        try:
            self.free()
        finally:
            self.fmu.freeLibrary()

    def error(
        self, exc: Exception, what: str, step: int | str, t: float, status: int | None = None
    ) -> SimulationError:
        """Return the SimulationError for a failed FMI call (and free a Fatal instance)."""
        function = getattr(exc, "function", None) or what
        status = getattr(exc, "status", status)
        label = (
            f" returned {STATUS_NAMES[status]}"
            if status is not None and 0 <= status < len(STATUS_NAMES)
            else " failed"
        )
        if status is not None and status >= _FMI_FATAL:
            self.free()
        return SimulationError(
            f"{self.name}: {function}{label} at step {step}, t={t:g} ({what}).{self.log.text()}"
        )

    def loop_error(self, status: int, k: int, call: int, t: np.ndarray) -> SimulationError:
        """Return the SimulationError for a failed Co-Simulation step loop at step ``k``."""
        if status == steploop.STATUS_TERMINATE:
            return SimulationError(
                f"{self.name}: the FMU requested termination in fmi3DoStep at step "
                f"{k}, t={t[k]:g}.{self.log.text()}"
            )
        what = (
            f"step from t={t[k]:g} to t={t[k + 1]:g}"
            if call in (steploop.CALL_STEP, steploop.CALL_DER)
            else "communication point"
        )
        err = CallFailed(steploop.CALL_NAMES[self.major][call], status)
        return self.error(err, what, k, t[k])

    def _set(self, name: str, kind: str, vr: int, value: float, vtype: str) -> None:
        fmu = self.fmu
        if kind == "real":
            (fmu.setReal if self.major == 2 else fmu.setFloat64)([vr], [float(value)])
        elif kind == "int":
            if float(value) != round(float(value)):
                raise SimulationError(
                    f"{self.name}: {name!r} is an Integer variable, got non-integer {value!r}"
                )
            setter = (
                fmu.setInteger
                if self.major == 2
                else getattr(fmu, "set" + ("Int64" if vtype == "Enumeration" else vtype))
            )
            setter([vr], [round(float(value))])
        else:
            fmu.setBoolean([vr], [bool(value)])

    def apply(self, values: Values, variables: Mapping[str, VariableInfo], t0: float) -> None:
        """Set start values and parameters (before initialization)."""
        for name, kind, vr, value in values:
            try:
                self._set(name, kind, vr, value, variables[name].type)
            except SimulationError:
                raise
            except Exception as exc:  # FMICallException
                raise self.error(exc, f"setting {name!r} = {value!r}", 0, t0) from exc

    def initialize(
        self,
        t0: float,
        t_end: float,
        values: Values,
        variables: Mapping[str, VariableInfo],
        vr_in: np.ndarray,
        u0: np.ndarray,
    ) -> None:
        """Apply ``values``, set the inputs of ``t0`` and initialize."""
        fmu = self.fmu
        try:
            if self.major == 2:
                fmu.setupExperiment(tolerance=self.tolerance, startTime=t0, stopTime=t_end)
                self.apply(values, variables, t0)
                fmu.enterInitializationMode()
                if u0.size:
                    fmu.setReal(list(vr_in), list(u0))
            else:
                config = [v for v in values if variables[v[0]].causality == STRUCTURAL]
                if config:  # FMI 3: structural parameters only in Configuration Mode
                    fmu.enterConfigurationMode()
                    self.apply(config, variables, t0)
                    fmu.exitConfigurationMode()
                self.apply([v for v in values if v not in config], variables, t0)
                fmu.enterInitializationMode(tolerance=self.tolerance, startTime=t0, stopTime=t_end)
                if u0.size:
                    fmu.setFloat64(list(vr_in), list(u0))
            fmu.exitInitializationMode()
        except SimulationError:
            raise
        except Exception as exc:  # FMICallException from FMPy's checked wrappers
            raise self.error(exc, "initialization", 0, t0) from exc

    def terminate(self, step: int, t: float) -> None:
        """End the run (``fmi2Terminate`` / ``fmi3Terminate``)."""
        try:
            self.fmu.terminate()
        except Exception as exc:  # FMICallException
            raise self.error(exc, "terminate", step, t) from exc
