"""Plots of a study written to PNG files (atomically): main effects, fit, convergence.

Thin wrappers over the figures of :mod:`.figures` and :mod:`.fitfig`; a whole study is
drawn at once by :func:`tsid_fmu.report.render.draw_study`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from tsid_fmu.evaluate.protocol import Simulated
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.report.figures import MainEffects, convergence_figure
from tsid_fmu.report.fitfig import FitFigure
from tsid_fmu.report.style import png_bytes
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageResult
from tsid_fmu.trail.files import atomic_write

__all__ = ["convergence_plot", "fit_plot", "main_effects_plot"]


def main_effects_plot(
    rec: IterationRecord,
    path: Path,
    describe: Mapping[str, str] | None = None,
    units: Mapping[str, str] | None = None,
    cost_name: str = "cost",
) -> None:
    """Write the S/N and mean-cost main effects of one iteration (the papers' Figs. 7-9).

    Parameters
    ----------
    rec : IterationRecord
        The iteration: its arrays, S/N ratios and response tables.
    path : Path
        PNG file to write.
    describe : dict, optional
        What each rotated factor moves, shown under its name.
    units : dict, optional
        Unit of each parameter.
    cost_name : str
        What the cost is, for the axis of the mean-cost row.
    """
    fig = MainEffects(cost_name).draw(rec, describe, units)
    atomic_write(Path(path), png_bytes(fig))


def fit_plot(
    spec: EvaluationSpec,
    simulated: Sequence[Simulated],
    path: Path,
    title: str = "",
    units: Mapping[str, str] | None = None,
) -> None:
    """Write measured and simulated outputs, and their residual, for each experiment."""
    fig = FitFigure(spec.experiments, units).draw(simulated, title)
    atomic_write(Path(path), png_bytes(fig))


def convergence_plot(stages: Sequence[StageResult], path: Path, cost_name: str = "cost") -> None:
    """Write the best cost after each iteration, one panel per set of experiments."""
    atomic_write(Path(path), png_bytes(convergence_figure(stages, cost_name)))
