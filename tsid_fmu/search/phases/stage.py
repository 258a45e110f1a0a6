"""Phases of the MISO paper: plan them from the contribution analyses (Steps i and ii).

1. *Input contribution* (Step i): the identification experiments, each driven by one
   input, are ranked by the size of the output they produce; the main contributor's
   subsystem is identified first.
2. *Parameter contribution* (Step ii): on each experiment in that order, the parameters
   not yet assigned are varied one at a time (three values); those that change this
   experiment's cost by at least ``min_percent`` belong to its subsystem and are grouped
   by contribution. Each group becomes a phase, most influential first.

Each phase is then a Taguchi stage of its group on its experiment, every other
parameter held at its current value (:mod:`tsid_fmu.search.pipeline`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Protocol

import numpy as np

from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.search.phases.contribution import (
    Contribution,
    group_parameters,
    input_contribution,
    oat_values,
    parameter_contribution,
)
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.study.definition import Study
from tsid_fmu.study.schema import Parameter, Phase

__all__ = ["centre_values", "joint_levels", "plan_phases"]


class Evaluators(Protocol):
    """Specs and evaluators of sub-problems (see :mod:`tsid_fmu.search.pipeline`)."""

    def spec(
        self, parameters: list[str], experiments: list[str], fixed: Mapping[str, float]
    ) -> EvaluationSpec: ...

    def get(
        self, parameters: list[str], experiments: list[str], fixed: Mapping[str, float]
    ) -> Evaluator: ...

    def shortened(
        self, parameters: list[str], experiments: list[str], fraction: float
    ) -> Evaluator | None: ...


def centre_values(study: Study) -> dict[str, float]:
    """Centre value of each parameter: its middle one-at-a-time value."""
    out = {}
    for p in study.parameters:
        vals = study.contribution.values.get(p.name) or oat_values(p.levels)
        out[p.name] = float(sorted(vals)[1])
    return out


def _active_inputs(spec: EvaluationSpec) -> dict[str, list[str]]:
    out = {}
    for e in spec.experiments:
        std = np.std(e.inputs, axis=0) if e.inputs is not None else []
        out[e.name] = [n for n, s in zip(e.input_names, std, strict=True) if s > 0]
    return out


def plan_phases(study: Study, evaluators: Evaluators) -> StageResult:
    """Run the contribution analyses and plan the phases.

    Parameters
    ----------
    study : Study
        The study (its ``contribution`` options apply).
    evaluators : Evaluators
        Specs and evaluators of sub-problems.

    Returns
    -------
    StageResult
        A ``contribution`` stage with its ``phases`` and, for the report, its
        ``contribution`` tables.
    """
    opts = study.contribution
    ident = study.identify_names()
    centre = centre_values(study)
    found = Contribution()
    order, nfev = list(ident), 0
    if len(ident) > 1:
        spec = evaluators.spec(study.parameter_names, ident, centre)
        inc = input_contribution(
            {e.name: e.scored(e.measured) for e in spec.experiments}, _active_inputs(spec)
        )
        found.input = dataclasses.asdict(inc)
        order = inc.experiments
    remaining, phases = list(study.parameter_names), []
    for k, exp in enumerate(order):
        if not remaining:
            break
        first = {p.name: p.levels for p in study.parameters}
        values = {n: study.contribution.values.get(n) or oat_values(first[n]) for n in remaining}
        sets = [
            {**{m: centre[m] for m in remaining}, n: float(v)}
            for n, vals in values.items()
            for v in vals
        ]
        fixed = {m: centre[m] for m in study.parameter_names if m not in remaining}
        result = evaluators.get(remaining, [exp], fixed).evaluate(sets)
        nfev += result.nfev
        pc = parameter_contribution(values, {m: centre[m] for m in remaining}, result.costs[:, 0])
        found.percent[exp] = dict(pc.percent)
        found.runs[exp] = pc.runs
        last = k == len(order) - 1
        mine = {n: p for n, p in pc.percent.items() if last or p >= opts.min_percent}
        if not mine:
            continue
        groups = group_parameters(mine, ratio=opts.group_ratio)
        found.groups[exp] = groups
        phases += [Phase(parameters=g, experiments=[exp]) for g in groups]
        remaining = [n for n in remaining if n not in mine]
    for i, ph in enumerate(phases):
        ph.name = f"phase {i + 1}"
    what = "; ".join(
        f"{p.name}: {', '.join(p.parameters)} on {', '.join(p.experiments)}" for p in phases
    )
    return StageResult(
        name="contribution",
        kind=StageKind.CONTRIBUTION,
        x=dict(centre),
        cost=float("nan"),
        nfev=nfev,
        message=f"{len(phases)} phases planned ({what})",
        experiments=ident,
        phases=phases,
        contribution=found,
    )


def joint_levels(study: Study, current: Mapping[str, float]) -> list[Parameter]:
    """First levels of the joint phase: three values within ``refine_span`` of ``current``.

    A value at zero or on a bound spreads from the bound instead (by the span of a tenth
    of the largest first level when the value is 0).
    """
    span = study.contribution.refine_span
    out = []
    for p in study.parameters:
        v = min(max(current[p.name], p.min), p.max)
        lv = sorted({max(v * (1 - span), p.min), v, min(v * (1 + span), p.max)})
        if len(lv) < 3:
            typical = 0.1 * max(abs(x) for x in p.levels)
            width = max(abs(v), typical, 1e-9) * span
            lv = [v, v + width, v + 2 * width] if v <= p.min else [v - 2 * width, v - width, v]
        out.append(Parameter(p.name, lv, p.min, p.max, p.unit))
    return out
