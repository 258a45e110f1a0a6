"""Structure identification: the structure stage, then every candidate refined and compared.

1. The structure stage (:mod:`tsid_fmu.search.structure.arrays`) runs mixed arrays of the
   Real parameters and the discrete factors until every discrete factor is fixed, or
   for at most :data:`~tsid_fmu.search.structure.arrays.MAX_ITERATIONS` iterations.
2. The candidate structures: every combination of the levels still open (at most
   :data:`MAX_CANDIDATES`, the best-scoring first), and for each fixed factor its
   runner-up level, so that the choice is always compared with an alternative (all
   combinations where they are at most :data:`MAX_ALL`).
3. Each candidate's free parameters are probed at the best point the arrays saw in it
   (:mod:`tsid_fmu.search.structure.candidates`). The simplest (fewest free parameters) is
   identified as a study of its own over those parameters, from the first levels (the
   Taguchi stage, then the refinement, as the study's method says); every other one by
   a short refinement from the best of its warm starts: the earlier answers it nests,
   embedded in it (its extra parameters fitted to reproduce them), the earlier answers,
   the arrays' best point in it, the centre of the first levels. Kept in the trail as
   ``structure_NN/``.
4. At each candidate's answer: the residuals, the Real parameters that change the
   outputs in that structure (``k``), and, for each pair whose free parameters are
   nested, whether the richer one reproduces the simpler one's fit with its extra
   parameters (then it nests it, and the likelihood-ratio test applies); candidates
   not at their optimum by that nesting are restarted
   (:func:`~tsid_fmu.search.structure.optima.consistent`).
5. :func:`tsid_fmu.search.structure.selection.decide` chooses. Every structure one
   factor's level away from the choice that is no candidate yet is refined from the
   choice's answer, and the comparison is made again, until the choice has no such
   neighbour (:meth:`~tsid_fmu.search.structure.pool.Pool.neighbours`: a local search
   over the structures, for choices of more combinations than the arrays' candidates).
   A choice whose answer came from a
   warm start and is not shown to be an optimum gets a study of its own, or, where the
   choice is a poor fit, the richest candidate without one, until such a study lowers
   no answer (:func:`~tsid_fmu.search.structure.candidates.next_own_study`); the
   comparison is made again.
6. The chosen answer, where its stationarity test held by a trial alone (a cost made
   rough by events) and two of its parameters act through their combination, is
   refined in that combination (:mod:`tsid_fmu.search.local.combined`), and kept where lower.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from tsid_fmu.numerics.tuning import MAX_ALL, MAX_CANDIDATES
from tsid_fmu.search.context import Context
from tsid_fmu.search.local.combined import refine_in_combinations
from tsid_fmu.search.phases.stage import Evaluators
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.search.structure.arrays import DiscreteFactor, StructureRun, structure_stage
from tsid_fmu.search.structure.boundary import score_step, significant, tried
from tsid_fmu.search.structure.candidates import (
    best_point,
    measure_in,
    next_own_study,
    own_again,
    probe,
    simplest_first,
    stationary,
)
from tsid_fmu.search.structure.nesting import at_nesting_point
from tsid_fmu.search.structure.optima import consistent, update
from tsid_fmu.search.structure.pool import Pool
from tsid_fmu.search.structure.selection import Candidate, decide
from tsid_fmu.search.verdict import noise_floor
from tsid_fmu.study.definition import Study

__all__ = ["MAX_CANDIDATES", "StructureResult", "run_structure"]


@dataclass
class StructureResult:
    """What structure identification decided, and the stages it ran.

    ``nested`` lists the pairs ``[simpler, richer]`` of candidate labels where the
    richer structure reproduces the simpler one (None until the comparison ran).
    """

    stages: list[StageResult]
    study: Study
    chosen: int
    tied: list[int]
    candidates: list[Candidate]
    factors: list[DiscreteFactor]
    evaluators: Any = None
    paused: bool = False
    nested: list[list[str]] | None = None

    @property
    def values(self) -> dict[str, float]:
        """The chosen structure's discrete values."""
        return dict(self.candidates[self.chosen].values) if self.candidates else {}

    def table(self) -> list[dict[str, Any]]:
        """Return the rows of the structures table."""
        return [c.row() for c in self.candidates]

    def summary(self) -> dict[str, Any]:
        """Return the choice with its reason, as JSON data (``result.structure``)."""
        if not self.candidates:
            return {}
        pick = self.candidates[self.chosen]
        labels = {f.name: f.labels[f.values.index(pick.values[f.name])] for f in self.factors}
        return {
            "chosen": pick.label,
            "choices": labels,
            "values": dict(pick.values),
            "why": pick.why,
            "indistinguishable": [self.candidates[j].label for j in self.tied],
            "factors": [f.to_dict() for f in self.factors],
            **({"nested": self.nested} if self.nested is not None else {}),
        }


