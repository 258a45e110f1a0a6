"""Solver fidelity: notice when the FMU's own integrator, not the physics, decides the answer.

Many FMUs ship a cheap fixed-step Co-Simulation solver (forward Euler at 10 ms in the
Modelica Association's Reference-FMUs). Fitted to accurate data, the parameters then
absorb the solver's error, and nothing in the fit says so. :func:`check_fidelity`
simulates one parameter set with the solver the study uses and with a reference, and
compares the difference with the noise in the data, output by output:

- an FMU with both interfaces: the reference is its Model Exchange interface at a tight
  tolerance (:data:`REFERENCE_TOLERANCE`);
- a Co-Simulation-only FMU: the reference is the same FMU at a communication step
  :data:`FINER` times smaller (this cannot see an FMU-internal fixed step that does not
  follow the communication step).

The difference *matters* when its RMS exceeds :data:`THRESHOLD` times an output's noise
(see the constant for why 0.2) or, at the answer, when it alone moves an estimate by more
than :data:`BIAS_LIMIT` standard errors (projected on the sensitivities). Then the check
says so in one line with the figures and proposes a fix, after trying the alternatives
(Model Exchange, a smaller step, a tighter tolerance). With ``interface = "auto"`` the
study uses Model Exchange when Co-Simulation's difference matters at the start point and
Model Exchange is closer to the reference (:func:`choose_interface`).

A Co-Simulation-only FMU whose outputs do not settle as the step shrinks is not blamed
(:data:`CONVERGES`): a discrete-time FMU, or one that adds a fixed amount at every
communication step, *is* its step, and a smaller one would make the answer wrong. The
study keeps the data's sample interval and the check says why.

The simulations are those of :mod:`tsid_fmu.uncertainty.solvers` (which also corrects
the Model Exchange reference for inputs held linearly); the noise is each output's known
sensor noise, else its estimate from the data.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.errors import SimulationError, TsidError
from tsid_fmu.evaluate.isolated import IsolatedCalls
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.numerics.space import Space
from tsid_fmu.study.definition import Study
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
    "FINER",
    "REFERENCE_TOLERANCE",
    "THRESHOLD",
    "Fidelity",
    "check_fidelity",
    "choose_interface",
    "chosen_interface",
    "fidelity_record",
    "fidelity_warnings",
    "start_point",
    "study_noise",
]

THRESHOLD = 0.2
"""A solver's RMS difference from the reference above this fraction of an output's
noise matters: the error is then a visible part of the residuals (it adds 0.2**2 = 4 % to
the least-squares cost at the true parameters, more above). A smaller error can still
move a parameter whose sensitivity resembles it, by up to ``ratio * sqrt(n)`` standard
errors over ``n`` samples; at the answer the check therefore also projects the error on
the sensitivities (:data:`BIAS_LIMIT`)."""

BIAS_LIMIT = 1.0
"""At the answer, a solver error that alone moves an estimate by more than this many
standard errors matters too (the 95 % intervals would no longer cover the truth 95 % of
the time)."""

REFERENCE_TOLERANCE = 1e-12
"""Relative tolerance of the Model Exchange reference, 100 times tighter than a study's
default (:class:`~tsid_fmu.study.schema.Method` ``tolerance``). FMPy's CVode takes this
times each state's nominal value (often 1) as the absolute tolerance, so a state of
micrometres needs a relative tolerance far below its noise; 1e-12 costs about 30 % more
time than 1e-10 on the bundled FMUs. A study with a tighter tolerance of its own gets a
reference 100 times tighter still (down to 1e-14)."""

FINER = 4
"""The Co-Simulation reference of a Co-Simulation-only FMU uses a communication step this
many times smaller than the study's."""

CONVERGES = 0.5
"""A Co-Simulation-only FMU converges as its step shrinks when the difference between
the steps ``h / FINER`` and ``h / FINER**2`` is at most this fraction of the difference
between ``h`` and ``h / FINER`` (worst output, in noise units). A consistent method of
order ``p`` gives ``FINER**-p`` (0.25 for explicit Euler), once in its asymptotic range;
an FMU that adds a fixed amount per step gives ``FINER`` (4)."""

NAMES = {"cs": "Co-Simulation", "me": "Model Exchange"}


