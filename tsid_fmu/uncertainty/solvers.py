"""One parameter set simulated by several solvers, and how far apart they lie.

The building blocks of the fidelity check (:mod:`tsid_fmu.uncertainty.fidelity`): a
:class:`Solver` (interface, step, tolerance), :class:`SolverRuns` that simulates a spec's
experiments with any of them (each run in a fresh :class:`~tsid_fmu.fmu.FMUSession`,
remembered), :func:`compare` that measures a solver's RMS difference from a reference
against each output's noise, and :func:`solver_bias`, the shift of the estimates that such
a difference causes, in standard errors.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.errors import SimulationError
from tsid_fmu.evaluate.isolated import IsolatedCalls
from tsid_fmu.evaluate.spec import EvaluationSpec, PreparedExperiment
from tsid_fmu.fmu.delay import delayed_inputs, split_delays
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.native import record
from tsid_fmu.fmu.session import FMUSession
from tsid_fmu.study.prepare import NOISE_FLOOR, data_noise
from tsid_fmu.uncertainty.sensitivity import Sensitivities

__all__ = [
    "Deviation",
    "Solver",
    "SolverRuns",
    "available_interfaces",
    "compare",
    "output_noise",
    "simulate_solver",
    "solver_bias",
]


@dataclass(frozen=True)
class Solver:
    """One way of simulating the FMU.

    Parameters
    ----------
    interface : {"cs", "me"}
        Co-Simulation or Model Exchange.
    step : float, optional
        Co-Simulation: largest communication step (None: the sample interval). Model
        Exchange: the step hint.
    tolerance : float, optional
        Relative tolerance (None: the solver's default): Model Exchange's integrator's,
        or the Co-Simulation FMU's own solver's (``cs_tolerance``, passed to
        ``fmi2SetupExperiment`` / ``fmi3EnterInitializationMode``).
    settings : tuple of (str, float), optional
        FMU parameters of its own numerics set for this solver, over the study's values
        (the Co-Simulation reference's smaller internal time steps,
        :func:`~tsid_fmu.scaffold_rules.time_step_setting`).
    """

    interface: str
    step: float | None = None
    tolerance: float | None = None
    settings: tuple[tuple[str, float], ...] = ()

    @property
    def label(self) -> str:
        """Describe the solver in words (``Co-Simulation at step 0.01 s``)."""
        if self.interface == "cs":
            step = f"step {self.step:g} s" if self.step else "the data's sample interval"
            tol = f", tolerance {self.tolerance:g}" if self.tolerance else ""
            own = "".join(f", {n} = {v:g}" for n, v in self.settings)
            return f"Co-Simulation at {step}{tol}{own}"
        tol = f"tolerance {self.tolerance:g}" if self.tolerance else "its default tolerance"
        return f"Model Exchange at {tol}"


@dataclass
class Deviation:
    """How far one solver's outputs lie from the reference, relative to the noise.

    Attributes
    ----------
    solver : Solver
        The solver compared.
    outputs : dict
        ``{experiment: {output: {"rms": ..., "noise": ..., "ratio": rms / noise}}}``.
    differences : list of numpy.ndarray
        ``solver - reference`` per experiment, ``(n, outputs)`` (not serialised).
    shift : float
        The largest shift of an estimate the difference alone causes, in standard
        errors (:func:`solver_bias`), where the sensitivities are known; else 0.
    """

    solver: Solver
    outputs: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    differences: list[np.ndarray] = field(default_factory=list, repr=False)
    shift: float = 0.0

    @property
    def worst(self) -> tuple[str, str, dict[str, float]]:
        """Return the experiment, output and figures with the largest ratio."""
        rows = [(e, o, v) for e, per in self.outputs.items() for o, v in per.items()]
        return max(rows, key=lambda r: r[2]["ratio"])

    @property
    def ratio(self) -> float:
        """The largest RMS difference over noise of any output."""
        return self.worst[2]["ratio"] if self.outputs else 0.0

    def to_dict(self) -> dict[str, Any]:
        """Return strict-JSON data."""
        s = self.solver
        return {
            "solver": s.label,
            "interface": s.interface,
            "step": s.step,
            "tolerance": s.tolerance,
            **({"settings": dict(s.settings)} if s.settings else {}),
            "ratio": self.ratio,
            "outputs": self.outputs,
        }


def available_interfaces(spec: EvaluationSpec) -> tuple[str, ...]:
    """Return the interfaces the spec's FMU (every variant) declares, Co-Simulation first."""
    paths = spec.variants.fmus if spec.variants is not None else (spec.fmu,)
    mds = [read_fmu_description(p) for p in paths]
    kinds = (("cs", "coSimulation"), ("me", "modelExchange"))
    return tuple(k for k, attr in kinds if all(getattr(md, attr) for md in mds))


def output_noise(
    experiment: PreparedExperiment, given: Mapping[str, float] | None = None
) -> np.ndarray:
    """Return each output's noise: the given sensor noise, else the data's estimate.

    An output that shows no noise gets :data:`~tsid_fmu.study.prepare.NOISE_FLOOR` times
    its RMS value, as the residual scales of a study do.
    """
    y = experiment.scored(experiment.measured)
    given = given or {}
    names, estimate = experiment.output_names, data_noise(y)
    sigma = np.array([given.get(n, s) for n, s in zip(names, estimate, strict=True)])
    quiet = ~(sigma > 1e-6 * np.maximum(np.ptp(y, axis=0), 1e-300))
    rms = np.sqrt(np.mean(y**2, axis=0))
    return np.where(quiet, np.maximum(NOISE_FLOOR * rms, 1e-300), sigma)


def _finer_grid(
    e: PreparedExperiment, u: np.ndarray | None, k: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """Split the sample grid ``k`` times: linear inputs interpolated, the others held."""
    t = e.time
    j = np.arange(k) / k
    fine = np.append((t[:-1, None] + np.diff(t)[:, None] * j[None, :]).ravel(), t[-1])
    if u is None:
        return fine, None
    held = u[np.minimum(np.searchsorted(t, fine, side="right") - 1, t.size - 1)]
    for c, name in enumerate(e.input_names):
        if e.hold.get(name) == "linear":
            held[:, c] = np.interp(fine, t, u[:, c])
    return fine, held


def _fidelity_text(solver: Solver, printed: str) -> str:
    """Return what a fidelity run printed, headed by its solver ('' if nothing)."""
    return f"[solver fidelity check, {solver.label}]\n{printed}" if printed.strip() else ""


def simulate_solver(
    spec: EvaluationSpec, x: Mapping[str, float], solver: Solver, index: int, k: int, held: bool
) -> np.ndarray:
    """Return experiment ``index``'s outputs at ``x`` with ``solver`` (see SolverRuns.run).

    Module-level, so that it can run in a child process (:class:`SolverRuns` with a
    time limit).
    """
    e = spec.experiments[index]
    start, fixed = split_delays({**spec.start_values, **e.start_values})
    start.update(solver.settings)  # the solver's own numerics, over the study's values
    values, delays = split_delays(spec.experiment_values(index, x))
    fmu, variants = spec.fmu, spec.variants
    if variants is not None:  # the variant the set names, with the values it has
        v = variants.index({**spec.start_values, **x})
        fmu, start, values = variants.fmus[v], variants.keep(v, start), variants.keep(v, values)
    u = delayed_inputs(e.time, e.inputs, e.input_names, {**fixed, **delays})
    t, u = (e.time, u) if k == 1 else _finer_grid(e, u, k)
    with FMUSession(
        fmu,
        e.input_names,
        e.output_names,
        parameters=list(values),
        interface=solver.interface,  # type: ignore[arg-type]
        step_size=solver.step,
        start_values=start,
        hold={} if held else dict(e.hold),
        tolerance=solver.tolerance if solver.interface == "me" else None,
        cs_tolerance=solver.tolerance if solver.interface == "cs" else None,
        capture_output=True,  # as every run of a study: echoed, capped, on record
    ) as session:
        try:
            return session.simulate(t, u, values)[::k]
        finally:
            record(x, _fidelity_text(solver, session.printed))


class SolverRuns:
    """Simulate a spec's experiments at one parameter set, by solver; count and remember.

    Parameters
    ----------
    spec : EvaluationSpec
        The FMU, experiments and fixed values.
    x : mapping of str to float
        The parameter set.
    calls : IsolatedCalls, optional
        Run each simulation in this child process, under its time limit (a simulation
        that hangs or crashes raises :class:`~tsid_fmu.errors.SimulationError`); default
        in this process, without a limit.
    """

    def __init__(
        self, spec: EvaluationSpec, x: Mapping[str, float], calls: IsolatedCalls | None = None
    ) -> None:
        self.spec, self.x = spec, dict(x)
        self.calls = calls
        self.count = 0
        self.cache: dict[tuple[Solver, int, int, bool], np.ndarray] = {}

    def run(self, solver: Solver, index: int, k: int = 1, held: bool = False) -> np.ndarray:
        """Return experiment ``index``'s outputs, on its sample grid split ``k`` times.

        ``held=True`` holds every input between samples, whatever the experiment's
        ``hold``.
        """
        key = (solver, index, k, held)
        if key not in self.cache:
            args = (self.spec, self.x, solver, index, k, held)
            try:
                if self.calls is None:
                    self.cache[key] = simulate_solver(*args)
                else:
                    self.cache[key] = self.calls.call(simulate_solver, *args)
            except SimulationError:  # it ran (an FMU that cannot be opened did not)
                self.count += 1
                raise
            self.count += 1
        return self.cache[key]


def _rms(a: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(a**2, axis=0))


def _difference(
    runs: SolverRuns, solver: Solver, reference: Solver, i: int, limit: np.ndarray
) -> np.ndarray:
    """Return ``solver - reference`` on experiment ``i`` (see :func:`compare`)."""
    e = runs.spec.experiments[i]
    linear = any(e.hold.get(n) == "linear" for n in e.input_names)
    if not (reference.interface == "me" and linear):
        return runs.run(solver, i) - runs.run(reference, i)
    if solver.interface == "cs":
        # the integrators compared on the same held inputs: cheap, and exact for both
        d = runs.run(solver, i, held=True) - runs.run(reference, i, held=True)
        if not np.any(_rms(d) > limit):
            return d
    ref = runs.run(reference, i)
    ref = 2.0 * runs.run(reference, i, 2) - ref
    return runs.run(solver, i) - ref


def compare(
    runs: SolverRuns,
    solver: Solver,
    reference: Solver,
    noise: Sequence[np.ndarray],
    threshold: float,
) -> Deviation:
    """Compare ``solver`` with ``reference`` on every experiment of ``runs``.

    FMPy's Model Exchange loop holds inputs constant over each solver call, so a
    reference in Model Exchange is first order in the sample interval for inputs held
    linearly between samples. For such an experiment a Co-Simulation is first compared
    with the reference on held inputs (the same piecewise-constant inputs for both, so
    the difference is the integrators'); where that difference exceeds ``threshold``
    times the noise, and for a Model Exchange solver, the solver runs on the study's
    inputs and the reference is extrapolated from the sample grid and a twice finer one
    (Richardson, about three times the cost), so that a Co-Simulation that interpolates
    its inputs exactly is not blamed.
    """
    out = Deviation(solver)
    for i, e in enumerate(runs.spec.experiments):
        # the samples the windows score, weighted as the residuals are (solver_bias)
        d = e.weighted(_difference(runs, solver, reference, i, threshold * noise[i]))
        out.differences.append(d)
        out.outputs[e.name] = {
            n: {"rms": float(r), "noise": float(s), "ratio": float(r / s)}
            for n, r, s in zip(e.output_names, _rms(d), noise[i], strict=True)
        }
    return out


def solver_bias(deviation: Deviation, sens: Sensitivities) -> dict[str, float]:
    """Return the shift of each estimate that the solver's difference causes, in SEs.

    The least-squares estimate moves by ``(J^T J)^-1 J^T d`` when the model's outputs are
    off by ``d``, with ``J`` and ``d`` whitened by each output's residual RMS as the
    intervals are (:mod:`tsid_fmu.uncertainty.intervals`); divided by the standard
    errors. Parameters the data do not determine are left out.
    """
    blocks, rows = [], []
    for r, jac_e, diff in zip(sens.residuals, sens.jacobian, deviation.differences, strict=True):
        sigma = _rms(r)
        sigma = np.where(sigma > 0, sigma, 1.0)
        blocks.append((jac_e / sigma[None, :, None]).reshape(-1, jac_e.shape[-1]))
        rows.append((diff / sigma[None, :]).ravel())
    jac, d = np.vstack(blocks), np.concatenate(rows)
    fisher = jac.T @ jac
    try:
        cov = np.linalg.inv(fisher)
    except np.linalg.LinAlgError:
        return {}
    shift = cov @ (jac.T @ d)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return {
        n: float(abs(s) / e)
        for n, s, e in zip(sens.names, shift, se, strict=True)
        if np.isfinite(e) and e > 0 and np.isfinite(s)
    }
