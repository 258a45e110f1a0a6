"""Per-iteration figures as SVG: the main effects, and the fit of the best set so far.

Main effects follow Minitab's layout: one panel per factor, the level means joined by a
line, the grand mean dashed, one y scale per row so that the effects compare at a
glance; the top row is the S/N ratio, the bottom row the mean cost. The chosen level
(the largest S/N) is marked in both rows.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.evaluate.protocol import Simulated
from tsid_fmu.evaluate.spec import PreparedExperiment
from tsid_fmu.report.fitfig import envelope
from tsid_fmu.report.style import COLORS, fmt, fmt_levels, short_combination, with_unit
from tsid_fmu.report.svg import Canvas, Panel, nice_ticks
from tsid_fmu.search.record import IterationRecord

__all__ = ["fit_svg", "main_effects_svg"]

_PW, _PH, _GAP, _LEFT = 170.0, 120.0, 22.0, 84.0


def _limits(values: Sequence[float]) -> tuple[float, float]:
    v = [x for x in values if math.isfinite(x)]
    lo, hi = (min(v), max(v)) if v else (0.0, 1.0)
    pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi) * 0.05, 1e-9)
    return lo - pad, hi + pad


def _title(rec: IterationRecord, name: str, describe: Mapping[str, str], units: Mapping) -> str:
    factor = next(f for f in rec.frame.factors if f.name == name)
    if factor.values is not None:
        return with_unit(name, units.get(name))
    short = short_combination(describe.get(name, ""))
    return f"{name}: {short}" if short else f"{name} (offset)"


def main_effects_svg(
    rec: IterationRecord,
    describe: Mapping[str, str] | None = None,
    units: Mapping[str, str] | None = None,
    cost_name: str = "cost",
) -> str:
    """Return the S/N and mean-cost main effects of one iteration as an SVG document."""
    describe, units = dict(describe or {}), dict(units or {})
    n = len(rec.names)
    row_h = _PH + 88
    width = _LEFT + n * (_PW + _GAP) + 10
    canvas = Canvas(width, 2 * row_h + 70)
    canvas.text(
        width / 2, 18, f"{rec.stage}, iteration {rec.index} ({rec.array}): main effects", 13
    )
    chosen = rec.response.best_level
    panels = []
    rows = ((rec.response, "mean S/N [dB]", " dB"), (rec.response_means, f"mean {cost_name}", ""))
    for r, (table, ylabel, unit) in enumerate(rows):
        top = 66 + r * row_h
        allv = [v for name in rec.names for v in table.means[name]] + [table.grand_mean]
        ylim = _limits(allv)
        ticks = nice_ticks(*ylim, 4)
        canvas.text(16, top + _PH / 2, ylabel, 11, rotate=True)
        for c, name in enumerate(rec.names):
            y = np.asarray(table.means[name], dtype=float)
            x = np.arange(1, len(y) + 1, dtype=float)
            p = Panel(_LEFT + c * (_PW + _GAP), top, _PW, _PH, (0.6, len(y) + 0.4), ylim)
            p.frame(ticks, labels=c == 0)
            p.line([0.6, len(y) + 0.4], [table.grand_mean] * 2, "#888", 1.2, "5,3")
            p.line(x, y, COLORS[0])
            p.markers(x, y, COLORS[0])
            k = chosen[name]
            p.markers([x[k]], [y[k]], COLORS[1], "square")
            labels = fmt_levels(rec.levels[name])
            p.xticks(list(x), labels, rotate=max(len(s) for s in labels) > 5)
            p.title(
                [
                    _title(rec, name, describe, units),
                    f"Δ {fmt(table.delta[name], 3)}{unit}, rank {table.rank[name]}",
                ]
            )
            panels.append(p)
    canvas.legend(
        _LEFT,
        2 * row_h + 58,
        [
            ("circle", COLORS[0], "mean of the runs at the level"),
            ("dash", "#888", "grand mean (all runs)"),
            ("square", COLORS[1], "chosen level (largest S/N)"),
        ],
    )
    return canvas.svg(panels)


def _shade(panel: Panel, e: PreparedExperiment) -> None:
    """Shade the spans of ``e`` that are scored (nothing when the whole record is)."""
    for start, stop in e.windows:
        panel.band(float(e.time[start]), float(e.time[stop - 1]))


def _fit_panels(
    canvas: Canvas, e: PreparedExperiment, j: int, sim: Simulated, top: float, units: Mapping
) -> list[Panel]:
    name = e.output_names[j]
    unit = units.get(name)
    t0, t1 = float(e.time[0]), float(e.time[-1])
    tm, ym = envelope(e.time, e.measured[:, j], 500)
    values: list[Any] = [e.measured[:, j]]
    if sim.outputs is not None:
        values.append(sim.outputs[:, j])
    ylim = _limits(
        [float(np.nanmin(np.concatenate(values))), float(np.nanmax(np.concatenate(values)))]
    )
    main = Panel(80, top, 760, 170, (t0, t1), ylim)
    _shade(main, e)
    main.frame(nice_ticks(*ylim, 5))
    main.line(tm, ym, "#777", 1.0)
    main.title([f"{e.name}: {name}"], 12)
    canvas.text(18, top + 85, with_unit(name, unit), 11, rotate=True)
    res = Panel(80, top + 190, 760, 60, (t0, t1), (-1.0, 1.0))
    if sim.outputs is None:
        main.label(f"simulation failed: {sim.error}")
        res.frame([])
        return [main, res]
    ts, ys = envelope(e.time, sim.outputs[:, j], 500)
    main.line(ts, ys, COLORS[1], 1.1)
    r = sim.outputs[:, j] - e.measured[:, j]
    rms = float(np.sqrt(np.nanmean(e.scored(r) ** 2)))
    where = " (shaded: the scored windows)" if e.windows else ""
    main.label(f"residual RMS {fmt(rms, 4)} {unit or ''}".rstrip() + where)
    res.ylim = _limits([float(np.nanmin(r)), float(np.nanmax(r))])
    _shade(res, e)
    res.frame(nice_ticks(*res.ylim, 4))
    tr, yr = envelope(e.time, r, 500)
    res.line(tr, yr, COLORS[1], 0.8)
    xt = nice_ticks(t0, t1, 8)
    res.xticks(xt, [fmt(v, 4) for v in xt])
    canvas.text(18, top + 220, with_unit("residual", unit), 10, rotate=True)
    return [main, res]


def fit_svg(
    experiments: Sequence[PreparedExperiment],
    simulated: Sequence[Simulated],
    units: Mapping[str, str] | None = None,
    title: str = "",
) -> str:
    """Return measured vs simulated outputs and residuals, per experiment and output."""
    units = dict(units or {})
    pairs = [
        (e, j, sim)
        for e, sim in zip(experiments, simulated, strict=True)
        for j in range(len(e.output_names))
    ]
    block, n = 300.0, len(pairs)
    bottom = 52 + block * (n - 1) + 282
    canvas = Canvas(860, bottom + 34)
    canvas.text(430, 18, title, 13)
    panels: list[Panel] = []
    for k, (e, j, sim) in enumerate(pairs):
        panels += _fit_panels(canvas, e, j, sim, 52 + k * block, units)
    canvas.text(460, bottom, "time [s]", 11)
    legend = [("line", "#777", "measured"), ("line", COLORS[1], "simulated")]
    canvas.legend(80, bottom + 24, legend)
    return canvas.svg(panels)
