"""Structure identification: the structure stage, then every candidate refined and compared.

1. The structure stage (:mod:`tsid_fmu.search.structure`) runs mixed arrays of the
   Real parameters and the discrete factors until every discrete factor is fixed (or
   the stage ends with some open).
2. The candidate structures: every combination of the levels still open (at most
   :data:`MAX_CANDIDATES`, the best-scoring first), and for each fixed factor its
   runner-up level, so that the choice is always compared with an alternative.
3. Each candidate is identified as a study of its own (the study's Real parameters,
   the structure's values fixed): the existing stages (the Taguchi stage from levels
   centred on the best set the arrays saw in that structure, then the refinement,
   restarts or check, as the study's method says), kept in the trail as
   ``structure_NN/``.
4. At each candidate's optimum: the residuals, the Real parameters that change the
   outputs in that structure (``k``), and, for each pair whose free parameters are
   nested, whether the richer one reproduces the simpler one's fit with its extra
   parameters (then it nests it, and the likelihood-ratio test applies).
5. :func:`tsid_fmu.search.selection.decide` chooses.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.search.adaptive import answer_stage
from tsid_fmu.search.context import Context
from tsid_fmu.search.frame import Frame
from tsid_fmu.search.phases import Evaluators
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.selection import Candidate, decide
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.structure import DiscreteFactor, StructureRun, structure_stage
from tsid_fmu.study.definition import Study
from tsid_fmu.study.schema import Parameter

__all__ = ["MAX_CANDIDATES", "StructureResult", "run_structure"]

MAX_CANDIDATES = 8
"""Most candidate structures refined at the end."""

ACTIVE_STEP = 0.01
"""Step (in search coordinates: a fraction of the first levels' range) by which each Real
parameter is moved to see whether it changes the outputs in a structure."""

REPRODUCE = 0.01
"""A richer structure nests a simpler one where its extra parameters reproduce the
simpler one's fitted outputs to within this fraction of one noise variance in total."""


@dataclass
class StructureResult:
    """What structure identification decided, and the stages it ran."""

    stages: list[StageResult]
    study: Study
    chosen: int
    tied: list[int]
    candidates: list[Candidate]
    factors: list[DiscreteFactor]
    evaluators: Any = None
    paused: bool = False
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def values(self) -> dict[str, float]:
        """The chosen structure's discrete values."""
        return dict(self.candidates[self.chosen].values) if self.candidates else {}

    def table(self) -> list[dict[str, Any]]:
        """Return the rows of the structures table."""
        return [c.row() for c in self.candidates]

    def summary(self) -> dict[str, Any]:
        """Return the choice with its reason, as JSON data (``result.extra["structure"]``)."""
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
            **self.extra,
        }


class _Prefixed:
    """A stage store whose keys lie under one folder (a candidate's stages)."""

    def __init__(self, store: Any, prefix: str) -> None:
        self.store, self.prefix = store, prefix

    def _k(self, key: str) -> str:
        return f"{self.prefix}/{key or 'taguchi'}"

    def iterations(self, key: str) -> list[IterationRecord]:
        return self.store.iterations(self._k(key))

    def override(self, key: str, record: IterationRecord, space: Space) -> Frame | None:
        return self.store.override(self._k(key), record, space)

    def stage(self, key: str) -> StageResult | None:
        return self.store.stage(self._k(key))

    def write_iteration(self, key: str, record: IterationRecord, space: Space) -> None:
        self.store.write_iteration(self._k(key), record, space)

    def write_stage(self, key: str, result: StageResult) -> None:
        self.store.write_stage(self._k(key), result)


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


def _label(factors: list[DiscreteFactor], values: Mapping[str, float]) -> str:
    return ", ".join(f"{f.name}={f.labels[f.values.index(values[f.name])]}" for f in factors)


