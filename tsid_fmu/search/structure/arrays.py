"""The structure stage: discrete factors in the same orthogonal arrays as the parameters.

A study with :class:`~tsid_fmu.study.choice.Choice` factors (FMU Integer, Boolean or
Enumeration switches) first runs mixed-level arrays (L18, L36, L50, ...): each open
discrete factor takes its choices as the levels of its column, the Real parameters
their current levels. Every iteration gives the usual response table, S/N and ANOVA,
the discrete factors included, with their levels' means.

The rule that closes a discrete factor (:func:`settled`): its effect is **significant**
(the ANOVA F test of the S/N, with Taguchi's pooling, gives ``p <`` :data:`ALPHA`; a
pooled factor is not significant) **and its best level is the same in two consecutive
iterations** (significant in both). It is then fixed to that level, and the Real
parameters are re-leveled within that structure (centred on the best set that has
it). Otherwise the next arrays keep it open. Discrete factors are never re-leveled
numerically: their levels stay their choices until they are fixed.

The stage ends when every discrete factor is fixed, when the Real parameters' levels
converge (Case 3) or stall, or at the study's limits. What follows (each candidate
structure refined to its own optimum and compared) is :mod:`tsid_fmu.search.structure.compare`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.doe.arrays import select_array
from tsid_fmu.doe.leveling import FactorDecision, LevelingDecision
from tsid_fmu.errors import ArrayError, StudyError
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.numerics.tuning import ARRAYS_ALPHA as ALPHA
from tsid_fmu.numerics.tuning import MAX_ITERATIONS
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.taguchi.iteration import Best, ProgressCallback, predict
from tsid_fmu.search.taguchi.nextlevels import next_frame
from tsid_fmu.study.schema import Method

__all__ = [
    "ALPHA",
    "MAX_ITERATIONS",
    "DiscreteFactor",
    "StructureRun",
    "discrete_table",
    "settled",
    "structure_stage",
]


@dataclass
class DiscreteFactor:
    """A discrete factor in the structure stage: its levels and what the arrays said.

    Attributes
    ----------
    name : str
        The FMU variable.
    values : list of float
        The number of each choice (the level values).
    labels : list of str
        The choices as a person reads them.
    fixed : int or None
        0-based level it was fixed to, or None while open.
    history : list of (bool, int)
        Per iteration it was open in: significant, best level (0-based).
    runner_up : int or None
        Second-best level when it was fixed (a candidate structure to compare).
    """

    name: str
    values: list[float]
    labels: list[str]
    fixed: int | None = None
    history: list[tuple[bool, int]] = field(default_factory=list)
    runner_up: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy."""
        return {
            "name": self.name,
            "values": list(self.values),
            "labels": list(self.labels),
            "fixed": self.fixed,
            "history": [[bool(s), int(b)] for s, b in self.history],
            "runner_up": self.runner_up,
        }


def settled(history: Sequence[tuple[bool, int]]) -> bool:
    """Whether a discrete factor is fixed: significant with the same best level twice running."""
    if len(history) < 2:
        return False
    (sig_a, best_a), (sig_b, best_b) = history[-2], history[-1]
    return sig_a and sig_b and best_a == best_b


def discrete_table(record: IterationRecord, name: str) -> dict[str, Any]:
    """Response and ANOVA of one discrete factor in an iteration: its levels' means.

    Returns ``{"sn": [...], "cost": [...], "best": level, "second": level, "f": F,
    "p": p, "pooled": bool, "significant": bool}`` (levels 0-based; ``sn`` the mean
    S/N per level, ``cost`` the mean cost per level).
    """
    sn = [float(v) for v in record.response.means[name]]
    cost = [float(v) for v in record.response_means.means[name]]
    table = record.anova
    p = float(table.p[name])
    order = np.argsort(-np.where(np.isfinite(sn), sn, -np.inf), kind="stable")
    pooled = name in table.pooled
    return {
        "sn": sn,
        "cost": cost,
        "best": int(order[0]),
        "second": int(order[1]),
        "f": float(table.f[name]),
        "p": p,
        "pooled": pooled,
        "significant": bool(not pooled and math.isfinite(p) and p < ALPHA),
    }


@dataclass
class StructureRun:
    """How to run the structure stage."""

    levels: dict[str, list[float]]
    bounds: dict[str, tuple[float, float]]
    factors: list[DiscreteFactor]
    method: Method
    max_iterations: int | None = None
    nfev_before: int = 0


@dataclass
class StructureOutcome:
    """What the structure stage leaves for the comparison of structures."""

    stage: StageResult
    factors: list[DiscreteFactor]
    levels: dict[str, list[float]]
    points: list[tuple[float, dict[str, float]]]


