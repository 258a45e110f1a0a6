"""Solver fidelity: notice when the FMU's own integrator, not the physics, decides the answer.

Many FMUs ship a cheap fixed-step Co-Simulation solver (forward Euler at 10 ms in the
Modelica Association's Reference-FMUs). Fitted to accurate data, the parameters then
absorb the solver's error, and nothing in the fit says so. :func:`check_fidelity`
simulates one parameter set with the solver the study uses and with a reference, and
compares the difference with the noise in the data, output by output:

- an FMU with both interfaces: the reference is its Model Exchange interface at a tight
  tolerance (:data:`REFERENCE_TOLERANCE`);
- a Co-Simulation-only FMU: the reference is the same FMU at a communication step
  :data:`FINER` times smaller and its own solver at a tight tolerance
  (:data:`CS_REFERENCE_TOLERANCE`, passed as ``fmi2SetupExperiment``'s), and each of
  the FMU's own integration time steps that the study does not identify (a parameter
  in s such as Hopsan's ``timestep``, :func:`~tsid_fmu.scaffold_rules.time_step_setting`)
  :data:`FINER` times smaller, since an FMU-internal fixed step follows neither.

The difference *matters* when its RMS exceeds :data:`THRESHOLD` times an output's noise
(see the constant for why 0.2) or, at the answer, when it alone moves an estimate by more
than :data:`BIAS_LIMIT` standard errors (projected on the sensitivities). Then the check
says so in one line with the figures and proposes a fix, after trying the alternatives
(Model Exchange, a smaller step, a tighter tolerance, the FMU's own smaller time
steps). With ``interface = "auto"`` the
study uses Model Exchange when Co-Simulation's difference matters at the start point and
Model Exchange is closer to the reference (:func:`choose_interface`). A study that
simulates Co-Simulation with no ``cs_tolerance`` of its own uses :data:`CS_TOLERANCE`
when the FMU's default tolerance is what makes the difference matter and that tolerance
removes it (:func:`choose_cs_tolerance`): the FMU's own solver, not the physics, then
limited the answer, and the check says so.

A Co-Simulation-only FMU whose outputs do not settle as the step shrinks is not blamed
(:data:`CONVERGES`): a discrete-time FMU, or one that adds a fixed amount at every
communication step, *is* its step, and a smaller one would make the answer wrong. The
study keeps the data's sample interval and the check says why.

The simulations are those of :mod:`tsid_fmu.uncertainty.solvers` (which also corrects
the Model Exchange reference for inputs held linearly); the noise is each output's known
sensor noise, else its estimate from the data.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence

import numpy as np

from tsid_fmu.errors import SimulationError, TsidError
from tsid_fmu.evaluate.isolated import IsolatedCalls
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.variables import parse_start, variable_info
from tsid_fmu.numerics.tuning import (
    BIAS_LIMIT,
    CONVERGES,
    CS_REFERENCE_TOLERANCE,
    CS_TOLERANCE,
    FINER,
    REFERENCE_TOLERANCE,
)
from tsid_fmu.scaffold_rules import time_step_setting
from tsid_fmu.uncertainty.fidelity_record import (
    THRESHOLD,
    Fidelity,
    chosen_cs_tolerance,
    chosen_interface,
    fidelity_record,
    fidelity_warnings,
    start_point,
    study_noise,
)
from tsid_fmu.uncertainty.sensitivity import Sensitivities
from tsid_fmu.uncertainty.solvers import (
    Deviation,
    Solver,
    SolverRuns,
    available_interfaces,
    compare,
    output_noise,
    solver_bias,
)

__all__ = [
    "BIAS_LIMIT",
    "CS_REFERENCE_TOLERANCE",
    "CS_TOLERANCE",
    "FINER",
    "REFERENCE_TOLERANCE",
    "THRESHOLD",
    "Fidelity",
    "check_fidelity",
    "choose_cs_tolerance",
    "choose_interface",
    "chosen_cs_tolerance",
    "chosen_interface",
    "fidelity_record",
    "fidelity_warnings",
    "start_point",
    "study_noise",
]


NAMES = {"cs": "Co-Simulation", "me": "Model Exchange"}


def _sample_step(spec: EvaluationSpec) -> float:
    return spec.step_size or min(float(np.min(np.diff(e.time))) for e in spec.experiments)


def _tolerance(spec: EvaluationSpec, interface: str) -> float | None:
    return spec.tolerance if interface == "me" else spec.cs_tolerance


def _tight(given: float | None, reference: float) -> float:
    """Return ``reference``, or 100 times tighter than ``given`` (at least 1e-14)."""
    return max(min(reference, 0.01 * (given or 1.0)), 1e-14)


def _plan(
    spec: EvaluationSpec, requested: str, available: tuple[str, ...]
) -> tuple[Solver, Solver]:
    """Return the study's solver and the reference for it."""
    first = requested
    if requested == "auto":  # an FMU without the interface requested fails in FMUSession
        first = "cs" if "cs" in available or not available else available[0]
    used = Solver(first, step=spec.step_size, tolerance=_tolerance(spec, first))
    if "me" in available:
        return used, Solver("me", tolerance=_tight(spec.tolerance, REFERENCE_TOLERANCE))
    tight = _tight(spec.cs_tolerance, CS_REFERENCE_TOLERANCE)
    finer = _sample_step(spec) / FINER
    return used, Solver("cs", step=finer, tolerance=tight, settings=_own_steps(spec))