def _candidates(
    factors: list[DiscreteFactor], points: list[tuple[float, dict[str, float]]]
) -> list[tuple[dict[str, float], str]]:
    """Return the structures to refine: open combinations, then each fixed factor's runner-up."""
    fixed = {f.name: f.values[f.fixed] for f in factors if f.fixed is not None}
    open_ = [f for f in factors if f.fixed is None]
    combos = [
        {**fixed, **{f.name: v for f, v in zip(open_, vs, strict=True)}}
        for vs in itertools.product(*(f.values for f in open_))
    ]
    combos.sort(key=lambda v: _best_point(points, v)[0])
    out = [(v, "the arrays' choice" if not open_ else "open in the arrays") for v in combos]
    out = out[:MAX_CANDIDATES]
    best = out[0][0]
    for f in factors:
        if f.fixed is not None and f.runner_up is not None and len(out) < MAX_CANDIDATES:
            alt = {**best, f.name: f.values[f.runner_up]}
            if alt not in [v for v, _ in out]:
                out.append((alt, f"runner-up level of {f.name}"))
    return out


def _best_point(
    points: list[tuple[float, dict[str, float]]], values: Mapping[str, float]
) -> tuple[float, dict[str, float] | None]:
    inside = [
        (c, x) for c, x in points if math.isfinite(c) and all(x[k] == v for k, v in values.items())
    ]
    return min(inside, key=lambda p: p[0]) if inside else (math.inf, None)


def _centred(
    study: Study, levels: Mapping[str, list[float]], x: Mapping[str, float] | None
) -> list[Parameter]:
    """Return the Real parameters with the structure stage's last levels, moved onto ``x``."""
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    out = []
    for j, p in enumerate(study.parameters):
        lv = sorted(levels[p.name])
        if x is not None:
            s = np.array([space.coordinate(j, v) for v in lv])
            shift = space.coordinate(j, x[p.name]) - 0.5 * (s[0] + s[-1])
            moved = [space.value(j, v + shift) for v in s]
            lv = moved if len(set(moved)) == len(moved) else lv
        out.append(dataclasses.replace(p, levels=lv))
    return out


def _active(ev: Any, study: Study, x: Mapping[str, float], r0: np.ndarray) -> list[str]:
    """Return the Real parameters that change the outputs at ``x`` (the structure's free ones)."""
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    sets = []
    for j, n in enumerate(space.names):
        s = space.coordinate(j, x[n])
        v = space.value(j, s + ACTIVE_STEP)
        v = v if v != x[n] else space.value(j, s - ACTIVE_STEP)
        sets.append({**x, n: v})
    ev_out = ev.evaluate(sets)
    tol = 1e-9 * max(float(np.linalg.norm(r0)), 1e-300)
    out = []
    for n, r in zip(space.names, ev_out.residuals or [None] * len(sets), strict=True):
        if r is None or float(np.linalg.norm(r - r0)) > tol:
            out.append(n)
    return out


def _reproduces(
    ev: Any, study: Study, small: Candidate, big: Candidate, r_small: np.ndarray
) -> bool:
    """Whether ``big`` reproduces ``small``'s fit with its extra parameters (nesting)."""
    from scipy.optimize import least_squares

    extra = [n for n in big.active if n not in small.active]
    base = {**big.x, **{n: small.x[n] for n in small.active}}
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    idx = [space.names.index(n) for n in extra]
    bad = np.full(r_small.shape, 1e6)

    def diff(s: np.ndarray) -> np.ndarray:
        x = {**base, **{n: space.value(j, float(v)) for n, j, v in zip(extra, idx, s, strict=True)}}
        r = ev.evaluate([x]).residuals
        return bad if not r or r[0] is None else r[0] - r_small

    start = np.array([space.coordinate(j, big.x[n]) for n, j in zip(extra, idx, strict=True)])
    lo = np.array([space.s_lower[j] for j in idx])
    hi = np.array([space.s_upper[j] for j in idx])
    fit = least_squares(
        diff, np.clip(start, lo, hi), bounds=(lo, hi), max_nfev=20 * (len(extra) + 1)
    )
    return 2 * float(fit.cost) <= REPRODUCE * small.chi2 / max(small.n, 1)