def _sets(frame: Frame, space: Space, rows: np.ndarray, fixed: Mapping[str, float]) -> list:
    return [{**s, **fixed} for s in frame.parameter_sets(space, rows)]


def _fixed(factors: Sequence[DiscreteFactor]) -> dict[str, float]:
    return {f.name: f.values[f.fixed] for f in factors if f.fixed is not None}


def _iteration_frame(
    real: Frame, run: StructureRun, open_: list[DiscreteFactor]
) -> tuple[Space, Frame]:
    levels = {**real.level_values(_real_space(run)), **{f.name: f.values for f in open_}}
    bounds = {**run.bounds, **{f.name: (min(f.values), max(f.values)) for f in open_}}
    space = Space(levels, bounds, run.method.leveling)
    return space, Frame.from_levels(space, levels)


def _real_space(run: StructureRun) -> Space:
    return Space(run.levels, run.bounds, run.method.leveling)


def _consistent(x: Mapping[str, float], fixed: Mapping[str, float]) -> bool:
    return all(x.get(k) == v for k, v in fixed.items())


def _decisions(
    factors: list[DiscreteFactor], tables: dict[str, dict[str, Any]]
) -> list[FactorDecision]:
    out = []
    for f in factors:
        t = tables[f.name]
        case = "fixed" if f.fixed is not None else "open"
        said = f"ANOVA F {t['f']:.4g}, p {t['p']:.3g}" if not t["pooled"] else "pooled (weak)"
        reason = f"best level {t['best'] + 1} ({f.labels[t['best']]}), {said}; " + (
            f"significant with the same best level twice: fixed to {f.labels[f.fixed]}"
            if f.fixed is not None
            else "kept open (not yet significant with the same best level twice)"
        )
        delta = float(np.nanmax(t["sn"]) - np.nanmin(t["sn"]))
        out.append(
            FactorDecision(f.name, case, delta, t["best"], f.values[t["best"]], f.values, reason)
        )
    return out


def _analyse(record: IterationRecord, open_: list[DiscreteFactor]) -> dict[str, dict[str, Any]]:
    """Judge each open discrete factor; fix those the rule settles."""
    tables = {}
    for f in open_:
        t = discrete_table(record, f.name)
        tables[f.name] = t
        f.history.append((t["significant"], t["best"]))
        if settled(f.history):
            f.fixed, f.runner_up = t["best"], t["second"]
    return tables


def _run_arrays(
    index: int,
    space: Space,
    frame: Frame,
    fixed: Mapping[str, float],
    evaluator: Evaluator,
    method: Method,
    progress: ProgressCallback | None,
) -> tuple[Any, list[dict[str, float]], np.ndarray, list[int], str]:
    n_levels = [f.n_levels for f in frame.factors]
    try:
        array, columns = select_array(n_levels, name=method.array)
    except ArrayError:
        array, columns = select_array(n_levels)
    rows = np.asarray(array.table[:, columns], dtype=int)
    sets = _sets(frame, space, rows, fixed)

    def tick(done: int, total: int) -> None:
        if progress is not None:
            info = {"stage": "structure", "iteration": index, "done": done, "total": total}
            progress("row", info)

    ev = evaluator.evaluate(sets, progress=tick)
    if all(e is not None for e in ev.errors):
        raise StudyError(
            f"structure, iteration {index}: every run of {array.name} failed; first reason: "
            f"{ev.errors[0]}"
        )
    return ev, sets, rows, list(columns), array.name