@dataclass
class Fidelity:
    """What :func:`check_fidelity` found at one parameter set.

    Attributes
    ----------
    where : str
        ``"start point"`` or ``"answer"``.
    x : dict
        The parameter set simulated.
    requested : str
        The study's interface (``"auto"``, ``"cs"`` or ``"me"``).
    interface : str
        The interface the study uses after the check (``"cs"`` or ``"me"``).
    reference : Solver or None
        The reference solution's solver (None: nothing to compare with).
    used : Deviation or None
        The study's solver against the reference.
    alternatives : list of Deviation
        Other solvers tried because the difference mattered.
    threshold : float
        :data:`THRESHOLD`.
    matters : bool
        The study's solver differs from the reference by more than the threshold, or
        its difference moves an estimate by more than :data:`BIAS_LIMIT` standard
        errors.
    bias : dict
        At the answer: how many standard errors the difference moves each estimate
        (:func:`~tsid_fmu.uncertainty.solvers.solver_bias`); empty at the start point.
    message : str
        One line with the figures (and the fix when it matters).
    simulations : int
        Simulations the check ran.
    seconds : float
        Their wall time.
    step : float or None
        The study's step (None: the data's sample interval).
    converges : bool or None
        A Co-Simulation-only FMU whose difference mattered: whether its outputs
        settle as the step shrinks (:data:`CONVERGES`); None when not tested.
    """

    where: str
    x: dict[str, float]
    requested: str
    interface: str
    reference: Solver | None = None
    used: Deviation | None = None
    alternatives: list[Deviation] = field(default_factory=list)
    threshold: float = THRESHOLD
    matters: bool = False
    bias: dict[str, float] = field(default_factory=dict)
    message: str = ""
    simulations: int = 0
    seconds: float = 0.0
    step: float | None = None
    converges: bool | None = None

    @property
    def checked(self) -> bool:
        """True when the comparison ran (no simulation failed)."""
        return self.used is not None

    @property
    def switched(self) -> bool:
        """True when ``"auto"`` chose another interface than the first one tried."""
        return self.used is not None and self.interface != self.used.solver.interface

    def to_dict(self) -> dict[str, Any]:
        """Return strict-JSON data (for ``result.json``)."""
        return {
            "where": self.where,
            "x": self.x,
            "requested": self.requested,
            "interface": self.interface,
            "step": self.step,
            "reference": self.reference.label if self.reference else None,
            "used": self.used.to_dict() if self.used else None,
            "alternatives": [a.to_dict() for a in self.alternatives],
            "threshold": self.threshold,
            "matters": self.matters,
            "bias": self.bias,
            "message": self.message,
            "simulations": self.simulations,
            "seconds": self.seconds,
            "converges": self.converges,
        }


def _sample_step(spec: EvaluationSpec) -> float:
    return spec.step_size or min(float(np.min(np.diff(e.time))) for e in spec.experiments)


def _tolerance(spec: EvaluationSpec, interface: str) -> float | None:
    return spec.tolerance if interface == "me" else None


def _plan(
    spec: EvaluationSpec, requested: str, available: tuple[str, ...]
) -> tuple[Solver, Solver]:
    """Return the study's solver and the reference for it."""
    first = requested
    if requested == "auto":  # an FMU without the interface requested fails in FMUSession
        first = "cs" if "cs" in available or not available else available[0]
    used = Solver(first, step=spec.step_size, tolerance=_tolerance(spec, first))
    if "me" in available:
        tight = min(REFERENCE_TOLERANCE, 0.01 * (spec.tolerance or 1.0))
        return used, Solver("me", tolerance=max(tight, 1e-14))
    return used, Solver("cs", step=_sample_step(spec) / FINER)


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
    if reference.interface == "cs":
        return []  # the reference itself is the fix: a smaller step
    if used.interface == "cs" and "me" in available:
        others.append(Solver("me", step=spec.step_size, tolerance=spec.tolerance))
    if used.interface == "me" and "cs" in available:
        others.append(Solver("cs", step=spec.step_size))
    if used.interface == "cs" and reference.interface == "me":
        others.append(Solver("cs", step=_sample_step(spec) / FINER))
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
    return f"step = {solver.step:g}" if solver.step != used.step else 'interface = "cs"'