def _own_steps(spec: EvaluationSpec) -> tuple[tuple[str, float], ...]:
    """Return the FMU's own integration time steps, :data:`FINER` times smaller.

    Those of its parameters in s that :func:`~tsid_fmu.scaffold_rules.time_step_setting`
    names, at the study's value (else the FMU's start value), except those the study
    identifies or sets per experiment.
    """
    try:
        md = read_fmu_description(spec.fmu)
    except TsidError:  # the check's own simulations will say why
        return ()
    skip = set(spec.parameter_names).union(*(e.start_values for e in spec.experiments))
    found = []
    for v in md.modelVariables:
        info = variable_info(v)
        if info.name in skip or not time_step_setting(info):
            continue
        value = spec.start_values.get(info.name, parse_start(info))
        if value is not None and math.isfinite(value) and value > 0:
            found.append((info.name, float(value) / FINER))
    return tuple(found)


def _tighter(spec: EvaluationSpec) -> list[Solver]:
    """Return the study's Co-Simulation at its step at :data:`CS_TOLERANCE`.

    Nothing where the study's own ``cs_tolerance`` is that tight already.
    """
    if spec.cs_tolerance is not None and spec.cs_tolerance <= CS_TOLERANCE:
        return []
    return [_tightened(Solver("cs", step=spec.step_size))]


def _alternatives(
    runs: SolverRuns,
    used: Solver,
    reference: Solver,
    available: tuple[str, ...],
    noise: Sequence[np.ndarray],
    threshold: float,
) -> list[Deviation]:
    """Try the other solvers the study could use instead."""
    spec = runs.spec
    others = []
    if used.interface == "cs" and "me" in available:
        others.append(Solver("me", step=spec.step_size, tolerance=spec.tolerance))
    if used.interface == "me" and "cs" in available:
        others.append(Solver("cs", step=spec.step_size, tolerance=spec.cs_tolerance))
    if used.interface == "cs":  # a smaller step alone, a tighter tolerance alone
        step = reference.step if reference.interface == "cs" else _sample_step(spec) / FINER
        others.append(Solver("cs", step=step, tolerance=spec.cs_tolerance))
        others += _tighter(spec)
        if reference.settings:  # the FMU's own time steps alone
            own = reference.settings
            others.append(
                Solver("cs", step=spec.step_size, tolerance=spec.cs_tolerance, settings=own)
            )
    return [compare(runs, s, reference, noise, threshold) for s in others]


