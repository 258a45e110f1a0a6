"""One Taguchi iteration: array runs, S/N analysis, confirmation, re-leveling (Steps III-IV).

1. The orthogonal array of the frame's factors gives the runs; each run's parameter set
   is simulated against the measured inputs (and the noise replicates, if any) and
   scored by the study's cost.
2. The smaller-the-better S/N of each run over its replicates gives the response table
   and the ANOVA.
3. Each factor's best S/N level, refined by a parabola through its neighbours, gives the
   main-effects prediction of the optimum; one confirmation run checks it.
4. The lowest cost seen so far (over the runs, the confirmation and earlier iterations)
   is the stage's answer: never worse than any run evaluated.
5. The next levels are centred on the prediction or on the best run (``selection``) and
   re-levelled by the papers' cases (:mod:`tsid_fmu.search.taguchi.nextlevels`); with
   ``rotate``, the next factors are the principal axes of the surface the runs show.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from tsid_fmu.doe.arrays import select_array
from tsid_fmu.doe.rules import main_effect_optimum
from tsid_fmu.errors import ArrayError, StudyError
from tsid_fmu.evaluate.protocol import Evaluation, Evaluator
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.taguchi.nextlevels import next_frame
from tsid_fmu.search.taguchi.surface import principal_axes
from tsid_fmu.study.schema import Method

__all__ = ["Best", "ProgressCallback", "predict", "run_iteration"]

ProgressCallback = Callable[[str, dict[str, Any]], None]


@dataclass
class Best:
    """A parameter set, its cost on the measured inputs and where it was found."""

    x: dict[str, float]
    cost: float
    source: str


def predict(
    frame: Frame, space: Space, sn_means: dict[str, list[float]], refine: bool
) -> tuple[dict[str, float], np.ndarray]:
    """Return the main-effects optimum (parameter set) and its offsets along each factor.

    A factor whose best level is exact keeps that level's exact value (no rounding
    through the search coordinates).
    """
    offsets = np.zeros(len(frame.factors))
    exact: dict[str, float] = {}
    for k, f in enumerate(frame.factors):
        best, z, _ = main_effect_optimum(
            np.asarray(f.offsets), np.asarray(sn_means[f.name]), refine
        )
        offsets[k] = z
        if f.values is not None and z == f.offsets[best]:
            exact[f.name] = f.values[best]
    x = frame.at_offsets(space, offsets)
    x.update(exact)
    return x, offsets


def _choose_centre(
    method: Method, best_run: Best, predicted: Best, best: Best
) -> tuple[dict[str, float], str] | None:
    """Pick the parameter set the next levels are centred on (the selection rule)."""
    if method.selection == "main_effects":
        return dict(predicted.x), "the predicted optimum"
    if method.selection == "best_run":
        pick = best_run if best_run.cost <= best.cost else best
        return dict(pick.x), pick.source
    return dict(best.x), best.source


def _axes(
    space: Space,
    centre: dict[str, float],
    sets: list[dict[str, float]],
    residuals: list[np.ndarray | None],
) -> tuple[np.ndarray, np.ndarray] | None:
    """Principal axes of the surface the runs show, in coordinates anchored at ``centre``."""
    coords = space.anchored(centre)
    points = [(coords.to_s(x), r) for x, r in zip(sets, residuals, strict=True)]
    return principal_axes(points, coords.to_s(centre))


def _record(
    index: int,
    stage: str,
    array: str,
    columns: list[int],
    frame: Frame,
    space: Space,
    level_index: np.ndarray,
    sets: list[dict[str, float]],
    ev: Evaluation,
) -> IterationRecord:
    """Make the record of the runs (decision, prediction and best come later)."""
    return IterationRecord(
        index=index,
        stage=stage,
        array=array,
        columns=columns,
        frame=frame,
        parameters=list(space.names),
        level_index=level_index,
        sets=np.array([[s[n] for n in space.names] for s in sets]),
        costs=ev.costs,
        errors=list(ev.errors),
        decision=None,  # type: ignore[arg-type]
        prediction={},
        best_x={},
        best_cost=math.inf,
        best_source="",
        centre_source="",
        nfev=0,
        nfev_total=0,
        next_frame=frame,
    )


def run_iteration(
    index: int,
    stage: str,
    frame: Frame,
    space: Space,
    evaluator: Evaluator,
    method: Method,
    best: Best | None,
    nfev_before: int,
    progress: ProgressCallback | None = None,
) -> IterationRecord:
    """Run one iteration and return its record (see the module docstring).

    Raises
    ------
    StudyError
        Every run of the array failed (the message gives the first reason).
    """
    n_levels = [f.n_levels for f in frame.factors]
    try:
        array, columns = select_array(n_levels, name=method.array)
    except ArrayError:  # the study's array is for its first levels; later ones may differ
        array, columns = select_array(n_levels)
    level_index = np.asarray(array.table[:, columns], dtype=int)
    sets = frame.parameter_sets(space, level_index)
    start = evaluator.nfev

    def rows(done: int, total: int) -> None:
        if progress is not None:  # the run's cost, where the evaluator keeps it: the bar's best
            cost = getattr(evaluator, "last_cost", None)
            info = {"stage": stage, "iteration": index, "done": done, "total": total}
            progress("row", {**info, "cost": cost} if cost is not None else info)

    ev = evaluator.evaluate(sets, progress=rows)
    if all(e is not None for e in ev.errors):
        raise StudyError(
            f"{stage}, iteration {index}: every run of {array.name} failed; first reason: "
            f"{ev.errors[0]}"
        )
    record = _record(index, stage, array.name, list(columns), frame, space, level_index, sets, ev)
    sn_means = record.sn_means()
    x_pred, z_pred = predict(frame, space, sn_means, method.leveling.refine)
    conf = evaluator.evaluate([x_pred])
    predicted = Best(x_pred, float(conf.costs[0, 0]), f"iteration {index}, predicted optimum")
    measured = ev.costs[:, 0]
    i_best = int(np.argmin(np.where(np.isfinite(measured), measured, np.inf)))
    best_run = Best(
        dict(sets[i_best]), float(measured[i_best]), f"iteration {index}, run {i_best + 1}"
    )
    candidates = [c for c in (best, best_run, predicted) if c is not None]
    new_best = min(candidates, key=lambda c: c.cost)
    centre = _choose_centre(method, best_run, predicted, new_best)
    axes = None
    if method.rotate and ev.residuals is not None and conf.residuals is not None:
        axes = _axes(space, centre[0], [*sets, x_pred], [*ev.residuals, conf.residuals[0]])
    contribution = record.anova.contribution
    decision, following = next_frame(
        frame, space, sn_means, centre, method.leveling, contribution, axes
    )
    record.decision = decision
    record.prediction = {
        "x": x_pred,
        "cost": predicted.cost,
        "error": conf.errors[0],
        "offsets": [float(z) for z in z_pred],
    }
    record.best_x, record.best_cost, record.best_source = new_best.x, new_best.cost, new_best.source
    record.centre_source = centre[1]
    record.nfev = evaluator.nfev - start
    record.nfev_total = nfev_before + record.nfev
    record.next_frame = following
    return record
