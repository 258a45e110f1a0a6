"""Where the simulations run: one parameter set over every experiment and replicate.

:class:`SetRunner` owns one :class:`~tsid_fmu.fmu.FMUSession` per experiment
(extracted and instantiated once, reset between runs). Every evaluator runs a parameter
set through exactly this code -- in its own process, in a local worker process or on a
Dask worker -- so a set's costs, residuals, error and simulation count are the same bits
wherever it ran.

The order is fixed: experiments in spec order, and within one its replicates, replicate 1
(the measured inputs) first. The first failure ends the set: the remaining simulations of
the set are not run, its costs are all ``inf``, and the reason is
``"<experiment>: <message>"``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from tsid_fmu.errors import TsidError
from tsid_fmu.evaluate.cost import Cost
from tsid_fmu.evaluate.protocol import Simulated
from tsid_fmu.evaluate.spec import EvaluationSpec, PreparedExperiment
from tsid_fmu.fmu import FMUSession
from tsid_fmu.fmu.compiled import warm_up
from tsid_fmu.fmu.delay import delay_input, delayed_inputs, split_delays

__all__ = [
    "Job",
    "Monitor",
    "OnResult",
    "SetResult",
    "SetRunner",
    "SimResult",
    "failed_result",
    "warm_up",
]

REUSE_PER_EXPERIMENT = 8
"""Outputs kept per experiment for reuse (only where the spec has per-experiment copies)."""

Job = tuple[str, dict[str, float], bool]
"""``(kind, parameters, full)``: kind ``"run"`` scores a set (:meth:`SetRunner.run`;
``full=False``: the measured inputs only), ``"sim"`` simulates it on the measured inputs
(:meth:`SetRunner.simulate`)."""


@dataclass
class SetResult:
    """What scoring one parameter set gave.

    Attributes
    ----------
    costs : numpy.ndarray
        Shape ``(n_replicates,)``; all ``inf`` when the set failed. Only column 0 is
        computed when only the measured inputs were asked for.
    error : str or None
        ``"<experiment>: <message>"`` of the first failure.
    residuals : numpy.ndarray or None
        Scaled residuals on the measured inputs (read-only float64), None if failed.
    nfev : int
        Simulations started for this set (the failed one included).
    durations : list of float
        Seconds each successful simulation took.
    printed : str
        What the FMU printed natively in the set's simulations (:mod:`tsid_fmu.fmu.native`),
        each run's text after a line naming its experiment and replicate; '' if nothing.
    """

    costs: np.ndarray
    error: str | None
    residuals: np.ndarray | None
    nfev: int
    durations: list[float] = field(default_factory=list)
    printed: str = ""


@dataclass
class SimResult:
    """What simulating one parameter set on the measured inputs gave."""

    simulated: list[Simulated]
    nfev: int
    durations: list[float] = field(default_factory=list)
    printed: str = ""


OnResult = Callable[[int, SetResult | SimResult], None]
"""``on_result(job index, result)``: called as each job of a batch finishes."""


class Monitor(Protocol):
    """Told when each simulation starts and ends (a worker's watchdog reads it)."""

    def started(self, experiment: int, replicate: int, count: int) -> None:
        """Note that simulation ``count`` of the set starts (``experiment``, ``replicate``)."""

    def finished(self) -> None:
        """Note that the simulation that started last has returned."""


class _NoMonitor:
    def started(self, experiment: int, replicate: int, count: int) -> None:
        pass

    def finished(self) -> None:
        pass


class SetRunner:
    """Score parameter sets of a spec in this process, one :class:`FMUSession` per experiment.

    Parameters
    ----------
    spec : EvaluationSpec
        What to simulate and how to score it.
    monitor : Monitor, optional
        Told about every simulation (worker processes publish it for their parent).

    Raises
    ------
    FMUError
        An FMU session cannot be opened (file, platform, variable names).
    """

    def __init__(self, spec: EvaluationSpec, monitor: Monitor | None = None) -> None:
        self.spec = spec
        self.monitor: Monitor = monitor or _NoMonitor()
        self.cost = Cost(spec.cost)
        self.n_replicates = spec.n_replicates
        self.plans = [e.replicate_plan(self.n_replicates) for e in spec.experiments]
        self.started = 0  # simulations started for the current set
        self.printed: list[str] = []  # what the FMU printed in the current set's runs
        # with per-experiment copies: each experiment's latest outputs, by its own values
        copies = any(e.copies for e in spec.experiments)
        self.reuse: dict[tuple, np.ndarray] | None = {} if copies else None
        self.sessions: list[FMUSession] = []  # variant-major: variant k, experiment e
        self.fixed_delays: list[dict[str, float]] = []  # per experiment, by input name
        variants = spec.variants
        try:
            for k in range(1 if variants is None else len(variants.fmus)):
                for i, e in enumerate(spec.experiments):
                    self.sessions.append(self._open(k, i, e))
        except BaseException:
            self.close()
            raise

    def _open(self, k: int, i: int, e: PreparedExperiment) -> FMUSession:
        """Open experiment ``i``'s session of variant ``k`` (the spec's FMU without variants)."""
        spec, variants = self.spec, self.spec.variants
        # the shared parameters and this experiment's own copies, by FMU variable
        names = [n for n in spec.experiment_parameters(i) if delay_input(n) is None]
        start, delays = split_delays({**spec.start_values, **e.start_values})
        fmu = spec.fmu
        if variants is not None:  # only what this variant has (the choice is none of it)
            fmu, names = variants.fmus[k], variants.names(k, names)
            start = variants.keep(k, start)
        if k == 0:
            self.fixed_delays.append(delays)
        options: dict = {"hold": dict(e.hold)} if e.hold else {}
        return FMUSession(
            fmu,
            inputs=e.input_names,
            outputs=e.output_names,
            parameters=names,
            interface=spec.interface,  # type: ignore[arg-type]
            step_size=spec.step_size,
            tolerance=spec.tolerance,
            cs_tolerance=spec.cs_tolerance,
            fresh=spec.fresh,
            start_values=start,
            capture_output=True,
            **options,
        )

    def _simulate(self, e: int, r: int, params: Mapping[str, float]) -> np.ndarray:
        experiment = self.spec.experiments[e]
        # only a study with per-experiment copies maps the set per experiment (the
        # per-row hot path of every other study stays as it was)
        own = params if self.reuse is None else self.spec.experiment_values(e, params)
        key = (e, r, tuple(own.items())) if self.reuse is not None else None
        if key is not None and key in self.reuse:
            # the same values for this experiment as a recent set: another experiment's
            # copy moved (the Jacobian's block-sparse columns), not this one's inputs
            self.reuse[key] = self.reuse.pop(key)
            return self.reuse[key].copy()
        session = self.sessions[e]
        variants = self.spec.variants
        if variants is not None:  # the variant the set (or a fixed value) names
            k = variants.index({**self.spec.start_values, **params})
            session = self.sessions[k * len(self.spec.experiments) + e]
            own = variants.keep(k, own)
        self.started += 1
        self.monitor.started(e, r, self.started)
        values, delays = split_delays(own)
        inputs = delayed_inputs(
            experiment.time,
            experiment.replicate_inputs(r),
            experiment.input_names,
            {**self.fixed_delays[e], **delays},
        )
        try:
            y = session.simulate(experiment.time, inputs, values)
        finally:
            self.monitor.finished()
            if session.printed.strip():
                self.printed.append(f"-- {experiment.name}, replicate {r + 1}:\n{session.printed}")
        if key is not None and self.reuse is not None:
            self.reuse[key] = y.copy()
            while len(self.reuse) > REUSE_PER_EXPERIMENT * len(self.sessions):
                del self.reuse[next(iter(self.reuse))]
        return y

    def run(self, params: Mapping[str, float], full: bool = True) -> SetResult:
        """Score one parameter set (``full=False``: the measured inputs only).

        Failures of the FMU (:class:`~tsid_fmu.errors.TsidError`) end the set and are
        returned; any other exception propagates.
        """
        self.started, self.printed = 0, []
        costs = np.zeros(self.n_replicates)
        residuals: list[np.ndarray] = []
        durations: list[float] = []
        for e, (experiment, plan) in enumerate(zip(self.spec.experiments, self.plans, strict=True)):
            values: list[float] = []
            for r in range(self.n_replicates if full else 1):
                if plan[r] != r:  # the same inputs as an earlier replicate: the same cost
                    values.append(values[plan[r]])
                    continue
                t0, before = time.monotonic(), self.started
                try:
                    y = self._simulate(e, r, params)
                except TsidError as exc:
                    costs[:] = math.inf
                    reason = f"{experiment.name}: {exc}"
                    return SetResult(costs, reason, None, self.started, [], self._printed())
                if self.started > before:  # not reused: its time counts
                    durations.append(time.monotonic() - t0)
                per_output = experiment.output_costs(self.cost, y)
                value = float(np.dot(per_output, experiment.weights))
                values.append(value if math.isfinite(value) else math.inf)
                if r == 0:  # y is this run's own array: scaled in place, no copy
                    np.subtract(y, experiment.measured, out=y)
                    np.divide(y, experiment.scale, out=y)
                    residuals.append(experiment.weighted(y).reshape(-1))
            costs[: len(values)] += values
        out = residuals[0] if len(residuals) == 1 else np.concatenate(residuals)
        out.flags.writeable = False
        return SetResult(costs, None, out, self.started, durations, self._printed())

    def simulate(self, params: Mapping[str, float]) -> SimResult:
        """Simulate every experiment on its measured inputs (each one even if another fails)."""
        self.started, self.printed = 0, []
        out: list[Simulated] = []
        durations: list[float] = []
        for e, experiment in enumerate(self.spec.experiments):
            t0, before = time.monotonic(), self.started
            try:
                y = self._simulate(e, 0, params)
            except TsidError as exc:
                out.append(Simulated(experiment.name, None, str(exc)))
                continue
            if self.started > before:
                durations.append(time.monotonic() - t0)
            y.flags.writeable = False
            out.append(Simulated(experiment.name, y, None))
        return SimResult(out, self.started, durations, self._printed())

    def _printed(self) -> str:
        return "\n".join(self.printed)

    def run_job(self, job: Job) -> SetResult | SimResult:
        """Run a :data:`Job`: :meth:`run` or :meth:`simulate`."""
        kind, params, full = job
        return self.simulate(params) if kind == "sim" else self.run(params, full)

    def close(self) -> None:
        """Free the FMU sessions (instances and extracted folders)."""
        for s in self.sessions:
            try:
                s.close()
            except TsidError:
                pass
        self.sessions = []


def failed_result(
    spec: EvaluationSpec,
    kind: str,
    reason: str,
    *,
    nfev: int = 0,
    where: tuple[int, int] | None = None,
) -> SetResult | SimResult:
    """Return the result of a job that did not finish (worker crashed, time limit, lost).

    Parameters
    ----------
    spec : EvaluationSpec
        The evaluation.
    kind : {"run", "sim"}
        Scoring (:meth:`SetRunner.run`) or simulating (:meth:`SetRunner.simulate`).
    reason : str
        What happened.
    nfev : int
        Simulations the task had started.
    where : tuple of int, optional
        ``(experiment, replicate)`` of the simulation that was running, if known.
    """
    prefix = ""
    if where is not None:
        e, r = where
        prefix = f"{spec.experiments[e].name}: "
        if spec.n_replicates > 1:
            prefix += f"replicate {r + 1}: "
    if kind == "sim":
        return SimResult([Simulated(x.name, None, reason) for x in spec.experiments], nfev, [])
    costs = np.full(spec.n_replicates, math.inf)
    return SetResult(costs, prefix + reason, None, nfev, [])