def _figures(dev: Deviation) -> str:
    exp, out, v = dev.worst
    return (
        f"{v['ratio']:.3g} x the noise on {exp} / {out} (RMS difference {v['rms']:.3g}, "
        f"noise {v['noise']:.3g})"
    )


def _setting(solver: Solver, used: Solver) -> str:
    if solver.interface == "me":
        return 'interface = "me"'
    if solver.settings and (solver.step, solver.tolerance) == (used.step, used.tolerance):
        values = ", ".join(f"{n} = {v:g}" for n, v in solver.settings)
        return f"the FMU's own time step smaller, start_values = {{ {values} }}"
    if solver.step != used.step and solver.tolerance == used.tolerance:
        return f"a smaller communication step, step = {solver.step:g} or less"
    parts = [f"step = {solver.step:g}"] if solver.step != used.step else []
    if solver.tolerance is not None and solver.tolerance != used.tolerance:
        parts.append(f"cs_tolerance = {solver.tolerance:g}")
    return " with ".join(parts) or 'interface = "cs"'


def _fix(used: Solver, alternatives: list[Deviation], reference: Solver, threshold: float) -> str:
    """Name the settings that bring the solver within the threshold (or the closest)."""
    ranked = sorted(alternatives, key=lambda d: d.ratio)
    good = [d for d in ranked if d.ratio <= threshold and d.shift <= BIAS_LIMIT]
    named = [(f"{_setting(d.solver, used)} ({d.ratio:.2g} x the noise)", d) for d in good]
    fixes = [f"tolerance = {reference.tolerance:g}"] if used.interface == "me" else []
    fixes += [text for text, d in named if not d.solver.settings]  # keys of [method]
    own = [text for text, d in named if d.solver.settings]  # start values of the FMU
    if fixes and reference.interface == "cs":
        return "fix: " + " or ".join(fixes) + " in [method]" + "".join(f" or {f}" for f in own)
    if fixes:
        return "fix in [method]: " + " or ".join(fixes)
    if own:
        return "fix: " + " or ".join(own)
    if reference.interface == "cs":  # none alone: all, as the reference has them
        method = _setting(Solver("cs", reference.step, reference.tolerance), used)
        values = ", ".join(f"{n} = {v:g}" for n, v in reference.settings)
        also = f" and start_values = {{ {values} }}" if values else ""
        return f"fix: {method} in [method]{also}, as the reference"
    if ranked:
        best = ranked[0]
        return (
            f"closest: {_setting(best.solver, used)} in [method] ({best.ratio:.2g} x the "
            "noise); a smaller step or the FMU's own solver settings may help"
        )
    return "check the FMU's own solver settings"


