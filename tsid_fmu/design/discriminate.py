"""The input that best separates structures the study could not tell apart.

Where a structure study ends "indistinguishable" (the chosen structure and others within
the noise, :mod:`tsid_fmu.search.structure.selection`), each of those structures is simulated at
its own optimum with every candidate input, and the candidate whose outputs differ most
is proposed: the criterion is the expected chi-square between two structures'
predictions, ``sum ((y_a - y_b) / sigma)**2`` over the samples and outputs (what the
cost of the wrong structure would rise by on noise-free data of the right one), taken
for the pair it separates least, so that every pair is separated. The same figure on
the study's own inputs says how little its data separate them.
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

import numpy as np

from tsid_fmu.design.plan import Plan, candidate_spec
from tsid_fmu.evaluate.factory import make_evaluator
from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["discriminate", "tied"]


def tied(result: Any) -> list[dict[str, Any]]:
    """Return the rows of the chosen structure and those indistinguishable from it."""
    info = getattr(result, "structure", None) or {}
    names = [info.get("chosen"), *info.get("indistinguishable", [])]
    rows = [r for r in getattr(result, "structures", None) or [] if r.get("structure") in names]
    return rows if len(rows) > 1 and all("x" in r and "values" in r for r in rows) else []


def _outputs(spec: EvaluationSpec, plan: Plan, row: dict, workers: Any, timeout: Any) -> list:
    """Simulate every experiment of ``spec`` with one structure at its own optimum."""
    fixed = {k: float(v) for k, v in row["values"].items()}
    own = dataclasses.replace(spec, start_values={**spec.start_values, **fixed})
    point = {**plan.x, **{k: float(v) for k, v in row["x"].items() if k in plan.x}}
    with make_evaluator(own, workers=workers, timeout=timeout) as ev:
        (run,) = ev.simulate([point])
        return [None if sim.outputs is None else np.asarray(sim.outputs) for sim in run], ev.nfev


def _chi2(a: list, b: list, spec: EvaluationSpec) -> list[float]:
    return [
        float(np.sum(((ya - yb) / e.scale[None, :]) ** 2))
        if ya is not None and yb is not None
        else float("nan")
        for ya, yb, e in zip(a, b, spec.experiments, strict=True)
    ]


def discriminate(plan: Plan, result: Any, workers: Any, timeout: Any) -> dict[str, Any] | None:
    """Return the input that best separates the tied structures, or ``None`` if none tie.

    The dict has ``structures`` (their labels), ``best`` (the index of the candidate
    signal), ``chi2`` (per pair, with it), ``now`` (per pair, on the study's own
    inputs), ``scores`` (per candidate, the least-separated pair's chi-square) and
    ``nfev``.
    """
    rows = tied(result)
    if not rows:
        return None
    cspec = candidate_spec(plan, [s.values for s in plan.signals])
    sims, own, nfev = [], [], 0
    for row in rows:
        out, used = _outputs(cspec, plan, row, workers, timeout)
        now, more = _outputs(plan.spec, plan, row, workers, timeout)
        sims.append(out)
        own.append(now)
        nfev += used + more
    pairs = list(itertools.combinations(range(len(rows)), 2))
    per_pair = {(i, j): _chi2(sims[i], sims[j], cspec) for i, j in pairs}
    scores = [min(per_pair[p][k] for p in pairs) for k in range(len(plan.signals))]
    best = int(np.nanargmax(scores))
    label = [r["structure"] for r in rows]
    now = {f"{label[i]} / {label[j]}": float(np.nansum(_chi2(own[i], own[j], plan.spec)))
           for i, j in pairs}  # fmt: skip
    return {
        "structures": label,
        "best": best,
        "chi2": {f"{label[i]} / {label[j]}": per_pair[(i, j)][best] for i, j in pairs},
        "now": now,
        "scores": scores,
        "nfev": nfev,
    }
