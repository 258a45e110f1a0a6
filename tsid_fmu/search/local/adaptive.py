"""The adaptive pipeline's decisions: which answer stands, is it an optimum, where to restart.

With ``refine = "auto"`` (the default) and the ``sse`` cost a study is not a fixed
sequence of stages:

1. the Taguchi stage scores its start points and runs one array over the first ranges,
   then hands over (:func:`tsid_fmu.search.taguchi.stage._handover`);
2. the least-squares refinement polishes the best set; where its trust region crawls
   along a valley of two parameters that act through one combination (a step gaining
   less than :data:`~tsid_fmu.search.verdict.GATE_RTOL` of the cost, parallel columns:
   :mod:`~tsid_fmu.search.local.problem`), it stops, and goes on in that combination
   as one stage (step 6; the SISO example: 149 runs in all instead of 229);
3. if the refined answer is not shown to be stationary, or is a poor fit
   (:data:`~tsid_fmu.search.verdict.POOR_FIT` times the noise floor), or the
   refinement's trust region collapsed (SciPy's ``xtol``: its local model did not hold,
   as on dry friction's rough cost), it is first refined in the combinations the data
   fix where step 6's conditions hold (the SISO example's first refinement stopped in
   the valley along ``F_vm + B_s``: 229 runs in all instead of 596); where the answer is
   still unsettled, the refinement may sit in a local minimum: the Taguchi stage goes
   on from where it handed over, to its own end (Case 3 or a limit) or until its best
   set lies below the refinement's answer and an iteration stops lowering it (it hands
   back), and its best set is refined again;
4. while that still holds, the refinement follows a minimum over growing horizons: on
   the first :data:`HORIZONS` fractions of each experiment's samples in turn, from the
   arrays' best set, then on all of them (a model that swings or rings has few valleys
   in its cost over a short record, where the simulation cannot drift whole periods
   from the data; each horizon is a waypoint, ended at the first step that gains less
   than the stationarity gate's share of its cost); where that route ends at the same
   stationary answer, a poor fit is the model's or the noise's and no restart follows;
5. while that still holds, the refinement restarts, up to ``max_reruns`` times: from the
   start points first (where a local method alone would start), then from the next-best
   run of the arrays that lies away from every start and answer so far (the MISO
   paper's re-run from the next-best run);
6. where the answer's test held by a trial alone, or its simulated step was lower, or
   the refinement stopped crawling (step 2), and two parameters act through one
   combination, the refinement in that combination
   (:mod:`tsid_fmu.search.local.combined`), kept where lower;
7. the answer is the lowest-cost set of every stage, and the study has converged only
   where a stationarity test holds there (:mod:`tsid_fmu.search.verdict`). A poor fit
   that no restart improved is a warning, not a verdict: the optima of a model that
   does not quite explain the data, or of strongly coloured noise, are far above the
   floor too.

Every decision names its reason in the stage's message, and so in the log and report.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from tsid_fmu.numerics.tuning import AGREE, RESTART_SEPARATION
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageKind, StageResult

__all__ = [
    "AGREE",
    "HORIZONS",
    "RESTART_SEPARATION",
    "answer_stage",
    "restart_start",
    "start_sets",
    "verdict",
]


HORIZONS = (1 / 8, 1 / 4, 1 / 2)
"""Fractions of each experiment's samples the refinement follows a minimum over, in turn,
before it refines on all of them (a stage of kind ``"horizon"`` each)."""


_ANSWERS = (StageKind.TAGUCHI, StageKind.REFINEMENT, StageKind.CHECK)


def answer_stage(stages: Sequence[StageResult]) -> StageResult:
    """Return the stage whose answer the study reports: the lowest cost on the full cost.

    The stages that score the whole study (a single Taguchi stage, refinements, checks)
    and the last stage compete; phases that score a part of it do not.
    """
    last = stages[-1]
    pool = [s for s in stages if s.kind in _ANSWERS] + [last]
    finite = [s for s in pool if math.isfinite(s.cost)]
    if not finite:
        return last
    best = min(s.cost for s in finite)
    # the latest stage with the best cost (a check confirms the refinement's answer)
    return [s for s in finite if s.cost == best][-1]


def verdict(stages: Sequence[StageResult]) -> tuple[int, str] | None:
    """Return (status, reason) from the answer's stationarity test, if one was made."""
    test = answer_stage(stages).stationarity
    if test is None:
        return None
    if test.holds:
        return 0, f"stationary at the answer ({test.test}): {test.detail}"
    return 1, f"not shown to be an optimum ({test.test}): {test.detail}"


def _points(stages: Sequence[StageResult]) -> list[tuple[float, dict[str, float]]]:
    """Every parameter set the Taguchi stages scored on the full cost, with its cost."""
    out = []
    for st in stages:
        if st.kind != StageKind.TAGUCHI:
            continue
        for rec in st.records:
            costs = rec.measured_costs
            for row, cost in zip(rec.sets, costs, strict=True):
                out.append((float(cost), dict(zip(rec.parameters, map(float, row), strict=True))))
            for start in rec.starts:
                if start.get("cost") is not None:
                    out.append((float(start["cost"]), dict(start["x"])))
    return [(c, x) for c, x in out if math.isfinite(c)]


def start_sets(stages: Sequence[StageResult]) -> list[tuple[float, dict[str, float], str]]:
    """Return the start points the first Taguchi stage scored: (cost, set, source)."""
    first = next((s for s in stages if s.kind == StageKind.TAGUCHI and s.records), None)
    starts = first.records[0].starts if first is not None else []
    out = [(float(s["cost"]), dict(s["x"]), str(s["source"])) for s in starts if s.get("cost")]
    return sorted((p for p in out if math.isfinite(p[0])), key=lambda p: p[0])


def restart_start(
    stages: Sequence[StageResult],
    space: Space,
    explored: Sequence[dict[str, float]],
    starts_first: bool = False,
) -> tuple[dict[str, float], float, str] | None:
    """Return the lowest-cost scored set away from every explored set, its cost and origin.

    With ``starts_first``, the start points (the FMU's start values, the centre of the
    first levels: where a local method alone would start) come before the arrays' runs.
    """
    seen = [space.to_s(x) for x in explored]
    starts = [(c, x, s) for c, x, s in start_sets(stages)] if starts_first else []
    runs = [(c, x, "a run of the arrays") for c, x in sorted(_points(stages), key=lambda p: p[0])]
    for cost, x, origin in starts + runs:
        if not all(n in x for n in space.names):
            continue
        s = space.to_s(x)
        if all(np.max(np.abs(s - t)) >= RESTART_SEPARATION for t in seen):
            return x, cost, origin
    return None