def check_fidelity(
    spec: EvaluationSpec,
    x: Mapping[str, float],
    *,
    where: str = "start point",
    noise: Mapping[str, Mapping[str, float]] | None = None,
    sensitivities: Sensitivities | None = None,
    threshold: float = THRESHOLD,
    isolate: bool = False,
    time_limit: float | None = None,
    adopt: bool = True,
) -> Fidelity:
    """Compare the study's solver with a reference at ``x`` and choose the interface.

    Parameters
    ----------
    spec : EvaluationSpec
        The study's identification experiments; its ``interface`` (``"auto"``, ``"cs"``
        or ``"me"``), ``step_size`` and ``tolerance`` are the study's solver.
    x : mapping of str to float
        The parameter set (every name of ``spec.parameter_names``).
    where : str
        ``"start point"`` or ``"answer"``, for the message.
    noise : mapping, optional
        Known sensor noise per experiment and output (``Experiment.noise``); the others
        are estimated from the data
        (:func:`~tsid_fmu.uncertainty.solvers.output_noise`).
    sensitivities : Sensitivities, optional
        The sensitivities at ``x`` (at the answer): the difference is then also
        projected on them (:attr:`Fidelity.bias`).
    threshold : float
        Fraction of the noise above which a difference matters.
    isolate : bool
        Run the simulations in a child process (:class:`~tsid_fmu.evaluate.isolated.
        IsolatedCalls`), each under ``time_limit``: an FMU that hangs or crashes then
        leaves the check undone, with the reason, instead of stopping the caller.
    time_limit : float, optional
        With ``isolate``: seconds per simulation (None: no limit).
    adopt : bool
        Let the check adopt :data:`CS_TOLERANCE` for a study without ``cs_tolerance``
        (:func:`choose_cs_tolerance`); False at the answer, which was found already.

    Returns
    -------
    Fidelity
        The figures, the message and the interface to use. A simulation that fails
        leaves the check undone (``used`` None) with the reason in ``message``.

    Raises
    ------
    FMUError
        The FMU cannot be opened for the study's solver.
    """
    t0 = time.perf_counter()
    available = available_interfaces(spec)
    used, reference = _plan(spec, spec.interface, available)
    out = Fidelity(where, dict(x), spec.interface, used.interface, threshold=threshold)
    out.step, out.cs_tolerance = spec.step_size, spec.cs_tolerance
    sigma = [output_noise(e, (noise or {}).get(e.name)) for e in spec.experiments]
    calls = IsolatedCalls(time_limit, spec.fmu.name) if isolate else None
    runs = SolverRuns(spec, x, calls)
    try:
        _compare(out, runs, (used, reference), available, sigma, sensitivities)
        chosen = choose_interface(out)
        if adopt:
            choose_cs_tolerance(out)
        out.message = _message(out, chosen)
    except TsidError as exc:
        if not isinstance(exc, SimulationError) and not runs.count:
            raise
        out.reference, out.used, out.matters = None, None, False
        out.message = f"solver fidelity ({where}): not checked, a simulation failed: {exc}"
    finally:
        if calls is not None:
            calls.close()
        out.simulations, out.seconds = runs.count, time.perf_counter() - t0
    return out


def _compare(
    out: Fidelity,
    runs: SolverRuns,
    solvers: tuple[Solver, Solver],
    available: tuple[str, ...],
    sigma: Sequence[np.ndarray],
    sensitivities: Sensitivities | None,
) -> None:
    """Compare the study's solver with the reference; where it matters, the alternatives."""
    used, reference = solvers
    out.used = compare(runs, used, reference, sigma, out.threshold)
    out.reference = reference
    if sensitivities is not None:
        out.bias = solver_bias(out.used, sensitivities)
    out.matters = out.used.ratio > out.threshold or max(out.bias.values(), default=0) > BIAS_LIMIT
    if out.matters and reference.interface == "cs":
        _convergence(out, runs, reference, sigma)
    if out.matters:  # (a Co-Simulation-only FMU: one that converges)
        tried = _alternatives(runs, used, reference, available, sigma, out.threshold)
        for d in tried if sensitivities is not None else ():  # a fix must remove the shift too
            d.shift = max(solver_bias(d, sensitivities).values(), default=0.0)
        out.alternatives += tried


def _convergence(
    out: Fidelity, runs: SolverRuns, reference: Solver, sigma: Sequence[np.ndarray]
) -> None:
    """Decide whether a Co-Simulation-only FMU converges as its step shrinks (:data:`CONVERGES`).

    One more simulation, at a step :data:`FINER` times smaller than the reference's; a
    difference that does not fall is the FMU's design, not a solver error.
    """
    assert out.used is not None
    finer = compare(runs, reference, _finer(reference), sigma, out.threshold)
    out.alternatives = [finer]
    out.converges = finer.ratio <= CONVERGES * out.used.ratio
    out.matters = out.converges


def _finer(solver: Solver) -> Solver:
    """Return ``solver`` with its step and its FMU's own time steps :data:`FINER` times smaller."""
    settings = tuple((n, v / FINER) for n, v in solver.settings)
    return Solver("cs", (solver.step or 0.0) / FINER, solver.tolerance, settings)


