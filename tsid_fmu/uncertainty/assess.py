"""The evidence at the answer: cost, fit, noise, intervals, validation, warnings."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.evaluate.cost import Cost
from tsid_fmu.evaluate.noise import quantum
from tsid_fmu.evaluate.protocol import Evaluator, Simulated
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.numerics.space import Space
from tsid_fmu.numerics.tuning import MISMATCH
from tsid_fmu.study.prepare import data_noise
from tsid_fmu.uncertainty.discrepancy import judge
from tsid_fmu.uncertainty.intervals import Uncertainty, quantile, scale_groups, uncertainty
from tsid_fmu.uncertainty.probe import probe_combinations
from tsid_fmu.uncertainty.profile import ProfileProblem, profile_intervals
from tsid_fmu.uncertainty.sensitivity import Sensitivities, residual_jacobian, sensitivities

__all__ = [
    "MISMATCH",
    "NOISE_SOURCES",
    "Assessment",
    "answer_space",
    "assess",
    "standard_errors",
    "validate",
]


def answer_space(
    levels: Mapping[str, Any], bounds: Mapping[str, tuple[float, float]], leveling: LevelingOptions
) -> Space:
    """Return the coordinates an answer is assessed in: ``log10`` where levels are positive.

    Relative precision, and products and ratios as combinations; :func:`assess` makes
    them linear where they are degenerate at the answer (:meth:`Space.near`).
    """
    return Space(levels, bounds, dataclasses.replace(leveling, scale="log"))


@dataclass
class Assessment:
    """What :func:`assess` found at a parameter set."""

    fun: float
    fit: dict[str, Any] = field(default_factory=dict)
    noise: dict[str, dict[str, float]] = field(default_factory=dict)
    noise_source: dict[str, dict[str, str]] = field(default_factory=dict)
    simulated: list[Simulated] = field(default_factory=list)
    uncertainty: Uncertainty | None = None
    warnings: list[str] = field(default_factory=list)
    nfev: int = 0
    sensitivities: Sensitivities | None = None
    space: Space | None = None
    """The coordinates of ``sensitivities`` and of the uncertainty's covariance and
    combinations: the space :func:`assess` was given, :meth:`~Space.near` the answer."""


NOISE_SOURCES = {"study": "stated in the study", "data": "estimated from the data"}
"""Where the noise of an output came from (``noise_source`` of a result), in words."""


def _noise(
    spec: EvaluationSpec, stated: Mapping[str, Mapping[str, float]]
) -> tuple[dict[str, dict[str, float]], dict[str, dict[str, str]]]:
    """Return the noise of each experiment's outputs that the cost uses, and its source.

    The sensor noise the study states (``noise = {...}``, :attr:`Experiment.noise`),
    else the estimate from the measured data
    (:func:`~tsid_fmu.study.prepare.data_noise`), as ``study/prepare.py`` weights them.
    """
    noise: dict[str, dict[str, float]] = {}
    source: dict[str, dict[str, str]] = {}
    for e in spec.experiments:
        given = stated.get(e.name, {})
        estimate = data_noise(e.scored(e.measured))  # the scored samples' noise
        noise[e.name], source[e.name] = {}, {}
        for name, s in zip(e.output_names, estimate, strict=True):
            known = name in given
            noise[e.name][name] = float(given[name]) if known else float(s)
            source[e.name][name] = "study" if known else "data"
    return noise, source


def mismatches(fit: Mapping, noise: Mapping) -> list[tuple[str, str, float, float]]:
    """Return the outputs that the model does not explain: RMS above :data:`MISMATCH` x noise.

    Parameters
    ----------
    fit : mapping
        Per experiment, per output, the fit metrics (``rmse``); an experiment whose
        simulation failed holds ``error`` instead and is left out.
    noise : mapping
        Per experiment, per output, the noise's standard deviation.

    Returns
    -------
    list of tuple
        ``(experiment, output, rmse, noise)`` of each such output, in the fit's order.
    """
    out = []
    for exp, outputs in fit.items():
        for name, metrics in outputs.items():
            if not isinstance(metrics, Mapping) or "rmse" not in metrics:
                continue
            s, rmse = float(noise.get(exp, {}).get(name, 0.0)), float(metrics["rmse"])
            if s > 0 and rmse > MISMATCH * s:
                out.append((exp, name, rmse, s))
    return out


def mismatch_warning(exp: str, name: str, rmse: float, s: float) -> str:
    """Return the warning of one output the model does not explain (:func:`mismatches`)."""
    return (
        f"{exp} / {name}: model or solver mismatch: residual RMS {rmse:.3g} is "
        f"{rmse / s:.1f} times the noise ({s:.3g}; more than "
        f"{MISMATCH:g} x): the model or its solver does not explain these data, "
        "and the intervals assume it does"
    )


def _fit(spec: EvaluationSpec, sims: list[Simulated], noise: Mapping) -> dict:
    fit: dict[str, Any] = {}
    for e, sim in zip(spec.experiments, sims, strict=True):
        if sim.outputs is None:
            fit[e.name] = {"error": sim.error}
            continue
        fit[e.name] = e.fit_metrics(sim.outputs)  # the scored samples only
    return fit


def assess(
    evaluator: Evaluator,
    spec: EvaluationSpec,
    space: Space,
    x: Mapping[str, float],
    stated: Mapping[str, Mapping[str, float]] | None = None,
) -> Assessment:
    """Evaluate the answer ``x``: its cost, fit, the noise, intervals and warnings.

    ``stated`` is the sensor noise the study states per experiment and output; the
    noise reported (and compared with the residuals) is that, else the data's estimate,
    as the cost weights it. The simulations of the fit and of the sensitivities are
    counted (``nfev``) but they are not part of any stage.
    """
    start = evaluator.nfev
    fun = float(evaluator.evaluate([dict(x)]).costs[0, 0])
    sims = evaluator.simulate([dict(x)], count=False)[0]
    noise, source = _noise(spec, stated or {})
    fit = _fit(spec, sims, noise)
    misfit = mismatches(fit, noise)
    warnings = [mismatch_warning(*m) for m in misfit]
    out = Assessment(fun, fit, noise, source, sims, warnings=warnings)
    varied = {n: float(x[n]) for n in space.names}
    # a log coordinate below its smallest first level is degenerate (an offset at 0 has
    # no effect in it): linear there, every derivative and interval below means its value
    space = out.space = space.near(varied)
    why: list[str] = []
    sens = (
        sensitivities(evaluator, spec, space, varied, failures=why) if math.isfinite(fun) else None
    )
    if sens is not None:
        out.uncertainty = uncertainty(sens, space, varied)
        out.sensitivities = sens
        if out.uncertainty is None:
            why.append("the outputs do not depend on the parameters at the answer")
    elif not math.isfinite(fun):
        why.append("the cost at the answer is not finite")
    if out.uncertainty is None:  # said, the same way in every view: a warning
        out.warnings.append(f"no intervals: {'; '.join(why) or 'no sensitivities'}")
    if out.uncertainty is not None and sens is not None and spec.cost == "sse":
        rise = _widen_by_profile(evaluator, spec, space, sens, out.uncertainty, x=varied, cost=fun)
        jac = residual_jacobian(sens, spec)
        out.warnings += probe_combinations(
            evaluator, space, out.uncertainty, varied, fun, rise, jac
        )
    if out.uncertainty is not None:
        out.uncertainty.scale_groups = scale_groups(out.uncertainty, space)
    if out.uncertainty is not None:
        u = out.uncertainty
        rounded = _rounded(spec, noise)
        coloured = [c for c in u.coloured if c not in rounded]
        # the constancy test's scores sum to 0 only at a least-squares optimum
        test = u.constancy if spec.cost == "sse" else {}
        u.discrepancy = judge(test, coloured, [f"{e} / {n}" for e, n, *_ in misfit], u.inflation)
        if not u.discrepancy.holds:
            out.warnings.append(u.discrepancy.warning())
        elif u.coloured:
            out.warnings.append(
                f"residuals are coloured ({', '.join(u.coloured)}) by the sensors' rounding: "
                f"standard errors that assume white noise would be optimistic by "
                f"~x{u.inflation:.3g}; the intervals use a HAC covariance that allows for it"
            )
    out.nfev = evaluator.nfev - start
    return out


def _rounded(spec: EvaluationSpec, noise: Mapping) -> set[str]:
    """``experiment / output`` of the outputs whose noise is a sensor's rounding.

    A quantised sensor (an encoder) on a slow signal leaves residuals coloured by its
    rounding, a known, deterministic cause (:func:`~tsid_fmu.evaluate.noise.quantum`):
    noise no larger than twice the grid's ``q / sqrt(12)`` cannot be told from it.
    """
    out = set()
    for e in spec.experiments:
        measured = e.scored(e.measured)
        for k, name in enumerate(e.output_names):
            q = quantum(np.asarray(measured[:, k], dtype=float))
            if q > 0 and noise[e.name][name] <= 2 * q / math.sqrt(12.0):
                out.add(f"{e.name} / {name}")
    return out


def _widen_by_profile(
    evaluator: Evaluator,
    spec: EvaluationSpec,
    space: Space,
    sens: Sensitivities,
    u: Uncertainty,
    *,
    x: dict[str, float],
    cost: float,
) -> float:
    """Make every interval of ``u`` at least as wide as the parameter's profile one.

    ``sens`` holds the Jacobian at the answer ``x``, whose cost is ``cost``. Each
    parameter's threshold carries its own HAC inflation and degrees of freedom. Returns
    the rise of the cost that bounds a 95 % interval of a combination.
    """
    jacobian = residual_jacobian(sens, spec)
    n, p = jacobian.shape
    variance = max(cost / max(n - p, 1), 1e-300)
    thresholds = {
        name: quantile(u.dof.get(name, n - p)) ** 2 * variance * _inflation(u, name) ** 2
        for name in space.names
    }
    # linear coordinates with the same local scale: a valley along a sum of parameters is
    # straight there, so the chord re-fit follows it (the Jacobian is the same at x)
    line = space.anchored(x)
    threshold = quantile(n - p) ** 2 * variance * u.inflation**2
    problem = ProfileProblem(
        evaluator, line, line.to_s(x), cost, jacobian, threshold, thresholds=thresholds
    )
    steps = {
        name: u.std_error[name] / space.local_scale(j, x[name])
        for j, name in enumerate(space.names)
    }
    u.profile = profile_intervals(problem, steps)
    for name, (low, high) in u.profile.items():
        c_low, c_high = u.intervals.get(name, [None, None])
        u.intervals[name] = [
            None if low is None or c_low is None else min(low, c_low),
            None if high is None or c_high is None else max(high, c_high),
        ]
        # the standard error reported is the wider interval's half-width / 1.96
        if low is None or high is None:
            u.std_error[name] = u.relative[name] = math.inf
        else:
            profiled = 0.5 * (high - low) / quantile(u.dof.get(name, n - p))
            floor = name in problem.unresolved and profiled > u.std_error[name]
            u.std_error[name] = max(u.std_error[name], profiled)
            if x[name]:
                u.relative[name] = 100 * u.std_error[name] / abs(x[name])
                if floor:  # the profile's resolution, not an estimate: a bound
                    u.resolution[name] = u.relative[name]
    u.method = (
        "the wider of a HAC sandwich (AR(p) long-run covariance, at least the Cramer-Rao "
        "bound) and the profile likelihood, both with Student t quantiles of Satterthwaite "
        "degrees of freedom"
    )
    return threshold


def _inflation(u: Uncertainty, name: str) -> float:
    """HAC over Cramer-Rao standard error of ``name`` (the median one where unknown)."""
    hac, crb = u.relative.get(name, math.nan), u.cramer_rao.get(name, math.nan)
    if 0 < crb < math.inf and 0 < hac < math.inf:
        return hac / crb
    return u.inflation


def validate(evaluator: Evaluator, spec: EvaluationSpec, x: Mapping[str, float]) -> dict[str, Any]:
    """Simulate the validation experiments at ``x``; return cost and fit per experiment."""
    sims = evaluator.simulate([dict(x)], count=False)[0]
    cost = Cost(spec.cost)
    out: dict[str, Any] = {}
    for e, sim in zip(spec.experiments, sims, strict=True):
        if sim.outputs is None:
            out[e.name] = {"error": sim.error}
            continue
        value = float(np.dot(e.output_costs(cost, sim.outputs), e.weights))
        out[e.name] = {
            "cost": value,
            "fit": e.fit_metrics(sim.outputs),
        }
    return out


def standard_errors(evaluator: Evaluator, x: Mapping[str, float]) -> Uncertainty | None:
    """Cramer-Rao standard errors of ``x`` from an evaluator's experiments.

    The derivatives are taken in linear coordinates (steps of 0.04 % of each value), the
    noise of each output from its residual RMS at ``x``.
    """
    levels = {n: [0.9 * v, 1.1 * v] if v else [-0.1, 0.1] for n, v in x.items()}
    bounds = {n: (-math.inf, math.inf) for n in x}
    space = Space(levels, bounds, LevelingOptions(scale="linear"))
    sens = sensitivities(evaluator, evaluator.spec, space, dict(x))
    return None if sens is None else uncertainty(sens, space, dict(x))
