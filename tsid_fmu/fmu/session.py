"""Run an FMU for one parameter set against measured inputs, many times over.

A Taguchi study simulates the same FMU hundreds of times with different parameter
values.  :class:`FMUSession` therefore does all the expensive work once -- extract the
archive, read ``modelDescription.xml``, check the variable names, load the shared
library and instantiate -- and only *resets* the instance between runs.

Co-Simulation FMUs (FMI 2.0 and 3.0) are stepped by the loops of
:mod:`tsid_fmu.fmu.steploop` (compiled by Numba when available); inputs are held or
interpolated between samples as :mod:`tsid_fmu.fmu.grid` describes.  Model Exchange
FMUs are integrated by the project's own adaptive Runge-Kutta loop with event location
(:mod:`tsid_fmu.fmu.meloop`, :mod:`tsid_fmu.fmu.mesolver`; compiled likewise), or with
FMPy's CVode (``me_solver="cvode"``, :mod:`tsid_fmu.fmu.exchange`), reusing the
session's instance and extracted folder.

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

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

import tsid_fmu.fmu.exchange as exchange
import tsid_fmu.fmu.extraction as extraction
import tsid_fmu.fmu.grid as grid
from tsid_fmu.errors import FMUError, SimulationError
from tsid_fmu.fmu.compiled import cs_loop
from tsid_fmu.fmu.instance import Instance, Values
from tsid_fmu.fmu.library import load_fmu, loop_functions
from tsid_fmu.fmu.logs import LogCapture, Logger
from tsid_fmu.fmu.mesolver import MESolver, me_functions
from tsid_fmu.fmu.native import NativeOutput
from tsid_fmu.fmu.variables import (
    VariableInfo,
    choose_interface,
    parse_start,
    read_description,
    real_reference,
    restarts_instance,
    setter_kind,
    variable_info,
)

__all__ = ["FMUSession"]


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
        into equal sub-steps.  Model Exchange: the largest integration step
        (``"rk45"``) or the solver's step size hint (``"cvode"``).
    start_values : mapping of str to float, optional
        Values applied on every run before the parameters (e.g. initial states).
    logger : logging.Logger or callable, optional
        Receives the FMU's log messages (the session always keeps the last few and puts
        them into error messages).
    hold : mapping of str to {"previous", "linear"}, optional
        How each input behaves between samples: ``"previous"`` (zero-order hold, the
        default for every input) or ``"linear"`` (linear interpolation; through
        ``fmi2SetRealInputDerivatives`` if the FMI 2.0 FMU declares
        ``canInterpolateInputs``, else by ``substeps`` communication steps per sample
        interval with interpolated values).
    substeps : int, optional
        Communication steps per sample interval for linear inputs the FMU does not
        interpolate itself (default 10).
    me_solver : {"rk45", "cvode"}, optional
        Model Exchange: the project's compiled Cash-Karp integrator with event location
        (default; inputs set without an event per sample) or FMPy's CVode.
    tolerance : float, optional
        Model Exchange: relative tolerance (``"rk45"``: default
        :data:`~tsid_fmu.fmu.mesolver.DEFAULT_RTOL`; ``"cvode"``: FMPy's default).
    capture_output : bool, optional
        Capture what the FMU prints natively during instantiation and each run
        (:mod:`tsid_fmu.fmu.native`): it is echoed on stderr, kept as :attr:`printed`,
        and its tail ends the message of a failed run (default False).
    cs_tolerance : float, optional
        Co-Simulation: relative tolerance of the FMU's own solver, passed to
        ``fmi2SetupExperiment`` / ``fmi3EnterInitializationMode`` (default: not defined).
    fresh : bool, optional
        Instantiate afresh before every run instead of resetting (a broken reset).

    Attributes
    ----------
    model_description : fmpy.model_description.ModelDescription
        FMPy's model description, read once.
    variables : dict of str to VariableInfo
        Every model variable by name.
    hold : dict of str to str
        The hold of every input.
    nfev : int
        Number of simulations run (including failed ones).

    Raises
    ------
    FMUError
        The file is missing, not an FMU, lacks a binary for this platform, cannot be
        loaded, or does not have the named variables with the right causality and type;
        a hold or ``substeps`` is invalid.
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
        hold: Mapping[str, str] | None = None,
        substeps: int = 10,
        me_solver: Literal["rk45", "cvode"] = "rk45",
        tolerance: float | None = None,
        capture_output: bool = False,
        cs_tolerance: float | None = None,
        fresh: bool = False,
    ) -> None:
        self.path = Path(path)
        self.input_names = tuple(inputs)
        self.output_names = tuple(outputs)
        self.parameter_names = tuple(parameters)
        self.nfev = 0
        self._tempdir: Path | None = None
        self._inst: Instance | None = None
        self._needs_reset = False
        self._checked = grid.Checked()
        self._log = LogCapture(logger)
        self._capture = NativeOutput(enabled=capture_output)
        self._setters: dict[str, tuple[str, int]] = {}
        self._me: MESolver | None = None
        try:
            self.step_size = grid.check_step_size(self.path.name, step_size)
            self.substeps = grid.check_substeps(self.path.name, substeps)
            if interface not in ("auto", "cs", "me"):
                raise FMUError(
                    f"{self.path.name}: interface must be 'auto', 'cs' or 'me', not {interface!r}"
                )
            if me_solver not in ("rk45", "cvode"):
                raise FMUError(
                    f"{self.path.name}: me_solver must be 'rk45' or 'cvode', not {me_solver!r}"
                )
            self.me_solver = me_solver
            self.tolerance = grid.check_tolerance(self.path.name, tolerance)
            cs_tol = grid.check_tolerance(self.path.name, cs_tolerance)
            self._open(interface, dict(start_values or {}), dict(hold or {}), (cs_tol, fresh))
        except BaseException:
            self.close()
            raise

    # -- opening --------------------------------------------------------------------------

    def _open(self, interface: str, start: dict, hold: dict, cs: tuple) -> None:
        unzipdir = self._extract()
        md = read_description(unzipdir / "modelDescription.xml", self.path)
        self.model_description = md
        self.fmi_version = md.fmiVersion
        self._major = 2 if md.fmiVersion == "2.0" else 3
        self.variables: dict[str, VariableInfo] = {
            v.name: variable_info(v) for v in md.modelVariables
        }
        self.interface = choose_interface(md, interface, self.path)
        name = self.path.name
        self._vr_in = np.array(
            [real_reference(self.variables, name, n, "input", "input") for n in self.input_names],
            dtype=np.uint32,
        )
        self._vr_out = np.array(
            [real_reference(self.variables, name, n, "output") for n in self.output_names],
            dtype=np.uint32,
        )
        if not self.output_names:
            raise FMUError(f"{self.path}: at least one output is needed")
        for pname in self.parameter_names:  # an input is a parameter only without data
            if pname in self.input_names:
                raise FMUError(f"{name}: {pname!r} is both an input from the data and a parameter")
            self._setter(pname, role="parameter")
        self._start_values: dict[str, float] = {}
        for sname, value in start.items():
            self._setter(sname, role="start value")
            self._start_values[sname] = value
        self._set_hold(hold)
        fmu = load_fmu(name, unzipdir, md, self.interface, self._major)
        self._inst = Instance(fmu, self._major, self._log, name)
        self._inst.tolerance = cs[0] if self.interface == "cs" else None
        self._inst.fresh = cs[1]
        if self.interface == "cs":
            self._loop_funcs = loop_functions(fmu.dll, self._major)
        elif self.me_solver == "rk45":
            self._me = MESolver(
                me_functions(fmu.dll, self._major, name),
                self._major,
                md.numberOfContinuousStates,
                md.numberOfEventIndicators,
                self._vr_in,
                self._vr_out,
                self._linear,
                rtol=self.tolerance,
                max_step=self.step_size,
            )
        self._capture.call(self._inst.instantiate)

    def _set_hold(self, hold: dict[str, str]) -> None:
        """Check the holds; decide how linear inputs reach the FMU."""
        self.hold = grid.check_holds(self.path.name, self.input_names, hold)
        self._linear = np.array([self.hold[n] == "linear" for n in self.input_names], dtype=bool)
        cs = self.model_description.coSimulation
        #: the FMU interpolates linear inputs from their derivatives (FMI 2.0 only)
        self._native = bool(
            self._major == 2
            and self.interface == "cs"
            and cs is not None
            and getattr(cs, "canInterpolateInputs", False)
        )
        interpolated = self._linear if self._native else np.zeros_like(self._linear)
        self._vr_der = np.ascontiguousarray(self._vr_in[interpolated])
        self._order = np.ones(max(self._vr_der.size, 1), dtype=np.int32)
        self._flags = np.zeros(16, dtype=np.uint8)

    def _extract(self) -> Path:
        if self.path.is_dir():
            return self.path
        # this process's extraction of the file, shared with the sessions before and
        # after this one (see tsid_fmu.fmu.extraction for why)
        self._tempdir = extraction.borrow(self.path)
        return self._tempdir

    def _setter(self, name: str, role: str) -> tuple[str, int]:
        """Check that ``name`` can be set before initialization; cache how to set it."""
        if name not in self._setters:
            self._setters[name] = setter_kind(self.variables, self.path.name, name, role)
        return self._setters[name]

    @property
    def _fmu(self) -> Any:
        """FMPy's FMU object (None once closed)."""
        return None if self._inst is None else self._inst.fmu

    @property
    def _component(self) -> Any:
        """The FMU instance (None once freed)."""
        return None if self._inst is None else self._inst.component

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
            start = parse_start(self.variables[name])
            out[name] = float("nan") if start is None else start
        return out

    def set_start_values(self, values: Mapping[str, float]) -> None:
        """Replace the start values applied on every run (checked like the constructor's).

        Raises
        ------
        FMUError
            A name is unknown or cannot be set.
        """
        checked = {}
        for name, value in values.items():
            self._setter(name, role="start value")
            checked[name] = value
        self._start_values = checked

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
            Shape ``(n, len(inputs))`` (or ``(n,)`` with one input); row ``k`` is the
            inputs at ``time[k]``, held or interpolated up to ``time[k+1]`` as the
            session's ``hold`` says.  ``None`` when the session has no inputs.
        parameters : mapping of str to float
            Values for this run, set after instantiation/reset and before the end of
            initialization (after the construction's ``start_values``).

        Returns
        -------
        numpy.ndarray
            Shape ``(n, len(outputs))``; row ``k`` is the outputs at ``time[k]``, after
            the inputs of ``time[k]`` are set (no lag for direct feed-through).

        Raises
        ------
        SimulationError
            An FMI call failed (the message names the call, step and time and quotes
            the FMU's log) or an output is not finite.  The session stays usable.
        FMUError
            A parameter name is unknown or cannot be set.
        """
        inst = self._inst
        if inst is None:
            raise SimulationError(f"{self.path.name}: the session is closed")
        g = self._check_arrays(time, inputs)
        values = [
            (name, *self._setter(name, "parameter"), value)
            for name, value in {**self._start_values, **parameters}.items()
        ]
        structure = tuple(
            (name, float(value))
            for name, _kind, _vr, value in values
            if restarts_instance(self.variables[name])
        )
        self._log.messages.clear()
        self.nfev += 1
        out, t = self._capture.call(self._run, inst, g, values, structure)
        grid.check_finite(self.path.name, self.output_names, t, out)
        return out

    @property
    def printed(self) -> str:
        """What the FMU printed natively in the last run ('' unless ``capture_output``)."""
        return self._capture.text

    def _run(
        self, inst: Instance, g: grid.Grid, values: Values, structure: tuple
    ) -> tuple[np.ndarray, np.ndarray]:
        if self._needs_reset:
            inst.renew(structure)
        inst.structure = structure
        self._needs_reset = True
        if self.interface == "cs":
            t = g.time if g.keep is None else g.time[g.keep]
            return self._simulate_cs(inst, g, values), t
        return self._simulate_me(inst, g, values), g.time

    def _check_arrays(self, time: np.ndarray, inputs: np.ndarray | None) -> grid.Grid:
        hit = self._checked.get(time, inputs)
        if hit is not None:
            return hit
        t, u = self._validate_arrays(time, inputs)
        if self.interface == "cs":
            g = grid.refine(
                self.path.name,
                t,
                u,
                self._linear,
                native=self._native,
                step_size=self.step_size,
                substeps=self.substeps,
            )
        else:
            g = grid.model_exchange(t, u, self._linear)
        self._checked.put(time, inputs, g)
        return g

    def _validate_arrays(
        self, time: np.ndarray, inputs: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        return grid.validate(self.path.name, self.input_names, time, inputs)

    # -- one run -----------------------------------------------------------------------------

    def _simulate_cs(self, inst: Instance, g: grid.Grid, values: Values) -> np.ndarray:
        t, u = g.time, g.inputs
        inst.initialize(t[0], t[-1], values, self.variables, self._vr_in, u[0])
        out = np.empty((t.size, self._vr_out.size))
        buffers = (self._vr_in, self._vr_out, u, g.held, out)
        extra = (self._vr_der, self._order, g.slopes) if self._major == 2 else self._flags
        loop = cs_loop(self._major)
        status, k, call = loop(self._loop_funcs, inst.address, t, buffers, extra)
        if status:
            raise inst.loop_error(status, k, call, t)
        inst.terminate(t.size - 1, t[-1])
        return out if g.keep is None else out[g.keep]

    def _simulate_me(self, inst: Instance, g: grid.Grid, values: Values) -> np.ndarray:
        if self._me is not None:
            return self._me.simulate(inst, g, values, self.variables)
        start_values = {
            name: (bool(v) if kind == "bool" else round(v) if kind == "int" else float(v))
            for name, kind, _vr, v in values
        }
        return exchange.simulate_me(
            inst.fmu,
            self.model_description,
            g.time,
            exchange.input_signal(g.time, g.inputs, self.input_names, self._linear),
            self.output_names,
            start_values,
            self.step_size,
            self.tolerance,
            lambda exc, t: inst.error(exc, f"Model Exchange simulation: {exc}", "?", t),
        )

    # -- closing ---------------------------------------------------------------------------

    def close(self) -> None:
        """Terminate and free the instance, unload the library, give the folder back.

        The extraction folder is kept for the next session of the same FMU file and
        removed when the process exits (:mod:`tsid_fmu.fmu.extraction`).
        """
        try:
            if self._inst is not None:
                inst, self._inst = self._inst, None
                inst.unload()
        finally:
            self._log.release()
            if getattr(self, "_capture", None) is not None:
                self._capture.close()
            if self._tempdir is not None:
                extraction.give_back(self._tempdir)
                self._tempdir = None

    @property
    def instantiations(self) -> int:
        """Instances made so far (:meth:`~tsid_fmu.fmu.instance.Instance.renew`)."""
        return 0 if self._inst is None else self._inst.instantiations

    @property
    def me_stats(self) -> dict[str, int] | None:
        """Counters of the last run of the Model Exchange integrator (None without it)."""
        return None if self._me is None else self._me.stats

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._inst is None

    @property
    def tempdir(self) -> Path | None:
        """The folder the FMU was extracted to, while the session holds one (else None).

        It is this process's extraction of the FMU file, lent to the session until
        :meth:`close`, then to the next session of the same file; it is removed when the
        process exits.
        """
        return self._tempdir

    def __enter__(self) -> FMUSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if getattr(self, "_tempdir", None) is not None or getattr(self, "_inst", None):
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