def _candidates(check: Fidelity) -> list[Deviation]:
    """Return the alternatives tried as fixes (not the convergence test's finer pair)."""
    return check.alternatives[1:] if check.converges is not None else check.alternatives


def choose_cs_tolerance(check: Fidelity) -> float | None:
    """Return the FMU's Co-Simulation tolerance to use: :data:`CS_TOLERANCE` where it helps.

    Sets ``check.cs_tolerance``. A study that simulates Co-Simulation without a
    ``cs_tolerance`` of its own adopts :data:`CS_TOLERANCE` where the difference matters
    and that tolerance alone, at the study's step, brings it within the threshold: the
    FMU's own solver at its default tolerance limited the answer. A tighter tolerance
    costs every simulation time, so one that only narrows the difference is proposed, not
    adopted; a ``cs_tolerance`` the study gives is kept (the check warns with the fix).
    """
    used = check.used
    if check.interface == "cs" and check.matters and used is not None:
        if used.solver.interface == "cs" and used.solver.tolerance is None:
            tight = [d for d in _candidates(check) if d.solver == _tightened(used.solver)]
            if tight and tight[0].ratio <= check.threshold:
                check.cs_tolerance = CS_TOLERANCE
    return check.cs_tolerance


def _tightened(solver: Solver) -> Solver:
    """Return ``solver``'s Co-Simulation at :data:`CS_TOLERANCE` (the one candidate)."""
    return Solver("cs", step=solver.step, tolerance=CS_TOLERANCE)


def choose_interface(check: Fidelity) -> str:
    """Return the interface to use: with ``"auto"``, Model Exchange when it is closer.

    Sets ``check.interface``. Model Exchange replaces Co-Simulation only where the
    Co-Simulation's difference matters and Model Exchange's is smaller.
    """
    if check.requested == "auto" and check.matters and check.used is not None:
        me = [d for d in check.alternatives if d.solver.interface == "me"]
        if me and me[0].ratio < check.used.ratio:
            check.interface = "me"
    return check.interface


def _shift(bias: Mapping[str, float]) -> str:
    if not bias:
        return ""
    name = max(bias, key=lambda n: bias[n])
    return f"; it alone moves {name} by {bias[name]:.2g} standard errors"


def _message(check: Fidelity, chosen: str) -> str:
    used, ref = check.used, check.reference
    assert used is not None and ref is not None
    head = f"solver fidelity ({check.where}): {used.solver.label}"
    if check.converges is False:
        finer = _finer(ref)
        return (
            f"{head} differs from {ref.label} by {used.ratio:.3g} x the noise, and that from "
            f"{finer.label} by {check.alternatives[0].ratio:.3g} x: the outputs do not converge as "
            "the communication step shrinks, so they depend on the step by design (a "
            "discrete-time FMU, or one that acts once per step); this is no solver error, "
            "and the study keeps its step. Make sure the data were sampled at the step the "
            "FMU is meant to run at"
        )
    if not check.matters:
        return (
            f"{head} matches {ref.label} to {used.ratio:.2g} x the noise "
            f"(threshold {check.threshold:g}){_shift(check.bias)}"
        )
    text = (
        f"{head} differs from {ref.label} by {_figures(used)}{_shift(check.bias)}: the "
        "parameters absorb the solver's error"
    )
    if chosen != used.solver.interface:
        me = next(d for d in check.alternatives if d.solver.interface == chosen)
        return (
            f'{text}; interface = "auto" uses {NAMES[chosen]} instead ({me.ratio:.2g} x the noise)'
        )
    if check.adopted:
        tight = next(d for d in check.alternatives if d.solver == _tightened(used.solver))
        return (
            f"{text}: the FMU's own solver at its default tolerance, not the physics, limits "
            f"the answer; the study passes cs_tolerance = {check.cs_tolerance:g} instead "
            f"({tight.ratio:.2g} x the noise)"
        )
    return f"{text}; {_fix(used.solver, _candidates(check), ref, check.threshold)}"