class _Recorder:
    def __init__(self, store: Any, space: Space) -> None:
        self.store, self.space = store, space

    def iteration(self, record: IterationRecord) -> None:
        self.store.write_iteration("structure", record, self.space)


def discrete_factors(study: Study) -> list[DiscreteFactor]:
    """Return the study's choices as discrete factors, their levels in increasing value."""
    out = []
    for c in study.choices:
        pairs = sorted(zip(c.values, c.labels, strict=True))
        out.append(DiscreteFactor(c.name, [v for v, _ in pairs], [lb for _, lb in pairs]))
    return out


def _candidates(
    factors: list[DiscreteFactor], points: list[tuple[float, dict[str, float]]]
) -> list[tuple[dict[str, float], str]]:
    """Return the structures to refine, the arrays' choice first.

    Where the factors' combinations are at most :data:`MAX_ALL`, every one of them (a
    fixed factor's every level: a nested simpler structure scores worse in the arrays,
    so its level is rarely the runner-up); otherwise the open combinations and each
    fixed factor's runner-up.
    """
    fixed = {f.name: f.values[f.fixed] for f in factors if f.fixed is not None}
    open_ = [f for f in factors if f.fixed is None]
    combos = [
        {**fixed, **{f.name: v for f, v in zip(open_, vs, strict=True)}}
        for vs in itertools.product(*(f.values for f in open_))
    ]
    combos.sort(key=lambda v: best_point(points, v)[0])
    out = [(v, "the arrays' choice" if not open_ else "open in the arrays") for v in combos]
    out = out[:MAX_CANDIDATES]
    best = out[0][0]
    if math.prod(len(f.values) for f in factors) <= MAX_ALL:
        rest = [
            dict(zip([f.name for f in factors], vs, strict=True))
            for vs in itertools.product(*(f.values for f in factors))
        ]
        rest = [v for v in rest if v not in [w for w, _ in out]]
        rest.sort(key=lambda v: best_point(points, v)[0])
        for v in rest:
            moved = [f.name for f in factors if f.fixed is not None and v[f.name] != best[f.name]]
            out.append((v, f"another level of {', '.join(moved)} (every level is compared)"))
        return out
    for f in factors:
        if f.fixed is not None and f.runner_up is not None and len(out) < MAX_CANDIDATES:
            alt = {**best, f.name: f.values[f.runner_up]}
            if alt not in [v for v, _ in out]:
                out.append((alt, f"runner-up level of {f.name}"))
    return out


def _structure_stage(ctx: Context, factors: list[DiscreteFactor], make: Callable) -> Any:
    study = ctx.study
    exps = study.identify_names()
    names = [*study.parameter_names, *study.choice_names]
    evaluator = make(study).get(names, exps, {})
    run = StructureRun(
        levels=study.first_levels(),
        bounds=study.bounds(),
        factors=factors,
        method=study.method,
        max_iterations=ctx.control.max_iterations,
    )
    if ctx.progress:
        ctx.progress("stage", {"name": "structure", "message": "structure: mixed arrays"})
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    outcome = structure_stage(run, evaluator, _Recorder(ctx.store, space), ctx.progress)
    ctx.store.write_stage("structure", outcome.stage)
    return outcome


