"""Draw every figure of a study once, at its end, from the iteration records.

Plotting is kept off the study's critical path: nothing is drawn while the arrays run.
At the end :func:`draw_study` writes, from the records, each iteration's main effects
and best-so-far fit into its folder as SVG (:mod:`.svgfig`: microseconds each, however
many iterations), and the study's fit, convergence and parameter trajectories into the
output folder as PNG at 2x (matplotlib). Iteration figures already on disk from an
earlier run of the same study (``--resume``) are read back, not redrawn.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tsid_fmu.evaluate.protocol import Simulated
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.report.figures import MIN_POINTS, convergence_figure, points, trajectory_figure
from tsid_fmu.report.fitfig import FitFigure
from tsid_fmu.report.style import cost_name, png_bytes
from tsid_fmu.report.svgfig import fit_svg, main_effects_svg
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.trail.files import atomic_write

__all__ = ["Figures", "cost_name", "draw_study", "iteration_folders"]

Simulate = Callable[[list[dict[str, float]]], list[list[Simulated]]]
"""Simulates parameter sets on the measured inputs (not counted as the study's)."""


@dataclass
class Figures:
    """PNG images of a study by path relative to its output folder, and the time taken."""

    images: dict[str, bytes] = field(default_factory=dict)
    seconds: float = 0.0
    timings: dict[str, float] = field(default_factory=dict)

    def lap(self, what: str, since: float) -> float:
        """Add the seconds since ``since`` to ``timings[what]``; return the time now."""
        now = time.perf_counter()
        self.timings[what] = self.timings.get(what, 0.0) + now - since
        return now


def iteration_folders(stages: Sequence[StageResult]) -> list[tuple[str, IterationRecord]]:
    """Return ``(folder, record)`` of every iteration, folders relative to the output."""
    out, phase = [], 0
    for st in stages:
        phase += st.kind == StageKind.PHASE
        base = f"phase_{phase:02d}/" if st.kind == StageKind.PHASE else ""
        out += [(f"{base}iteration_{r.index:02d}", r) for r in st.records]
    return out


def _iteration_x(rec: IterationRecord, names: Sequence[str]) -> dict[str, float] | None:
    x = {n: rec.best_x.get(n, math.nan) for n in names}
    return None if any(math.isnan(v) for v in x.values()) else x


class _Writer:
    """Keeps the images and writes each into the output folder (if there is one)."""

    def __init__(self, out: Path | None, figures: Figures) -> None:
        self.out, self.figures = out, figures

    def cached(self, name: str) -> bool:
        if self.out is None or not (self.out / name).is_file():
            return False
        self.figures.images[name] = (self.out / name).read_bytes()
        return True

    def put(self, name: str, data: bytes) -> None:
        self.figures.images[name] = data
        if self.out is not None:
            (self.out / name).parent.mkdir(parents=True, exist_ok=True)
            atomic_write(self.out / name, data)


def _iterations(
    writer: _Writer,
    stages: Sequence[StageResult],
    spec: EvaluationSpec | None,
    simulate: Simulate | None,
    units: Mapping[str, str],
    cost: str,
) -> None:
    t0 = time.perf_counter()
    items = iteration_folders(stages)
    for folder, rec in items:
        name = f"{folder}/main_effects.svg"
        if not writer.cached(name):
            svg = main_effects_svg(rec, rec.describe, units, cost)
            writer.put(name, svg.encode())
    writer.figures.lap("main effects (SVG)", t0)
    if spec is None or simulate is None:
        return
    names = list(spec.parameter_names)
    todo = [
        (folder, rec, x)
        for folder, rec in items
        if (x := _iteration_x(rec, names)) is not None and not writer.cached(f"{folder}/fit.svg")
    ]
    unique: dict[tuple[float, ...], dict[str, float]] = {}
    for _, _, x in todo:
        unique.setdefault(tuple(x.values()), x)
    t0 = time.perf_counter()
    sims = dict(zip(unique, simulate(list(unique.values())), strict=True)) if unique else {}
    t0 = writer.figures.lap("simulations of the iterations' best sets", t0)
    drawn: dict[tuple[tuple[float, ...], str], bytes] = {}
    for folder, rec, x in todo:
        key = (tuple(x.values()), rec.best_source)
        if key not in drawn:
            title = f"{rec.stage}, iteration {rec.index}: best set so far ({rec.best_source})"
            drawn[key] = fit_svg(spec.experiments, sims[key[0]], units, title).encode()
        writer.put(f"{folder}/fit.svg", drawn[key])
    writer.figures.lap("iteration fits (SVG)", t0)


def draw_study(
    result: Any,
    out: Path | None,
    *,
    spec: EvaluationSpec | None = None,
    simulated: Sequence[Simulated] | None = None,
    simulate: Simulate | None = None,
    units: Mapping[str, str] | None = None,
) -> Figures:
    """Draw every figure of a finished (or paused) study.

    Parameters
    ----------
    result : IdentificationResult
        The study's result (stages and their records, ``x``).
    out : Path or None
        Output folder to write the PNG files into (None: keep them in memory only).
    spec : EvaluationSpec, optional
        The identification experiments; with ``simulated`` (the outputs at ``x``) it
        gives ``fit.png``, with ``simulate`` each iteration's ``fit.png``.
    simulated : sequence of Simulated, optional
        The identified model on each experiment of ``spec``.
    simulate : callable, optional
        Simulates a list of parameter sets (for each iteration's best set).
    units : mapping, optional
        Unit of each parameter and FMU variable.

    Returns
    -------
    Figures
        The images by path relative to ``out`` and the seconds spent drawing.
    """
    t0 = time.perf_counter()
    figures = Figures()
    writer = _Writer(out, figures)
    units = dict(units or {})
    cost = cost_name(result.study)
    _iterations(writer, result.stages, spec, simulate, units, cost)
    t = time.perf_counter()
    if spec is not None and simulated is not None:
        fig = FitFigure(spec.experiments, units).draw(
            simulated, "Identified model against the measured data"
        )
        writer.put("fit.png", png_bytes(fig))
        t = figures.lap("fit.png", t)
    drawn = points(result)  # no one-point figures
    if result.iterations and drawn["convergence.png"] >= MIN_POINTS:
        writer.put("convergence.png", png_bytes(convergence_figure(result.stages, cost)))
        t = figures.lap("convergence.png", t)
    if drawn["parameters.png"] >= MIN_POINTS:
        names = result.names
        fig = trajectory_figure(result.iterations, names, units, result.params)
        writer.put("parameters.png", png_bytes(fig))
        figures.lap("parameters.png", t)
    figures.seconds = time.perf_counter() - t0
    return figures
