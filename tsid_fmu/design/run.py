"""The experiment that determines what a study left open, or the finding that none can.

:func:`design` takes an identification's answer and its study, and

1. builds the candidate inputs of ``[design]`` (:mod:`tsid_fmu.design.signals`);
2. computes the study's Fisher information and each candidate's at the answer
   (:mod:`tsid_fmu.design.fisher`): ``2p + 1`` simulations of the study, and ``2p + 1``
   of every candidate;
3. finds the directions the study leaves weak (an open interval, a combination not
   determined) and asks whether any candidate could fix them. A direction that even
   all the candidates together leave nearly flat is followed by simulation: a point
   :data:`STEP` search units along it, re-fitted across it by Gauss-Newton steps,
   simulated with every candidate input. Where every candidate's outputs there match
   the answer's to :data:`~tsid_fmu.uncertainty.probe.FLAT` of the sensors' noise (the
   RMS over the samples, as the study's own probe of a symmetry), the outputs are the
   same for every input, up to the FMU solver's accuracy: the direction is
   *structural*. No input of this family separates those parameters; the design names
   the combinations across it that the data do fix, and what would fix the rest (a
   known value, another measurement);
4. ranks the candidates by the criterion (D or A, :class:`~tsid_fmu.study.designopts.
   DesignOptions`) of the summed information in the directions that are not
   structural, and predicts the 95 % intervals that the study plus the best candidate
   would give by running the study's own analysis on them
   (:mod:`tsid_fmu.design.predict`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.design.across import combinations_across
from tsid_fmu.design.discriminate import discriminate, tied
from tsid_fmu.design.fisher import candidate_fisher, study_fisher
from tsid_fmu.design.outcome import Design, Structural
from tsid_fmu.design.plan import Plan, at_bounds, candidate_spec, make_plan
from tsid_fmu.design.predict import predicted_intervals
from tsid_fmu.evaluate.factory import make_evaluator
from tsid_fmu.search.space import Space
from tsid_fmu.study.designopts import DesignOptions
from tsid_fmu.uncertainty.assess import answer_space
from tsid_fmu.uncertainty.intervals import UNDETERMINED, seen_inverse
from tsid_fmu.uncertainty.probe import FLAT, GAIN, MEMBER, REFITS

__all__ = ["STEP", "design"]

STEP = 0.25
"""How far (search units: a quarter of a first range) a weak direction is followed to
test whether any input could separate it."""


def _basis(vectors: list[np.ndarray], dim: int) -> np.ndarray:
    """Orthonormal columns spanning ``vectors`` (``(dim, 0)`` for none)."""
    if not vectors:
        return np.zeros((dim, 0))
    u, s, _ = np.linalg.svd(np.stack(vectors, axis=1), full_matrices=False)
    return u[:, s > 0.5 * s.max()]


def _weak(
    result: Any,
    space: Space,
    f0: np.ndarray,
    assessed: Space | None = None,
    x: Mapping[str, float] | None = None,
) -> np.ndarray:
    """Return the directions the study leaves weak (orthonormal columns, ``space``'s).

    The combinations the study found not determined; for each parameter with an open
    interval that none of those explains, the direction its profile follows (the
    parameter moving, the others re-fitted: the valley of F_vm and B_s, which act on
    one output through their sum only); and the directions the information ``f0``
    itself leaves undetermined. ``assessed`` is the space the study's combinations
    are in at its answer ``x``, where it is not ``space``.
    """
    vectors = []
    values, vecs = np.linalg.eigh(f0)
    for lam, v in zip(values, vecs.T, strict=True):
        if lam <= 0 or 1 / math.sqrt(lam) > UNDETERMINED:
            vectors.append(v)
    u = getattr(result, "uncertainty", None)
    explained = set()
    for c in getattr(u, "combinations", None) or []:
        if c.get("determined") is False and "direction" in c:
            v = np.asarray(c["direction"], dtype=float)
            if assessed is not None and x is not None:  # the study's, to the design's
                v = assessed.carry(v, x, space)
            v = v / max(float(np.linalg.norm(v)), 1e-300)
            vectors.append(v)
            explained |= {j for j in range(space.dim) if abs(v[j]) >= MEMBER}
    # the profile's direction from a regularised inverse, not pinv: along an exact
    # symmetry f0 is zero to rounding, and pinv would drop the very direction wanted
    trace = float(np.trace(f0))
    inverse = (
        np.linalg.inv(f0 + 1e-12 * trace * np.eye(space.dim)) if trace > 0 else np.eye(space.dim)
    )
    for j, name in enumerate(space.names):
        if j not in explained and None in (result.intervals.get(name) or [None]):
            v = inverse[:, j] if np.any(inverse[:, j]) else np.eye(space.dim)[j]
            vectors.append(v / np.linalg.norm(v))
    return _basis(vectors, space.dim)


def _cov(info: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``keep (keep^T info keep)^-1 keep^T``: the covariance within ``keep``'s span."""
    if keep.shape[1] == 0:
        return np.zeros_like(info)
    m = keep.T @ info @ keep
    values, vectors = np.linalg.eigh(m)
    seen = values > 1e-14 * max(values.max(), 1e-300)
    inv = np.where(seen, 1 / np.maximum(values, 1e-300), 0)
    cov = keep @ (vectors * inv) @ vectors.T @ keep.T
    unseen = keep @ vectors[:, ~seen]  # no information at all: infinite variance
    return cov + np.diag(np.where((unseen**2).sum(axis=1) > 1e-6, np.inf, 0.0))


def _score(info: np.ndarray, keep: np.ndarray, targets: np.ndarray, criterion: str) -> float:
    """Score in ``keep``'s span: log det (D, larger is better) or -sum of variances (A)."""
    if keep.shape[1] == 0:
        return 0.0
    if criterion == "D":
        m = keep.T @ info @ keep
        values = np.linalg.eigvalsh(m)
        return float(np.sum(np.log(np.maximum(values, 1e-300))))
    cov = _cov(info, keep)
    cov = np.where(np.isfinite(cov), cov, 1e300)  # a target left unseen: the worst score
    return -float(np.trace(targets.T @ cov @ targets))


class _Follow:
    """Simulate the candidates along a direction and measure how far their outputs move."""

    def __init__(self, evaluator: Any, space: Space, x: Mapping[str, float], base: list) -> None:
        self.evaluator, self.space, self.x, self.base = evaluator, space, dict(x), base

    def rise(self, point: dict[str, float]) -> tuple[np.ndarray, np.ndarray] | None:
        """Per candidate, how far its outputs at ``point`` lie from the answer's.

        The largest over its outputs of the RMS over the samples of the difference, in
        the sensors' noise; and every whitened difference, for the re-fit.
        """
        (run,) = self.evaluator.simulate([point])
        if any(sim.outputs is None for sim in run):
            return None
        r = [
            (sim.outputs - b) / e.scale[None, :]
            for sim, b, e in zip(run, self.base, self.evaluator.spec.experiments, strict=True)
        ]
        rms = np.array([float(np.max(np.sqrt(np.mean(d**2, axis=0)))) for d in r])
        return rms, np.concatenate([d.ravel() for d in r])

    def flat(self, v: np.ndarray, jac: np.ndarray, held: np.ndarray | None = None) -> bool:
        """Whether no candidate tells the answer from :data:`STEP` along ``v`` (re-fitted).

        Gauss-Newton steps across ``v`` with the candidates' Jacobian at the answer: in
        linear coordinates a symmetry (``R C`` fixed) is curved, and the point along its
        tangent lies off it. The re-fit is the probes' (:mod:`tsid_fmu.uncertainty.probe`):
        at most :data:`~tsid_fmu.uncertainty.probe.REFITS` simulations, stopping once a
        step lowers the rise by less than :data:`~tsid_fmu.uncertainty.probe.GAIN` of
        :data:`FLAT`, or once the rise, falling at the rate of its last step, would not
        reach :data:`FLAT` in the re-fits left (three, as it was, left the motor's second
        direction at 1.16 noise, falling by a factor of four a step). The re-fit stays
        outside the span of ``held`` (columns: every weak direction tested with ``v``): in a
        symmetry of two directions it slid along the other one without end (a DC motor
        measured by its speed, J to 48.5 and then to 1e300).
        """
        s0 = self.space.to_s(self.x)
        # the side that stays within the bounds (a parameter at 0 steps up, not into 0),
        # else the one the bounds cut least
        ends = [self.space.clip(s0 + sign * STEP * v) for sign in (1.0, -1.0)]
        s = max(ends, key=lambda end: float(np.linalg.norm(end - s0)))
        span = _basis([v, *(() if held is None else held.T)], self.space.dim)
        rank = span.shape[1]
        across = np.linalg.svd(np.eye(self.space.dim) - span @ span.T)[0][
            :, : self.space.dim - rank
        ]
        step = seen_inverse(jac @ across)
        last = math.inf
        for done in range(1, REFITS + 1):
            found = self.rise(self.space.to_x(s))
            if found is None:
                return False
            rise = float(np.max(found[0]))
            if rise <= FLAT:
                return True
            if last - rise < GAIN * FLAT:  # the re-fit no longer gains: not flat
                return False
            # falling as it does, it would not reach FLAT in the re-fits left: not flat
            if math.isfinite(last) and rise * (rise / last) ** (REFITS - done) > FLAT:
                return False
            last = rise
            s = self.space.clip(s - across @ (step @ found[1]))
        return False


def _structural(space: Space, x: dict, found: list[np.ndarray], cov: np.ndarray) -> list:
    """Return the structural finding: one subspace, its members, what the data fix."""
    if not found:
        return []
    basis = _basis(found, space.dim)
    members, fixed = combinations_across(space, x, basis, cov)
    return [Structural(members, [_terms(space, v) for v in basis.T], fixed)]


def _terms(space: Space, v: np.ndarray) -> dict[str, float]:
    """Name a direction by its coordinates' weights (``lg C``: -0.58), small ones left out."""
    u = space.u_direction(v)
    return {space.label(j): round(float(c), 3) for j, c in enumerate(u) if abs(c) >= 0.05}


def _explore(plan: Plan, result: Any, workers: Any, timeout: Any, say: Any) -> dict[str, Any]:
    """Simulate the study and the candidates: information, weak and structural directions."""
    space, x = plan.space, plan.x
    inflation = float(getattr(result.uncertainty, "inflation", 1.0) or 1.0)
    # a study whose outputs did not move (a nut stuck below its break-away force) has
    # no inflation to speak of: nan, which would spoil every matrix below
    inflation = inflation if math.isfinite(inflation) and inflation > 0 else 1.0
    n = 2 * space.dim + 1
    say(f"the study's information at the answer: {n} simulations of each experiment")
    with make_evaluator(plan.spec, workers=workers, timeout=timeout) as ev:
        f0, residuals = study_fisher(ev, space, x, inflation)
        nfev = ev.nfev
    cspec = candidate_spec(plan, [s.values for s in plan.signals])
    say(f"{len(plan.signals)} candidate inputs: {n * len(plan.signals)} simulations")
    with make_evaluator(cspec, workers=workers, timeout=timeout) as ev:
        fishers, outputs, jacs = candidate_fisher(ev, space, x, plan.sigma)
        # the study's combinations are in the coordinates its answer was assessed in
        study = plan.study
        assessed = answer_space(plan.levels, study.bounds(), study.method.leveling)
        weak = _weak(result, space, f0, assessed.near(x), x)
        # what the study says it does not determine, it does not: the differences'
        # curvature along those directions is the solver's noise, not the data's
        drop = np.eye(space.dim) - weak @ weak.T
        f0 = drop @ f0 @ drop
        follow = _Follow(ev, space, x, outputs)
        jac = np.vstack(jacs)
        found = []
        vecs = np.linalg.eigh(f0 + sum(fishers))[1]
        held = vecs[:, : weak.shape[1]]  # the pooled information's weakest directions
        for k in range(weak.shape[1]):  # tested together: each re-fit outside them all
            if not follow.flat(vecs[:, k], jac, held):
                break
            found.append(vecs[:, k])
        nfev += ev.nfev
    return {"f0": f0, "residuals": residuals, "fishers": fishers, "outputs": outputs,
            "jacobians": jacs, "weak": weak, "found": found, "nfev": nfev}  # fmt: skip


def _predict(plan: Plan, e: dict, best: int, workers: Any, timeout: Any, say: Any) -> tuple:
    """Run the study's analysis with the proposal: its intervals, and the simulations."""
    one = candidate_spec(plan, [plan.signals[best].values])
    # for the study the user runs next: the proposal added, first levels around the answer
    # in the coordinates the study will assess its answer in (identify's, answer_space)
    follow = answer_space(plan.follow, plan.study.bounds(), plan.study.method.leveling)
    say(f"proposal {plan.signals[best].name}: the study's analysis with it, to predict")
    return predicted_intervals(
        plan.spec, one, e["outputs"][best], e["residuals"][plan.template.name], follow,
        plan.x, plan.options.seed, jacobian=e["jacobians"][best], sigma=plan.sigma,
        workers=workers, timeout=timeout,
    )  # fmt: skip


def design(
    result: Any,
    options: DesignOptions | None = None,
    *,
    workers: int | None = 1,
    timeout: float | None = 0,
    progress: Callable[[str], None] | None = None,
) -> Design:
    """Propose the experiment that best determines what ``result`` left weak.

    Parameters
    ----------
    result : IdentificationResult
        A finished identification with its study attached (:func:`tsid_fmu.load` of its
        results folder, or :func:`tsid_fmu.identify`'s return).
    options : DesignOptions, optional
        The family of inputs; default the study file's ``[design]`` table (all defaults
        where it has none).
    workers, timeout
        As :func:`tsid_fmu.identify` (default: in this process, no time limit).
    progress : callable, optional
        Called with a line before each batch of simulations (``tsid design`` prints
        them on a terminal).

    Returns
    -------
    Design
        The proposal (or none, with the reason), the predicted intervals, the
        candidates' scores, the structural findings and the simulations used.
    """
    plan = make_plan(result, options)
    space, x = plan.space, plan.x
    say = progress or (lambda line: None)
    e = _explore(plan, result, workers, timeout, say)
    weak, found, nfev = e["weak"], e["found"], e["nfev"]
    scores, best, keep = _scores(plan, e)
    propose = not (found and weak.shape[1] <= len(found))
    cov = _cov(e["f0"] + e["fishers"][best], keep) if propose else _cov(e["f0"], keep)
    after, used = _predict(plan, e, best, workers, timeout, say) if propose else (None, 0)
    nfev += used
    structural = _structural(space, x, found, cov)
    left = _left_open(result, after, space.names, plan.study.bounds())
    if left:  # its own prediction determines nothing more: no proposal, and say so
        advice = Structural(left, [_terms(space, v) for v in weak.T], [], plan.signals[best].name)
        structural, propose, after = [*structural, advice], False, None
    if tied(result):
        say("the tied structures with every candidate input")
    separate = discriminate(plan, result, workers, timeout)
    if separate is not None:
        nfev += separate["nfev"]
    return Design(
        names=list(space.names),
        values=x,
        criterion=plan.options.criterion,
        inputs=plan.columns,
        limits=plan.limits,
        band=plan.band,
        time=plan.time,
        candidates=[
            {"name": s.name, "kind": s.kind, "score": sc}
            for s, sc in zip(plan.signals, scores, strict=True)
        ],
        proposal=plan.signals[best] if propose else None,
        predicted_outputs=e["outputs"][best] if propose else None,
        output_names=list(plan.template.output_names),
        template=plan.template.name,
        study_intervals={n: list(result.intervals.get(n) or [None, None]) for n in space.names},
        after=None if after is None else [after[n] for n in space.names],
        weak=[_terms(space, v) for v in weak.T],
        structural=structural,
        nfev=nfev,
        separating=None if separate is None else plan.signals[separate["best"]],
        discrimination=separate,
        levels={n: plan.follow[n] for n in space.names} if propose else {},
        warnings=_changes(result),
    )


def _scores(plan: Plan, e: dict[str, Any]) -> tuple[list[float], int, np.ndarray]:
    """Score every candidate in the directions not found structural; the best one.

    Returns the scores, the best candidate's index and those directions (columns).
    """
    dim, f0, weak, found = plan.space.dim, e["f0"], e["weak"], e["found"]
    s_basis = _basis(found, dim)
    keep = np.linalg.svd(np.eye(dim) - s_basis @ s_basis.T)[0][:, : dim - len(found)]
    targets = weak - s_basis @ (s_basis.T @ weak)
    targets = _basis([c for c in targets.T if np.linalg.norm(c) > 0.5], dim)
    if targets.shape[1] == 0:
        targets = keep
    scores = [_score(f0 + f, keep, targets, plan.options.criterion) for f in e["fishers"]]
    return scores, int(np.argmax(scores)), keep


def _left_open(
    result: Any,
    after: Mapping[str, list] | None,
    names: Sequence[str],
    bounds: Mapping[str, tuple[float, float]],
) -> list[str]:
    """Return the parameters the study left open if the prediction closes none of them.

    Empty where there is no prediction, where the study left none open, or where the
    proposal closes at least one: a proposal that determines nothing more is none (a DC
    motor measured by its speed: every parameter open before and after). An end open at
    a finite bound is the bound (an offset whose answer is its bound 0).
    """
    if after is None:
        return []

    def closed(iv: Any, name: str) -> bool:
        low, high = bounds.get(name, (-math.inf, math.inf))
        return None not in (at_bounds(iv, low, high) or [None])

    open_ = [n for n in names if not closed(result.intervals.get(n), n)]
    if not open_ or any(closed(after.get(n), n) for n in open_):
        return []
    return open_


def _changes(result: Any) -> list[str]:
    """Return the warning that the study or its files changed since ``result``'s run."""
    from tsid_fmu.load import study_changes

    out = getattr(result, "out_dir", None)
    return [] if out is None else study_changes(out, result.study)