def _one(
    index: int,
    run: StructureRun,
    real: Frame,
    evaluator: Evaluator,
    best: Best | None,
    nfev: int,
    progress: ProgressCallback | None,
) -> tuple[IterationRecord, Frame, Best, list[tuple[float, dict[str, float]]]]:
    """Run one mixed iteration; return its record, the next Real frame and the best set."""
    open_ = [f for f in run.factors if f.fixed is None]
    fixed = _fixed(run.factors)
    space, frame = _iteration_frame(real, run, open_)
    start = evaluator.nfev
    ev, sets, rows, columns, array = _run_arrays(
        index, space, frame, fixed, evaluator, run.method, progress
    )
    names = [*space.names, *fixed]
    record = IterationRecord(
        index=index, stage="structure", array=array, columns=columns, frame=frame,
        parameters=names, level_index=rows,
        sets=np.array([[s[n] for n in names] for s in sets]), costs=ev.costs,
        errors=list(ev.errors), decision=LevelingDecision(), prediction={}, best_x={},
        best_cost=math.inf, best_source="", centre_source="", nfev=0, nfev_total=0,
        next_frame=frame,
    )  # fmt: skip
    sn_means = record.sn_means()
    tables = _analyse(record, open_)
    chosen = {f.name: f.values[tables[f.name]["best"]] for f in open_}
    rspace = _real_space(run)
    x_pred, z_pred = predict(real, rspace, sn_means, run.method.leveling.refine)
    x_pred = {**x_pred, **fixed, **chosen}
    conf = evaluator.evaluate([x_pred])
    points = [(float(c), dict(s)) for s, c in zip(sets, ev.costs[:, 0], strict=True)]
    points.append((float(conf.costs[0, 0]), dict(x_pred)))
    labelled = [Best(s, c, f"structure iteration {index}, run {i + 1}")
                for i, (c, s) in enumerate(points[:-1])]  # fmt: skip
    labelled.append(Best(x_pred, points[-1][0], f"structure iteration {index}, predicted"))
    if best is not None:
        labelled.append(best)
    finite = [b for b in labelled if math.isfinite(b.cost)]
    new_best = min(finite, key=lambda b: b.cost) if finite else labelled[0]
    now_fixed = _fixed(run.factors)
    within = [b for b in finite if _consistent(b.x, now_fixed)] or finite or labelled
    centre = min(within, key=lambda b: b.cost)
    real_means = {n: sn_means[n] for n in rspace.names}
    contribution = {n: record.anova.contribution[n] for n in rspace.names}
    decision, following = next_frame(
        real, rspace, real_means, ({n: centre.x[n] for n in rspace.names}, centre.source),
        run.method.leveling, contribution, None,
    )  # fmt: skip
    record.decision = LevelingDecision(
        parameters=[*decision.parameters, *_decisions(open_, tables)],
        converged=decision.converged,
        message=decision.message,
    )
    record.prediction = {"x": x_pred, "cost": points[-1][0], "error": conf.errors[0],
                         "offsets": [float(z) for z in z_pred]}  # fmt: skip
    record.best_x, record.best_cost, record.best_source = new_best.x, new_best.cost, new_best.source
    record.centre_source = centre.source
    record.nfev = evaluator.nfev - start
    record.nfev_total = nfev + record.nfev
    record.discrete = {f.name: {**tables[f.name], "labels": f.labels} for f in open_}
    record.next_frame = following
    return record, following, new_best, points


def _stop(records: list[IterationRecord], run: StructureRun, nfev: int) -> str | None:
    if all(f.fixed is not None for f in run.factors):
        return "every discrete factor is fixed"
    if records and records[-1].decision.converged:
        return "the Real parameters' levels converged (Case 3) with discrete factors still open"
    stall = run.method.leveling.stall
    if stall and len(records) > stall:
        recent = records[-stall:]
        real = set(run.levels)
        flat = all(
            d.delta_db < run.method.leveling.significance_db
            for r in recent
            for d in r.decision.parameters
            if d.name in real
        )
        before = records[-stall - 1].best_cost
        if flat and before - recent[-1].best_cost <= run.method.leveling.stall_rtol * abs(before):
            return f"every Real S/N flat for {stall} iterations without a lower cost"
    limit = min(run.max_iterations or run.method.max_iterations, MAX_ITERATIONS)
    if len(records) >= limit:
        return f"iteration limit ({limit}) reached with discrete factors still open"
    budget = run.method.max_simulations
    if budget is not None and nfev - run.nfev_before >= budget:
        return f"simulation limit ({budget}) reached with discrete factors still open"
    return None


def structure_stage(
    run: StructureRun,
    evaluator: Evaluator,
    recorder: Any = None,
    progress: ProgressCallback | None = None,
) -> StructureOutcome:
    """Run the mixed arrays until the discrete factors are fixed or the stage ends.

    ``evaluator`` scores sets of every Real parameter and every discrete factor;
    ``recorder.iteration(record)`` keeps each finished iteration (the audit trail).
    """
    real = Frame.from_levels(_real_space(run), run.levels)
    records: list[IterationRecord] = []
    best: Best | None = None
    nfev, points = run.nfev_before, []
    while True:
        index = len(records) + 1
        if progress:
            progress("iteration", {"stage": "structure", "iteration": index, "frame": real})
        rec, real, best, seen = _one(index, run, real, evaluator, best, nfev, progress)
        records.append(rec)
        points += seen
        nfev = rec.nfev_total
        why = _stop(records, run, nfev)
        rec.structure = [f.to_dict() for f in run.factors]
        if recorder is not None:
            recorder.iteration(rec)
        if progress:
            progress("iteration done", {"record": rec})
        if why is not None:
            break
    levels = real.level_values(_real_space(run))
    stage = StageResult(
        name="structure",
        kind=StageKind.STRUCTURE,
        x=dict(best.x) if best else {},
        cost=best.cost if best else math.inf,
        nfev=nfev - run.nfev_before,
        message=why,
        status=0,
        records=records,
        extra={"factors": [f.to_dict() for f in run.factors], "levels": levels},
    )
    return StructureOutcome(stage, run.factors, levels, points)
