"""Sampled intervals: re-fits to bootstrap or Monte Carlo data sets, beside the others.

A check on the covariance and profile intervals (:mod:`.intervals`, :mod:`.profile`)
that does not linearise the model: ``R`` new data sets ``y* = y(answer) + e*`` are
made from the noise at the answer, and each is re-fitted; the spread of the re-fitted
parameters gives the intervals.

* ``"bootstrap"``: ``e*`` is a circular block bootstrap of the residuals, one
  experiment's rows drawn together, the block length from the residuals' AR model
  (:mod:`.resample`);
* ``"monte_carlo"``: ``e*`` is drawn from the AR(p) model of each residual series
  (white Gaussian noise where the residuals are white), the model of the HAC intervals
  (:func:`.longrun.long_run_covariance`: corrected for what the fit absorbs).

Residuals are smaller than the noise by what the fit absorbed: the bootstrap's draws are
rescaled by ``sqrt(n / (n - p))``, the AR models are corrected as the HAC intervals'.

Each replicate is re-fitted from the answer (its own data move its optimum by about a
standard error) by a short least squares of the study's ``sse`` cost in the search
coordinates (:mod:`tsid_fmu.numerics.space`), within the bounds, at most
:data:`~.refits.MAX_STEPS` simulations each: the replicates share one local model of
the residuals, learnt from all their simulations (:mod:`.refits`), and step in
lockstep, every step of every replicate still moving in one batch to the evaluator (in
parallel over its workers, through its memo).

The intervals are Efron's percentile intervals (:func:`.resample.percentile`) of the
re-fitted values, at the level of the other intervals (95 %).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.numerics.space import Space
from tsid_fmu.numerics.tuning import COLLAPSED, DEFAULT_REPLICATES, MIN_CONVERGED
from tsid_fmu.uncertainty.intervals import LEVEL, json_safe
from tsid_fmu.uncertainty.longrun import ArNoise, long_run_covariance
from tsid_fmu.uncertainty.refits import MAX_STEPS, Replicate, SharedModel, refit, tolerance
from tsid_fmu.uncertainty.resample import ar_draw, block_bootstrap, block_length, percentile
from tsid_fmu.uncertainty.sensitivity import Sensitivities, residual_jacobian

__all__ = [
    "COLLAPSED",
    "DEFAULT_REPLICATES",
    "MIN_CONVERGED",
    "SAMPLED",
    "Sampled",
    "for_study",
    "sampled_intervals",
]

SAMPLED = ("bootstrap", "monte_carlo")
"""The sampled kinds of ``[method] uncertainty``."""


Notify = Callable[[str, dict[str, Any]], None]


@dataclass
class Sampled:
    """Sampled intervals (module doc).

    Attributes
    ----------
    kind : str
        ``"bootstrap"`` or ``"monte_carlo"``.
    replicates : int
        Re-fits asked for.
    intervals : dict
        Percentile interval ``[low, high]`` per parameter (``None`` ends: too few
        replicates finished).
    std_error : dict
        Standard deviation of the re-fitted values, in parameter units.
    estimates : dict
        The re-fitted value of each parameter, one per replicate (``nan``: failed).
    noise : dict
        Per experiment, how its draws were made: block length (bootstrap) or AR order
        of each output (Monte Carlo).
    failed : int
        Replicates whose re-fit failed (a simulation failed at the answer's step).
    unfinished : int
        Replicates stopped by :data:`~.refits.MAX_STEPS` rather than having converged.
    nfev : int
        Simulations of the re-fits.
    level : float
        Confidence level.
    method : str
        How the intervals were computed, in words.
    withheld : dict
        Parameters whose sampled interval is not given, with the reason
        (:meth:`withhold`): too few re-fits converged, or the re-fits collapsed onto one
        value where the primary interval is open.
    """

    kind: str
    replicates: int
    intervals: dict[str, list[float | None]] = field(default_factory=dict)
    std_error: dict[str, float] = field(default_factory=dict)
    estimates: dict[str, list[float]] = field(default_factory=dict)
    noise: dict[str, Any] = field(default_factory=dict)
    failed: int = 0
    unfinished: int = 0
    nfev: int = 0
    level: float = LEVEL
    method: str = ""
    withheld: dict[str, str] = field(default_factory=dict)

    @property
    def converged(self) -> int:
        """Re-fits that converged (neither failed nor stopped at the step limit)."""
        return self.replicates - self.failed - self.unfinished

    def withhold(self, primary: Mapping[str, list[float | None]]) -> None:
        """Withhold the intervals a reader must not take (``withheld``, with the reason).

        All of them when fewer than :data:`MIN_CONVERGED` of the re-fits converged: a
        re-fit stopped at its step limit sits between the answer and its own optimum, and
        such intervals are too narrow (19 of 20 stopped gave 2.44 .. 2.58 against a primary
        0.79 .. 6.8). A parameter's, where its re-fits collapse onto one value (relative
        spread below :data:`COLLAPSED`) while its primary interval is open: a bound or a
        direction the data do not see holds every re-fit still, which says nothing of
        its precision.
        """
        if self.converged < MIN_CONVERGED * self.replicates:
            why = (
                f"only {self.converged} of {self.replicates} re-fits converged "
                f"({self.failed} failed, {self.unfinished} stopped at the step limit)"
            )
            self.withheld = dict.fromkeys(self.intervals, why)
            return
        for name, (low, high) in self.intervals.items():
            opened = primary.get(name, [None, None])
            if None not in opened or low is None or high is None:
                continue
            if abs(high - low) <= COLLAPSED * max(abs(low), abs(high), 1e-300):
                self.withheld[name] = (
                    "the re-fits collapsed onto one value where the data do not determine "
                    "the parameter (its primary interval is open)"
                )

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy (non-finite numbers as ``None``)."""
        return json_safe(dict(vars(self)))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Sampled:
        """Return the object :meth:`to_dict` wrote (``None`` numbers back as ``nan``)."""
        known = {k: data[k] for k in cls.__dataclass_fields__ if k in data}

        def number(v: Any) -> float:
            return math.nan if v is None else float(v)

        known["std_error"] = {k: number(v) for k, v in (known.get("std_error") or {}).items()}
        known["estimates"] = {
            k: [number(v) for v in vs] for k, vs in (known.get("estimates") or {}).items()
        }
        return cls(**known)

    def to_pandas(self) -> Any:
        """Return the re-fitted values as a DataFrame, one row per replicate."""
        import pandas as pd

        frame = pd.DataFrame(self.estimates)
        frame.index.name = "replicate"
        frame.attrs["kind"] = self.kind
        return frame