def _identify_candidate(
    ctx: Context,
    i: int,
    values: dict[str, float],
    origin: str,
    start: tuple[float, dict[str, float] | None],
    levels: Mapping[str, list[float]],
    make: Callable[[Study], Evaluators],
) -> tuple[Candidate, list[StageResult], Study, Evaluators]:
    """Run the existing stages on one structure; measure its fit, k and validation cost."""
    from tsid_fmu.search.pipeline import run_stages

    study = ctx.study
    sub = dataclasses.replace(
        study,
        parameters=_centred(study, levels, start[1]),
        choices=[],
        start_values={**study.start_values, **values},
        source=None,
    )
    evs = make(sub)
    store = _Prefixed(ctx.store, f"structure_{i + 1:02d}")
    stages = run_stages(sub, evs, store, ctx.progress, ctx.control)
    answer = answer_stage(stages)
    names = study.parameter_names
    x = {n: float(answer.x[n]) for n in names}
    exps = [e.name for e in study.identify_experiments()]
    ev = evs.get(names, exps, {})
    n0 = ev.nfev
    scored = ev.evaluate([x])
    r0 = scored.residuals[0] if scored.residuals else None
    r0 = np.zeros(0) if r0 is None else np.asarray(r0)
    active = _active(ev, study, x, r0) if r0.size else list(names)
    checks = [e.name for e in study.experiments if e.role == "validate"]
    vcost = None
    if checks:
        vcost = float(evs.get(names, checks, {}).evaluate([x]).costs[0, 0])
    cand = Candidate(
        label="",
        values=dict(values),
        x=x,
        cost=float(scored.costs[0, 0]),
        chi2=float(r0 @ r0) if r0.size else math.inf,
        n=int(r0.size),
        k=len(active),
        active=active,
        nfev=sum(s.nfev for s in stages) + ev.nfev - n0,
        origin=origin,
        validation=vcost,
        extra={"residuals": r0, "folder": f"structure_{i + 1:02d}"},
    )
    return cand, stages, sub, evs


def _nesting(
    cands: list[Candidate], studies: list[Study], evs: list[Evaluators]
) -> set[tuple[int, int]]:
    """Pairs (s, r): r's free parameters include s's and r reproduces s's fit."""
    pairs = set()
    for s, r in itertools.permutations(range(len(cands)), 2):
        small, big = cands[s], cands[r]
        if not (set(small.active) < set(big.active)) or not small.n or not big.n:
            continue
        exps = [e.name for e in studies[r].identify_experiments()]
        ev = evs[r].get(studies[r].parameter_names, exps, {})
        n0 = ev.nfev
        if _reproduces(ev, studies[r], small, big, small.extra["residuals"]):
            pairs.add((s, r))
        big.nfev += ev.nfev - n0
    return pairs


def _structure_stage(ctx: Context, factors: list[DiscreteFactor], make: Callable) -> Any:
    study = ctx.study
    exps = [e.name for e in study.identify_experiments()]
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
    """Identify structure and parameters (see the module docstring).

    ``make(study)`` returns the evaluators of a study (for the mixed arrays, the
    study itself; for a candidate, the study with the structure's values fixed).
    """
    factors = discrete_factors(ctx.study)
    outcome = _structure_stage(ctx, factors, make)
    found = _candidates(factors, outcome.points)
    cands, all_stages, studies, evs = [], [], [], []
    for i, (values, origin) in enumerate(found):
        if ctx.progress:
            label = _label(factors, values)
            ctx.progress("stage", {"name": f"structure {i + 1}", "message": f"structure {label}"})
        best = _best_point(outcome.points, values)
        cand, stages, sub, ev = _identify_candidate(
            ctx, i, values, origin, best, outcome.levels, make
        )
        cand.label = _label(factors, values)
        cands.append(cand)
        all_stages.append(stages)
        studies.append(sub)
        evs.append(ev)
        if stages[-1].status == 2:
            return StructureResult([outcome.stage, *stages], sub, i, [], cands, factors, ev, True)
    nested = _nesting(cands, studies, evs)
    chosen, tied = decide(cands, nested)
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
            kind="comparison",
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
    result.extra["nested"] = sorted([cands[s].label, cands[r].label] for s, r in nested)
    for j, ev in enumerate(evs):
        if j != chosen:
            ev.close()
    return result


def _summary(cand: Candidate, stages: list[StageResult]) -> StageResult:
    """One stage standing for a structure not chosen (its stages lie in its folder)."""
    return StageResult(
        name=f"structure {cand.label}",
        kind="candidate",
        x={**cand.x, **cand.values},
        cost=cand.cost,
        nfev=cand.nfev,
        message=f"{cand.origin}; {cand.why}",
        status=0,  # a structure not chosen: its stages' limits are not the answer's
        experiments=list(stages[-1].experiments),
        extra={"structure": cand.values, "stages": [s.name for s in stages]},
    )