def run_structure(ctx: Context, make: Callable[[Study], Evaluators]) -> StructureResult:
    """Identify structure and parameters; ``make(study)`` gives a study's evaluators.

    (The mixed arrays' own study, or a candidate's, with the structure's values fixed.)
    """
    factors = discrete_factors(ctx.study)
    outcome = _structure_stage(ctx, factors, make)
    found = _candidates(factors, outcome.points)
    probed = [probe(ctx.study, outcome.points, outcome.levels, v, make) for v, _ in found]
    order = simplest_first([len(p[3]) for p in probed])
    pool = Pool(ctx, make, factors)
    cands, all_stages, studies, evs = pool.found()

    def paused(i: int) -> StructureResult:
        return StructureResult([outcome.stage, *all_stages[i]], studies[i], i, [], cands,
                               factors, evs[i], True)  # fmt: skip

    for j in order:
        if pool.add(*found[j], probed[j]):
            return paused(len(cands) - 1)
    owned, left = {0}, set()  # left: the (simpler, richer) pairs whose point was tested
    rescue = True  # own studies for a poor fit go on while they lower an answer
    while True:
        settled = owned | {i for i, st in enumerate(all_stages) if stationary(st)}
        nested = consistent(cands, studies, evs, pool.restart, started=pool.started,
                            settled=settled, cache=pool.cache)  # fmt: skip
        pool.started |= set(nested)
        degenerate = {(s, r) for (s, r), e in nested.items()
                      if at_nesting_point(ctx.study, cands[s], cands[r], e)}  # fmt: skip
        if _leave(ctx, (cands, studies, evs), degenerate, left, pool.restart):
            continue  # a richer answer moved off its nesting point: compare again
        chosen, tied = decide(cands, set(nested), degenerate)
        steps = pool.neighbours(chosen)
        for values, why in steps:  # one level away from the choice: refined, compared
            at = {**{n: cands[chosen].x[n] for n in ctx.study.parameter_names}, **values}
            if pool.add(values, why, probe(ctx.study, [(0.0, at)], outcome.levels, values, make)):
                return paused(len(cands) - 1)
        if steps:
            continue
        floor = _floor(ctx.study, evs[chosen])
        target = next_own_study(chosen, owned, all_stages, cands, floor, rescue)
        if target is None:
            break
        owned.add(target)
        before, for_fit = cands[target].cost, target != chosen
        if own_again(ctx, target, cands[target], pool.owns[target], evs[target], all_stages):
            return paused(target)
        got = cands[target]
        if for_fit and not significant(before - got.cost, got.chi2, got.n):
            rescue = False  # the warm starts were not stuck: no more own studies for it
    return _result(ctx, outcome, factors, pool.found(), chosen, tied, nested)


def _floor(study: Study, evs: Evaluators) -> float:
    """Return the noise floor of a structure's cost (every Real parameter, fitted data)."""
    ev = evs.get(study.parameter_names, study.identify_names(), {})
    return noise_floor(ev, study.method.weighting == "noise")