def _describe(kind: str) -> str:
    draws = (
        "circular block bootstrap of the residuals (block length: the Politis-White rule "
        "from their AR model)"
        if kind == "bootstrap"
        else "Monte Carlo noise from the AR(p) model of each residual series (the HAC "
        "intervals' models, corrected for what the fit absorbs)"
    )
    return (
        f"{draws}; each replicate re-fitted from the answer by least squares (Gauss-Newton "
        f"on a local model of the residuals shared by the replicates, at most {MAX_STEPS} "
        "simulations each); Efron's percentile intervals of the re-fitted values"
    )


def _noise_models(sens: Sensitivities) -> list[ArNoise]:
    """Return the AR model of every residual series, as the HAC intervals make them.

    Each series whitened by its RMS (the models' unit), in the order of the experiments
    and their outputs; corrected for what the fit absorbs
    (:func:`.longrun.long_run_covariance`).
    """
    series = []
    for r, jac in zip(sens.residuals, sens.jacobian, strict=True):
        sigma = np.sqrt(np.mean(r**2, axis=0))
        sigma = np.where(sigma > 0, sigma, 1.0)
        series += [(r[:, k] / sigma[k], jac[:, k, :] / sigma[k]) for k in range(r.shape[1])]
    stacked = np.vstack([j for _, j in series])
    values, vectors = np.linalg.eigh(stacked.T @ stacked)
    keep = values > 1e-14 * max(float(values.max()), 1e-300)
    inverse = (vectors * np.where(keep, 1.0 / np.maximum(values, 1e-300), 0.0)) @ vectors.T
    return list(long_run_covariance(series, inverse).models)


class _Draws:
    """The noise of the replicates, in the units of the evaluator's residuals."""

    def __init__(self, kind: str, sens: Sensitivities, spec: EvaluationSpec, p: int) -> None:
        self.kind = kind
        self.blocks: list[tuple[np.ndarray, np.ndarray, Any]] = []
        self.noise: dict[str, Any] = {}
        total = sum(r.size for r in sens.residuals)
        inflate = math.sqrt(total / max(total - p, 1))
        models = _noise_models(sens) if kind == "monte_carlo" else []
        for e, r in zip(spec.experiments, sens.residuals, strict=True):
            rows = e.weighted(np.ones((len(e.time), 1)))[:, 0]  # sqrt of window weights
            plain = r / e.scale[None, :] / np.where(rows > 0, rows, 1.0)[:, None] * inflate
            if kind == "bootstrap":
                how: Any = block_length(plain)
                self.noise[e.name] = {"block_length": how}
            else:
                rms = np.sqrt(np.mean((plain / inflate) ** 2, axis=0))
                how = [(models.pop(0), sd) for sd in rms]
                self.noise[e.name] = {
                    "ar_order": dict(zip(e.output_names, [m.order for m, _ in how], strict=True))
                }
            self.blocks.append((plain, rows, how))

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """Return one replicate's noise, flattened as the evaluator's residuals are."""
        parts = []
        for plain, rows, how in self.blocks:
            if self.kind == "bootstrap":
                e = block_bootstrap(plain, how, rng)
            else:
                e = np.column_stack([sd * ar_draw(m, plain.shape[0], rng) for m, sd in how])
            parts.append((e * rows[:, None]).reshape(-1))
        return np.concatenate(parts)


