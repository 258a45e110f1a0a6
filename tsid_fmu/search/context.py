"""What every stage of a study shares: the study, its evaluators, its trail, its progress.

:class:`Context` is handed from stage to stage (:mod:`tsid_fmu.search.pipeline`,
:mod:`tsid_fmu.search.local.flow`); :func:`refinement` runs the least-squares refinement as a
stage of the trail, read back when it has already run from the same start.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.search.local.refine import refine_stage
from tsid_fmu.search.phases.stage import Evaluators
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.taguchi.frame import Frame
from tsid_fmu.search.taguchi.iteration import ProgressCallback
from tsid_fmu.search.verdict import noise_floor
from tsid_fmu.study.definition import Study

__all__ = ["Context", "Control", "StageStore", "note", "polish", "refinement"]


class StageStore(Protocol):
    """Where stages and iterations are kept (the audit trail, or nothing)."""

    def iterations(self, key: str) -> list[IterationRecord]:
        """Return a stage's complete iterations."""

    def override(self, key: str, record: IterationRecord, space: Space) -> Frame | None:
        """Return levels a person edited after ``record``, if any."""

    def stage(self, key: str) -> StageResult | None:
        """Return a finished stage."""

    def write_iteration(self, key: str, record: IterationRecord, space: Space) -> None:
        """Keep a finished iteration."""

    def write_stage(self, key: str, result: StageResult) -> None:
        """Keep a finished stage."""


@dataclass
class Control:
    """How this call runs the study: limits, pauses, a person's choice of run."""

    pause_after: int | None = None
    max_iterations: int | None = None
    continue_from_run: int | None = None

    def __post_init__(self) -> None:
        for name in ("pause_after", "max_iterations", "continue_from_run"):
            value = getattr(self, name)
            if value is None:
                continue
            if isinstance(value, np.integer):
                value = int(value)
            if isinstance(value, bool) or not isinstance(value, int):
                raise TypeError(f"{name} must be a whole number (from 1), got {value!r}")
            if value < 1:
                raise StudyError(f"{name} must be at least 1, got {value}")
            setattr(self, name, value)


@dataclass
class Context:
    """The study, its evaluators and trail, the progress callback, this call's control.

    ``ran`` counts the Taguchi iterations this call has run so far, over every stage:
    ``--pause-after`` counts them (a stage the arrays go back to counts on).
    """

    study: Study
    evaluators: Evaluators
    store: StageStore
    progress: ProgressCallback | None
    control: Control
    ran: int = 0


def polish(
    name: str,
    study: Study,
    start: Mapping[str, float],
    evaluator: Evaluator,
    progress: ProgressCallback | None,
    waypoint: bool = False,
) -> StageResult:
    """Run the refinement from ``start`` (its cost and residuals come from the memo).

    ``waypoint``: a horizon's, which needs only the basin
    (:attr:`~tsid_fmu.search.outcome.LocalStop.WAYPOINT`).
    """
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    floor = noise_floor(evaluator, study.method.weighting == "noise")
    scored = evaluator.evaluate([dict(start)])
    return refine_stage(
        name,
        space,
        start,
        float(scored.costs[0, 0]),
        evaluator,
        study.method,
        progress=progress,
        start_residuals=scored.residuals[0] if scored.residuals else None,
        floor=floor,
        waypoint=waypoint,
    )


def refinement(
    ctx: Context,
    start: Mapping[str, float],
    exps: list[str],
    key: str = "refinement",
    name: str = "refinement",
) -> StageResult:
    """Refine from ``start`` (a finished refinement from the same start is read back)."""
    study = ctx.study
    start = {n: float(start[n]) for n in study.parameter_names}
    done = ctx.store.stage(key)
    if done is not None and done.start == start:
        return done
    evaluator = ctx.evaluators.get(study.parameter_names, exps, {})
    result = polish(name, study, start, evaluator, ctx.progress)
    result.experiments = list(exps)
    result.start = start
    ctx.store.write_stage(key, result)
    return result


def note(ctx: Context, message: str) -> None:
    """Tell the progress callback why the search takes its next step (a ``rerun`` event)."""
    if ctx.progress:
        ctx.progress("rerun", {"message": message})