def _fix(used: Solver, alternatives: list[Deviation], reference: Solver, threshold: float) -> str:
    """Name the settings that bring the solver within the threshold (or the closest)."""
    if reference.interface == "cs":
        return f"fix: a smaller communication step, step = {reference.step:g} or less in [method]"
    fixes = [f"tolerance = {reference.tolerance:g}"] if used.interface == "me" else []
    ranked = sorted(alternatives, key=lambda d: d.ratio)
    fixes += [
        f"{_setting(d.solver, used)} ({d.ratio:.2g} x the noise)"
        for d in ranked
        if d.ratio <= threshold
    ]
    if fixes:
        return "fix in [method]: " + " or ".join(fixes)
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
    out.step = spec.step_size
    sigma = [output_noise(e, (noise or {}).get(e.name)) for e in spec.experiments]
    calls = IsolatedCalls(time_limit, spec.fmu.name) if isolate else None
    runs = SolverRuns(spec, x, calls)
    try:
        out.used = compare(runs, used, reference, sigma, threshold)
        out.reference = reference
        if sensitivities is not None:
            out.bias = solver_bias(out.used, sensitivities)
        out.matters = out.used.ratio > threshold or max(out.bias.values(), default=0) > BIAS_LIMIT
        if out.matters and reference.interface == "cs":
            _convergence(out, runs, reference, sigma)
        elif out.matters:
            out.alternatives = _alternatives(runs, used, reference, available, sigma, threshold)
        out.message = _message(out, choose_interface(out))
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


def _convergence(
    out: Fidelity, runs: SolverRuns, reference: Solver, sigma: Sequence[np.ndarray]
) -> None:
    """Decide whether a Co-Simulation-only FMU converges as its step shrinks (:data:`CONVERGES`).

    One more simulation, at a step :data:`FINER` times smaller than the reference's; a
    difference that does not fall is the FMU's design, not a solver error.
    """
    assert out.used is not None
    fine = Solver("cs", step=(reference.step or 0.0) / FINER)
    finer = compare(runs, reference, fine, sigma, out.threshold)
    out.alternatives = [finer]
    out.converges = finer.ratio <= CONVERGES * out.used.ratio
    out.matters = out.converges


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
        finer = Solver("cs", step=(ref.step or 0.0) / FINER)
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
    return f"{text}; {_fix(used.solver, check.alternatives, ref, check.threshold)}"


def start_point(study: Study) -> dict[str, float]:
    """Return the centre of a study's first levels (search coordinates 0).

    With an open choice among FMU files, the point names the study's ``fmu`` among them
    (the first file where ``fmu`` is none of them): a set simulates only in the variant
    it names, and the check runs in that one.
    """
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    x = space.to_x(np.zeros(space.dim))
    v = study.variants
    if v is not None and v.name not in study.start_values:  # both already resolved
        x[v.name] = float(v.paths.index(study.fmu)) if study.fmu in v.paths else v.values[0]
    return x


def study_noise(study: Study) -> dict[str, dict[str, float]]:
    """Return the known sensor noise of each experiment's outputs (``noise = {...}``)."""
    return {e.name: dict(e.noise) for e in study.experiments}


def fidelity_record(start: Fidelity, answer: Fidelity | None) -> dict[str, Any]:
    """Return ``result.extra["fidelity"]``: the interface used, why, and both checks."""
    return {
        "requested": start.requested,
        "interface": start.interface,
        "step": start.step,
        "threshold": start.threshold,
        "reason": start.message,
        "start": start.to_dict(),
        "answer": answer.to_dict() if answer is not None else None,
    }


def chosen_interface(extra: Mapping[str, Any] | None) -> str | None:
    """Return the interface a result's fidelity check chose, or ``None`` where none ran.

    ``extra`` is ``result.extra`` (or a saved result's ``"extra"``). Whatever simulates
    at the answer again (``tsid simulate --result``, ``tsid design``) uses it: OpenModelica's
    ``Mass_Damper`` simulated by its Co-Simulation (a fixed explicit Euler step) left
    residuals 330 times the noise where the identification had chosen Model Exchange.
    """
    return ((extra or {}).get("fidelity") or {}).get("interface")


def fidelity_warnings(start: Fidelity, answer: Fidelity | None) -> list[str]:
    """Return the warnings of the checks: the answer's, else the start point's.

    A difference that ``"auto"`` removed by switching the interface is no warning (it is
    recorded); a check that could not run is, and so is an FMU whose outputs depend on
    the step by design (the data must then be sampled at the FMU's step).
    """
    last = answer if answer is not None else start
    if not last.checked or (last.matters and not last.switched) or last.converges is False:
        return [last.message]
    return []