def _residuals(spec: EvaluationSpec, sims: list[Any]) -> np.ndarray | None:
    """Return the evaluator's residual vector of one simulated set (None: it failed)."""
    parts = []
    for e, sim in zip(spec.experiments, sims, strict=True):
        if sim.outputs is None:
            return None
        parts.append((e.weighted(sim.outputs - e.measured) / e.scale[None, :]).reshape(-1))
    return np.concatenate(parts)


def sampled_intervals(
    evaluator: Evaluator,
    spec: EvaluationSpec,
    space: Space,
    x: Mapping[str, float],
    sens: Sensitivities,
    *,
    kind: str,
    replicates: int = DEFAULT_REPLICATES,
    seed: int = 0,
    progress: Notify | None = None,
) -> Sampled:
    """Re-fit ``replicates`` bootstrap or Monte Carlo data sets from ``x`` (module doc).

    Parameters
    ----------
    evaluator, spec : Evaluator, EvaluationSpec
        The evaluator of the identification experiments (its workers and memo) and its
        spec; only its ``simulate`` is called.
    space : Space
        The search coordinates of ``sens`` (the re-fits step in them, within bounds).
    x : mapping
        The answer: every parameter of ``space``.
    sens : Sensitivities
        The residuals and sensitivities at ``x`` (:func:`.sensitivity.sensitivities`).
    kind : {"bootstrap", "monte_carlo"}
        How the replicates' noise is drawn.
    replicates : int
        Number of re-fits.
    seed : int
        Seed of the draws.
    progress : callable, optional
        Called as ``progress("sampled", {"message": ..., "done": ...})`` after every
        batch of steps (``done``: replicates finished).
    """
    if kind not in SAMPLED:
        raise ValueError(f"kind must be one of {SAMPLED}, got {kind!r}")
    start = evaluator.nfev
    rng = np.random.default_rng([int(seed), 29])
    s0 = space.to_s(x)
    jac0 = residual_jacobian(sens, spec)
    base = np.concatenate(
        [
            (r / e.scale[None, :]).reshape(-1)
            for e, r in zip(spec.experiments, sens.residuals, strict=True)
        ]
    )
    draws = _Draws(kind, sens, spec, space.dim)
    tol = tolerance(base)
    reps = []
    for _ in range(replicates):
        e = draws.draw(rng)
        reps.append(Replicate(base + e, np.zeros(space.dim), -e, tol))

    def simulate(points: list[np.ndarray]) -> list[np.ndarray | None]:
        sims = evaluator.simulate([space.to_x(s) for s in points])
        return [_residuals(spec, sim) for sim in sims]

    def said(step: int, stepped: int, left: int) -> None:
        if progress:
            message = (
                f"{kind}: step {step} of at most {MAX_STEPS}: {stepped} re-fits stepped, "
                f"{left} of {replicates} still moving"
            )
            progress("sampled", {"message": message, "done": replicates - left})

    refit(reps, SharedModel(base, jac0), space, s0, simulate, said)
    return _summary(space, s0, reps, kind, draws.noise, evaluator.nfev - start)


def _summary(
    space: Space,
    s0: np.ndarray,
    reps: list[Replicate],
    kind: str,
    noise: dict[str, Any],
    nfev: int,
) -> Sampled:
    out = Sampled(kind, len(reps), noise=noise, nfev=nfev, method=_describe(kind))
    failed = [rep.taken == 0 and rep.errors > 0 for rep in reps]
    out.failed = int(sum(failed))
    out.unfinished = int(
        sum(not rep.converged and not f for rep, f in zip(reps, failed, strict=True))
    )
    for j, name in enumerate(space.names):
        values = [
            math.nan if f else space.value(j, float(s0[j] + rep.d[j]))
            for rep, f in zip(reps, failed, strict=True)
        ]
        out.estimates[name] = values
        out.intervals[name] = percentile(values, out.level)
        finite = [v for v in values if math.isfinite(v)]
        out.std_error[name] = float(np.std(finite, ddof=1)) if len(finite) > 1 else math.nan
    return out


def for_study(
    method: Any,
    ev: Evaluator,
    where: tuple[EvaluationSpec, Space, dict[str, float]],
    found: Any,
    progress: Notify | None = None,
) -> Sampled | None:
    """Return the sampled intervals a study's ``method`` asks for, at ``found``'s answer.

    None for ``uncertainty = "analytic"`` or where the answer has no sensitivities; the
    intervals a reader must not take beside ``found``'s primary ones are withheld
    (:meth:`Sampled.withhold`).
    """
    sens = found.sensitivities
    if method.uncertainty == "analytic" or sens is None:
        return None
    spec, space, x = where
    out = sampled_intervals(
        ev,
        spec,
        space,
        x,
        sens,
        kind=method.uncertainty,
        replicates=method.uncertainty_replicates,
        seed=method.seed,
        progress=progress,
    )
    out.withhold(found.uncertainty.intervals if found.uncertainty else {})
    return out