def _leave(
    ctx: Context, found: tuple, degenerate: set[tuple[int, int]], left: set, restart: Callable
) -> bool:
    """Test each richer answer at a nesting point for a lower point off it; refine there.

    The score test of :mod:`~tsid_fmu.search.structure.boundary`, once per pair: where moving off
    the nesting point predicts a decrease beyond BIC's charge for one parameter, and
    the step (or its half) gives one, the richer candidate is restarted from there (kept
    where lower). Returns whether one moved.
    """
    cands, studies, evs = found
    moved = False
    for s, r in sorted(degenerate - left):
        left.add((s, r))
        big, small, sub = cands[r], cands[s], studies[r]
        if big.residuals is None or not big.residuals.size or not math.isfinite(big.cost):
            continue  # a failed answer: nothing to test from
        names = sub.parameter_names
        extra = [n for n in big.active if n not in small.active]
        ev = evs[r].get(names, sub.identify_names(), {})
        gap, point, runs = score_step(
            ev, names, big.x, big.residuals, extra, sub.first_levels(), sub.bounds()
        )
        big.nfev += runs
        if not significant(gap, big.chi2, big.n):
            continue
        point, cost, runs = tried(ev, big.x, point)  # the prediction, checked by two runs
        big.nfev += runs
        if significant(big.cost - cost, big.cost, big.n):
            why = f"off {small.label}'s nesting point (score test: {big.cost - cost:.3g} lower)"
            moved = restart(r, point, why) or moved
    return moved


def _combinations(ctx: Context, i: int, found: tuple) -> None:
    """Refine candidate ``i``'s answer in the combinations the data fix, where lower."""
    cands, all_stages, studies, evs = found
    lower, runs = refine_in_combinations(studies[i], evs[i], all_stages[i], ctx.progress)
    cands[i].nfev += runs
    if lower is not None:
        ctx.store.write_stage(f"{cands[i].folder}/combinations", lower)
        all_stages[i].append(lower)
        update(cands[i], measure_in(ctx.study, evs[i], lower.x))
        cands[i].origin += "; refined in the combinations the data fix"


def _result(
    ctx: Context,
    outcome: Any,
    factors: list[DiscreteFactor],
    found: tuple[list[Candidate], list[list[StageResult]], list[Study], list[Evaluators]],
    chosen: int,
    tied: list[int],
    nested: Mapping[tuple[int, int], Any],
) -> StructureResult:
    """Assemble the result: the arrays, the other structures, the comparison, the chosen.

    The chosen answer is first refined in the combinations the data fix, where that
    lowers it (:func:`_combinations`).
    """
    _combinations(ctx, chosen, found)
    cands, all_stages, studies, evs = found
    stages = [outcome.stage]
    for i, (cand, st) in enumerate(zip(cands, all_stages, strict=True)):
        if i != chosen:
            stages.append(_summary(cand, st))
            ctx.store.write_stage(f"structure_{i + 1:02d}", stages[-1])
    pick = cands[chosen]
    checks = pick.nfev - sum(s.nfev for s in all_stages[chosen])
    stages.append(
        StageResult(
            name="structure comparison",
            kind=StageKind.COMPARISON,
            x={**pick.x, **pick.values},
            cost=pick.cost,
            nfev=checks,
            message=f"chose {pick.label}: {pick.why}",
            experiments=list(all_stages[chosen][-1].experiments),
            extra={"structures": [c.row() for c in cands]},
        )
    )
    ctx.store.write_stage("structure_comparison", stages[-1])
    stages += all_stages[chosen]
    result = StructureResult(stages, studies[chosen], chosen, tied, cands, factors, evs[chosen])
    result.nested = sorted([cands[s].label, cands[r].label] for s, r in nested)
    for j, ev in enumerate(evs):
        if j != chosen:
            ev.close()
    return result


def _summary(cand: Candidate, stages: list[StageResult]) -> StageResult:
    """One stage standing for a structure not chosen (its stages lie in its folder)."""
    return StageResult(
        name=f"structure {cand.label}",
        kind=StageKind.CANDIDATE,
        x={**cand.x, **cand.values},
        cost=cand.cost,
        nfev=cand.nfev,
        message=f"{cand.origin}; {cand.why}",
        status=0,  # a structure not chosen: its stages' limits are not the answer's
        experiments=list(stages[-1].experiments),
        extra={"structure": cand.values, "stages": [s.name for s in stages]},
    )
