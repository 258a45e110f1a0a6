"""The candidate structures' own studies: which structure gets one, and over what.

Structure identification (:mod:`tsid_fmu.search.structure.compare`) refines every candidate
structure to its own optimum. A study of its own (the Taguchi stage from the first
levels, then the refinement) reaches an optimum from far away, but costs what one
identification costs; a refinement from a warm start (another structure's answer) costs
a fraction of that, but can stop where the warm start's structure put the parameters it
shares. So:

- **Probe** (:func:`probe`): at the best point the mixed arrays saw in a structure, the
  Real parameters that change its outputs there (its free parameters).
- **Simplest first** (:func:`simplest_first`): the structure with the fewest free
  parameters gets a study of its own, over those parameters only (the others held: they
  do not change its outputs); every other structure is refined from warm starts.
- **Own study where it is chosen** (:func:`needs_own_study`): a structure the comparison
  chooses whose answer came from a warm start and is not shown to be an optimum gets a
  study of its own too; where the choice is a poor fit, the richest structure without
  one (:func:`next_own_study`); the comparison is made again.

Measured on the SISO friction laws (``benchmarks/structure.py``, ``docs/dev/structure-
diagnosis.md``): law 3 refined from law 1's answer (whose spring damping absorbs the
viscous friction law 1 lacks) stopped at 5 to 7 times its optimum's cost; law 3's own
study from the richest-first order crawled at 3e11 on law-1 data, where law 1's own
study over its four free parameters reaches its optimum in the simulations of one
identification of law 1.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.search.context import Context
from tsid_fmu.search.local.adaptive import answer_stage, verdict
from tsid_fmu.search.phases.stage import Evaluators
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.structure.nesting import embed, slack
from tsid_fmu.search.structure.optima import measure, short, update, warm_start
from tsid_fmu.search.structure.selection import Candidate
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.verdict import POOR_FIT
from tsid_fmu.study.definition import Study
from tsid_fmu.study.schema import Parameter

__all__ = [
    "Prefixed",
    "best_point",
    "embedded_answers",
    "identify_candidate",
    "measure_in",
    "needs_own_study",
    "next_own_study",
    "own_again",
    "own_study",
    "probe",
    "short",
    "simplest_first",
    "stationary",
    "warm_starts",
]


def simplest_first(free: Sequence[int]) -> list[int]:
    """Order the candidates by their free parameters (``free[j]``), fewest first.

    Ties keep their order (the arrays' ranking). A structure the arrays never scored
    (``0``) comes first: it gets a study of its own, as nothing warm starts it.
    """
    return sorted(range(len(free)), key=lambda j: (free[j], j))


def own_study(
    study: Study,
    values: Mapping[str, float],
    active: Sequence[str],
    held_at: Mapping[str, float] | None,
) -> Study:
    """Return a structure's own study: its free parameters from the first levels.

    ``study`` is the structure study (every Real parameter, its first levels); the
    parameters not in ``active`` are held at ``held_at`` (the arrays' best point in the
    structure) or the centre of their first levels. Without ``active`` (nothing probed)
    every parameter is kept.
    """
    keep = [p for p in study.parameters if p.name in set(active)] or list(study.parameters)
    names = {p.name for p in keep}
    held = {
        p.name: float(held_at[p.name]) if held_at else float(sorted(p.levels)[len(p.levels) // 2])
        for p in study.parameters
        if p.name not in names
    }
    return _structure_study(study, {**values, **held}, keep)


def _structure_study(study: Study, fixed: Mapping[str, float], parameters: list) -> Study:
    """Return ``study`` with ``fixed`` set as start values and these Real ``parameters``."""
    return dataclasses.replace(
        study,
        parameters=parameters,
        choices=[],
        start_values={**study.start_values, **fixed},
        source=None,
    )


def completed(stages: list[StageResult], study: Study, own: Study) -> list[StageResult]:
    """Put the held parameters of ``own`` into its stages' answers (every Real parameter)."""
    held = {n: float(own.start_values[n]) for n in study.parameter_names
            if n not in own.parameter_names}  # fmt: skip
    for s in stages:
        if s.x:
            s.x = {**held, **s.x}
    return stages


def stationary(stages: Sequence[StageResult]) -> bool:
    """Whether a candidate's answer is shown to be an optimum (its stationarity test)."""
    found = verdict(stages)
    return found is not None and found[0] == 0


def needs_own_study(i: int, owned: set[int], stages: Sequence[StageResult]) -> bool:
    """Whether the chosen candidate ``i`` should get a study of its own.

    Where it has none yet and its answer (from a warm start) is not shown to be an
    optimum: the choice rests on its cost, and a warm start can stop above its optimum.
    """
    return i not in owned and not stationary(stages)


def next_own_study(
    chosen: int,
    owned: set[int],
    stages: Sequence[Sequence[StageResult]],
    cands: Sequence[Candidate],
    floor: float,
    rescue: bool = True,
) -> int | None:
    """Return the candidate to give a study of its own next, or None.

    The chosen one where :func:`needs_own_study` says so. Otherwise, where the chosen
    answer is a poor fit (its cost above :data:`~tsid_fmu.search.verdict.POOR_FIT`
    times the noise floor ``floor``) and ``rescue`` holds, the richest candidate
    without one (most free parameters): a warm start of the structure that fits can
    stop above a simpler one's cost, and is then never chosen (measured on the friction
    laws' evaluation seeds 3 and 5 of law 3: law 3's warm start stuck at or above laws
    1 and 2, at 1e7 times the noise floor; law 2 reported "indistinguishable" from law
    1). The caller clears ``rescue`` once such a study lowers no answer by more than
    BIC's charge for one parameter: the warm starts were not stuck, and the poor fit is
    the model's (real data: the Cascaded Tanks' every structure is 96 times the floor
    or more, and an own study for each of 15 candidates made the study 30217
    simulations where it takes 13195 with the rule, for the same choice).
    """
    if needs_own_study(chosen, owned, stages[chosen]):
        return chosen
    if not rescue or not cands[chosen].cost > POOR_FIT * floor:
        return None
    rest = [i for i in range(len(cands)) if i not in owned]
    return max(rest, key=lambda i: (cands[i].k, -i)) if rest else None


def run_own(
    study: Study,
    own: Study,
    make: Callable[[Study], Any],
    store: Any,
    progress: Any,
    control: Any,
) -> list[StageResult]:
    """Run a structure's own study (its evaluators closed after); answers completed."""
    from tsid_fmu.search.pipeline import run_stages

    evs = make(own)
    try:
        stages = run_stages(own, evs, store, progress, control)
    finally:
        evs.close()
    return completed(stages, study, own)


class Prefixed:
    """A stage store whose keys lie under one folder (a candidate's stages)."""

    def __init__(self, store: Any, prefix: str) -> None:
        self.store, self.prefix = store, prefix

    def _k(self, key: str) -> str:
        return f"{self.prefix}/{key or 'taguchi'}"

    def iterations(self, key: str) -> list[IterationRecord]:
        """Return the stage's iterations kept under the prefix."""
        return self.store.iterations(self._k(key))

    def override(self, key: str, record: IterationRecord, space: Space) -> Frame | None:
        """Return a person's override of the next levels, if any."""
        return self.store.override(self._k(key), record, space)

    def stage(self, key: str) -> StageResult | None:
        """Return the finished stage kept under the prefix, if any."""
        return self.store.stage(self._k(key))

    def write_iteration(self, key: str, record: IterationRecord, space: Space) -> None:
        """Keep an iteration under the prefix."""
        self.store.write_iteration(self._k(key), record, space)

    def write_stage(self, key: str, result: StageResult) -> None:
        """Keep a finished stage under the prefix."""
        self.store.write_stage(self._k(key), result)


def best_point(
    points: list[tuple[float, dict[str, float]]], values: Mapping[str, float]
) -> tuple[float, dict[str, float] | None]:
    """Return the lowest cost the arrays saw in a structure (``values``), and its set."""
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
    return _structure_study(study, values, _centred(study, levels, x))


def measure_in(study: Study, evs: Evaluators, x: Mapping[str, float]) -> dict[str, Any]:
    """Measure ``x`` with a structure's evaluators (steps in ``study``'s coordinates)."""
    names = study.parameter_names
    exps = study.identify_names()
    checks = [e.name for e in study.experiments if e.role == "validate"]

    def validate(p: dict[str, float]) -> float | None:
        if not checks:
            return None
        return float(evs.get(names, checks, {}).evaluate([p]).costs[0, 0])

    return measure(evs.get(names, exps, {}), study, x, validate)


def identify_candidate(
    ctx: Context,
    i: int,
    values: dict[str, float],
    origin: str,
    own: tuple[Study, Callable[[Study], Evaluators]] | None,
    sub: Study,
    evs: Evaluators,
    warm: list[tuple[dict[str, float], str]] | None,
) -> tuple[Candidate, list[StageResult]]:
    """Identify one structure and measure its fit, k and validation cost.

    With ``own`` (its own study and how to make evaluators): that study's stages. With
    ``warm`` (start points): the refinement from the best of them.
    """
    store = Prefixed(ctx.store, f"structure_{i + 1:02d}")
    names = ctx.study.parameter_names
    if own is not None:
        study, make = own
        stages = run_own(ctx.study, study, make, store, ctx.progress, ctx.control)
        tried = []
    else:
        exps = sub.identify_names()
        stage, start, _ = warm_start(evs.get(names, exps, {}), short(sub), warm or [], ctx.progress)
        store.write_stage("refinement", stage)
        stages, tried = [stage], [start]
    answer = answer_stage(stages)
    found = measure_in(ctx.study, evs, {n: float(answer.x[n]) for n in names})
    cand = Candidate(label="", values=dict(values), x={}, cost=math.inf, chi2=math.inf, n=0,
                     k=0, active=[], nfev=sum(s.nfev for s in stages), origin=origin,
                     folder=f"structure_{i + 1:02d}", tried=tried)  # fmt: skip
    update(cand, found)
    return cand, stages


def embedded_answers(
    study: Study,
    cands: list[Candidate],
    active: list[str],
    best: dict[str, float] | None,
    evs: Evaluators,
) -> tuple[list[tuple[int, dict[str, float], str]], int]:
    """Return an earlier answer a structure nests, embedded in it, and the runs spent.

    One earlier candidate whose free parameters are a subset of ``active`` is tried: the
    lowest-cost one (among those as good as the lowest, to within what an embedding may
    differ, :func:`~tsid_fmu.search.structure.nesting.slack`, the simplest: measured on the SISO
    friction laws, law 2's answer at law 1's fit did not embed in law 3 after 78 runs,
    law 1's did after 18). Where this structure's extra parameters reproduce its answer
    (:func:`~tsid_fmu.search.structure.nesting.embed`, from ``best`` or the centre of the first
    levels) it is returned as ``[(index, point, label)]``, else nothing. Only the
    lowest-cost start is refined from (:func:`~tsid_fmu.search.structure.optima.warm_start`), and an
    embedding costs up to 20 runs per extra parameter: measured on the SISO friction
    laws, a second one cost 16 to 78 runs and was never the start; where the first did
    not embed, the next did not either (law-1 data, dev seed 107: law 1's answer in law 3
    after 144 runs, law 2's after 77).
    """
    names = study.parameter_names
    ev = evs.get(names, study.identify_names(), {})
    n0 = ev.nfev
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    x0 = best if best is not None else space.to_x(space.clip(np.zeros(space.dim)))
    nested = [s for s, c in enumerate(cands) if c.n and set(c.active) < set(active)]
    if not nested:
        return [], 0
    lowest = min((cands[s] for s in nested), key=lambda c: c.chi2)
    tie = lowest.chi2 + slack(lowest)  # answers within what an embedding may differ: one fit

    def order(s: int) -> tuple:
        c = cands[s]
        return (c.chi2 > tie, c.k if c.chi2 <= tie else 0, c.chi2, s)

    s = min(nested, key=order)
    ok, point = embed(ev, study, cands[s], active, {n: float(x0[n]) for n in names})
    return ([(s, point, cands[s].label)] if ok else []), ev.nfev - n0


def warm_starts(
    study: Study,
    cands: list[Candidate],
    best: dict[str, float] | None,
    embedded: list[tuple[int, dict[str, float], str]] = (),  # type: ignore[assignment]
) -> list[tuple[dict[str, float], str]]:
    """Return a later candidate's start points.

    The earlier answers it nests, embedded; the earlier answers as they are; the arrays'
    best point in it; the centre of the first levels.
    """
    names = study.parameter_names
    out = [(dict(p), f"the answer of {label} embedded") for _, p, label in embedded]
    out += [(dict(c.x), f"the answer of {c.label}") for c in sorted(cands, key=lambda c: c.cost)]
    if best is not None:
        out.append(({n: best[n] for n in names}, "the arrays' best point in it"))
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    out.append((space.to_x(space.clip(np.zeros(space.dim))), "the centre of the first levels"))
    return out


def probe(
    study: Study,
    points: list[tuple[float, dict[str, float]]],
    levels: Mapping[str, list[float]],
    values: dict[str, float],
    make: Callable[[Study], Evaluators],
) -> tuple[Study, Evaluators, dict[str, float] | None, list[str], int]:
    """Return a structure's study, evaluators, arrays' best point, free parameters there, runs.

    The free parameters (those that change the outputs) are counted at the best point
    the arrays saw in the structure (:func:`~tsid_fmu.search.structure.optima.measure`, one run
    per Real parameter); a structure the arrays never scored counts none.
    """
    best = best_point(points, values)[1]
    sub = _sub_study(study, values, levels, best)
    evs = make(sub)
    if best is None:
        return sub, evs, None, [], 0
    found = measure_in(study, evs, {n: float(best[n]) for n in study.parameter_names})
    active = list(found["active"]) if math.isfinite(found["cost"]) else []
    return sub, evs, best, active, found["nfev"]


def own_again(
    ctx: Context,
    i: int,
    cand: Candidate,
    own: tuple[Study, Callable[[Study], Evaluators]],
    evs: Evaluators,
    all_stages: list[list[StageResult]],
) -> bool:
    """Give candidate ``i`` its own study (the one :func:`next_own_study` names).

    Its answer becomes the own study's where that is lower. Returns whether the study
    paused (the caller stops).
    """
    if ctx.progress:
        message = f"structure {cand.label}: a study of its own"
        ctx.progress("stage", {"name": f"structure {i + 1}", "message": message})
    store = Prefixed(ctx.store, f"structure_{i + 1:02d}/own")
    stages = run_own(ctx.study, own[0], own[1], store, ctx.progress, ctx.control)
    cand.nfev += sum(s.nfev for s in stages)
    if stages[-1].status == 2:
        all_stages[i] = stages
        return True
    answer = answer_stage(stages)
    if answer.cost < cand.cost:
        names = ctx.study.parameter_names
        update(cand, measure_in(ctx.study, evs, {n: float(answer.x[n]) for n in names}))
        all_stages[i] = [*all_stages[i], *stages]
        cand.origin += "; a study of its own after the comparison (warm start not optimal)"
    return False
