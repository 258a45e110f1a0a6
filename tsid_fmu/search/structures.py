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
from tsid_fmu.search.context import Context, polish
from tsid_fmu.search.frame import Frame
from tsid_fmu.search.optima import at_nesting_point, consistent, measure, update, warm_start
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

MAX_ALL = 6
"""Where the discrete factors' combinations are at most this many, every one of them is a
candidate (a fixed factor's other levels too, not only its runner-up)."""


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
    combos.sort(key=lambda v: _best_point(points, v)[0])
    out = [(v, "the arrays' choice" if not open_ else "open in the arrays") for v in combos]
    out = out[:MAX_CANDIDATES]
    best = out[0][0]
    if math.prod(len(f.values) for f in factors) <= MAX_ALL:
        rest = [
            dict(zip([f.name for f in factors], vs, strict=True))
            for vs in itertools.product(*(f.values for f in factors))
        ]
        rest = [v for v in rest if v not in [w for w, _ in out]]
        rest.sort(key=lambda v: _best_point(points, v)[0])
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


def _sub_study(
    study: Study,
    values: Mapping[str, float],
    levels: Mapping[str, list[float]],
    x: Mapping[str, float] | None,
) -> Study:
    """Return the study of one structure: its values fixed, the Real levels centred on ``x``."""
    return dataclasses.replace(
        study,
        parameters=_centred(study, levels, x),
        choices=[],
        start_values={**study.start_values, **values},
        source=None,
    )


def _measure(study: Study, evs: Evaluators, x: Mapping[str, float]) -> dict[str, Any]:
    """Measure ``x`` with a structure's evaluators (steps in ``study``'s coordinates)."""
    names = study.parameter_names
    exps = [e.name for e in study.identify_experiments()]
    checks = [e.name for e in study.experiments if e.role == "validate"]

    def validate(p: dict[str, float]) -> float | None:
        if not checks:
            return None
        return float(evs.get(names, checks, {}).evaluate([p]).costs[0, 0])

    return measure(evs.get(names, exps, {}), study, x, validate)


def _identify_candidate(
    ctx: Context,
    i: int,
    values: dict[str, float],
    origin: str,
    sub: Study,
    evs: Evaluators,
    warm: list[tuple[dict[str, float], str]] | None,
) -> tuple[Candidate, list[StageResult]]:
    """Identify one structure and measure its fit, k and validation cost.

    Without ``warm``: the existing stages (the structure's study of its own). With
    ``warm`` (start points): the refinement from the best of them.
    """
    from tsid_fmu.search.pipeline import run_stages

    store = _Prefixed(ctx.store, f"structure_{i + 1:02d}")
    names = ctx.study.parameter_names
    if warm is None:
        stages = run_stages(sub, evs, store, ctx.progress, ctx.control)
        tried = []
    else:
        exps = [e.name for e in sub.identify_experiments()]
        stage, start, _ = warm_start(evs.get(names, exps, {}), sub, warm, ctx.progress)
        store.write_stage("refinement", stage)
        stages, tried = [stage], [start]
    answer = answer_stage(stages)
    found = _measure(ctx.study, evs, {n: float(answer.x[n]) for n in names})
    cand = Candidate(label="", values=dict(values), x={}, cost=math.inf, chi2=math.inf, n=0,
                     k=0, active=[], nfev=sum(s.nfev for s in stages), origin=origin,
                     extra={"folder": f"structure_{i + 1:02d}", "tried": tried})  # fmt: skip
    update(cand, found)
    return cand, stages


def _warm_starts(
    study: Study, cands: list[Candidate], best: dict[str, float] | None
) -> list[tuple[dict[str, float], str]]:
    """Return a later candidate's start points: earlier answers, arrays' best, centre."""
    names = study.parameter_names
    out = [(dict(c.x), f"the answer of {c.label}") for c in sorted(cands, key=lambda c: c.cost)]
    if best is not None:
        out.append(({n: best[n] for n in names}, "the arrays' best point in it"))
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    out.append((space.to_x(space.clip(np.zeros(space.dim))), "the centre of the first levels"))
    return out


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
        best = _best_point(outcome.points, values)[1]
        sub = _sub_study(ctx.study, values, outcome.levels, best)
        ev = make(sub)
        # the arrays' choice: a study of its own; the others from warm starts
        warm = _warm_starts(ctx.study, cands, best) if cands else None
        cand, stages = _identify_candidate(ctx, i, values, origin, sub, ev, warm)
        cand.label = _label(factors, values)
        cands.append(cand)
        all_stages.append(stages)
        studies.append(sub)
        evs.append(ev)
        if stages[-1].status == 2:
            return StructureResult([outcome.stage, *stages], sub, i, [], cands, factors, ev, True)

    def restart(i: int, start: dict[str, float], why: str) -> bool:
        cand, names = cands[i], studies[i].parameter_names
        exps = [e.name for e in studies[i].identify_experiments()]
        ev = evs[i].get(names, exps, {})
        n_restart = sum(1 for s in all_stages[i] if s.name.startswith("restart")) + 1
        stage = polish(f"restart {n_restart}: {why}", studies[i], start, ev, ctx.progress)
        cand.extra.setdefault("tried", []).append(dict(start))
        cand.nfev += stage.nfev
        if not stage.cost < cand.cost:
            return False
        ctx.store.write_stage(f"{cand.extra['folder']}/restart_{n_restart:02d}", stage)
        all_stages[i].append(stage)
        update(cand, _measure(ctx.study, evs[i], stage.x))
        cand.origin += f"; restarted {why}"
        return True

    nested = consistent(cands, studies, evs, restart)
    degenerate = {
        (s, r) for (s, r), e in nested.items() if at_nesting_point(ctx.study, cands[s], cands[r], e)
    }
    chosen, tied = decide(cands, set(nested), degenerate)
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
