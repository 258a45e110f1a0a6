"""Fit figures: measured and simulated output, and the residual, per experiment and output.

Long records are thinned for drawing to the smallest and largest sample of each of
:data:`BINS` bins, which keeps every peak a reader could see at the figure's width.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.evaluate.protocol import Simulated
from tsid_fmu.evaluate.spec import PreparedExperiment
from tsid_fmu.report.style import (
    COLORS,
    TICK_PT,
    axis_formatter,
    fmt,
    margins,
    new_figure,
    with_unit,
)
from tsid_fmu.report.svg import WINDOW_FILL

__all__ = ["BINS", "FitFigure", "envelope"]

BINS = 1200
"""Bins of the min/max thinning of a drawn time series."""


def envelope(t: np.ndarray, y: np.ndarray, bins: int = BINS) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(t, y)`` thinned to each bin's smallest and largest sample, in time order.

    The bins hold ``len(t) // bins`` samples each; the samples past the last whole bin
    are kept as they are.
    """
    n = len(t)
    k = n // bins if bins > 0 else 0
    if k < 3:
        return t, y
    m = k * bins
    block = np.asarray(y[:m], dtype=float).reshape(bins, k)
    filled = np.where(np.isfinite(block), block, np.nan)
    finite = np.isfinite(filled).any(axis=1)
    lo = np.where(finite, np.argmin(np.where(np.isnan(filled), np.inf, filled), axis=1), 0)
    hi = np.where(finite, np.argmax(np.where(np.isnan(filled), -np.inf, filled), axis=1), 0)
    base = np.arange(bins) * k
    first, second = base + np.minimum(lo, hi), base + np.maximum(lo, hi)
    keep = np.concatenate([np.column_stack([first, second]).ravel(), np.arange(m, n)])
    return t[keep], y[keep]


class FitFigure:
    """Measured vs simulated outputs and their residuals; redraws into one figure.

    Parameters
    ----------
    experiments : sequence of PreparedExperiment
        The experiments, in the order of the simulations given to :meth:`draw`.
    units : mapping, optional
        Unit of each FMU output variable.
    """

    def __init__(
        self, experiments: Sequence[PreparedExperiment], units: Mapping[str, str] | None = None
    ) -> None:
        self.experiments = list(experiments)
        self.units = dict(units or {})
        self.panels = [(e, j) for e in self.experiments for j in range(len(e.output_names))]
        n = len(self.panels)
        self.fig = new_figure(9.0, 3.1 * n + 0.6)
        axes = self.fig.subplots(
            2 * n, 1, squeeze=False, gridspec_kw={"height_ratios": [3, 1.2] * n}
        )
        self.lines = []
        for k, (e, j) in enumerate(self.panels):
            ax, ax_r = axes[2 * k][0], axes[2 * k + 1][0]
            name = e.output_names[j]
            unit = self.units.get(name)
            t, y = envelope(e.time, e.measured[:, j])
            for k, (start, stop) in enumerate(e.windows):  # the samples that are scored
                span = (float(e.time[start]), float(e.time[stop - 1]))
                ax.axvspan(*span, color=WINDOW_FILL, lw=0, label=None if k else "scored")
                ax_r.axvspan(*span, color=WINDOW_FILL, lw=0)
            ax.plot(t, y, color="0.45", lw=0.8, label="measured")
            (sim,) = ax.plot([], [], color=COLORS[1], lw=0.9, label="simulated")
            (res,) = ax_r.plot([], [], color=COLORS[1], lw=0.6)
            ax_r.axhline(0.0, color="0.5", lw=0.6)
            ax.set_ylabel(with_unit(name, unit), fontsize=8)
            ax_r.set_ylabel(with_unit("residual", unit), fontsize=8)
            ax_r.set_xlabel("time [s]", fontsize=8)
            ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
            note = ax.text(0.01, 0.97, "", transform=ax.transAxes, va="top", fontsize=7)
            for a in (ax, ax_r):
                a.grid(True, alpha=0.3)
                a.tick_params(labelsize=TICK_PT)
                a.yaxis.set_major_formatter(axis_formatter())
                a.set_xlim(float(e.time[0]), float(e.time[-1]))
            self.lines.append((ax, ax_r, sim, res, note))
        self.title = self.fig.suptitle("", fontsize=9)
        margins(self.fig, 0.55, 0.45, left=0.1, right=0.98, hspace=0.5)

    def draw(self, simulated: Sequence[Simulated], title: str = "") -> Any:
        """Return the figure with ``simulated`` (one per experiment) drawn in."""
        by_exp = dict(zip([e.name for e in self.experiments], simulated, strict=True))
        for (e, j), (ax, ax_r, sim_line, res_line, note) in zip(
            self.panels, self.lines, strict=True
        ):
            sim = by_exp[e.name]
            name = e.output_names[j]
            ax.set_title(f"{e.name}: {name}", fontsize=8, loc="left")
            if sim.outputs is None:
                sim_line.set_data([], [])
                res_line.set_data([], [])
                note.set_text(f"simulation failed: {sim.error}")
                continue
            residual = sim.outputs[:, j] - e.measured[:, j]
            sim_line.set_data(*envelope(e.time, sim.outputs[:, j]))
            res_line.set_data(*envelope(e.time, residual))
            rms = float(np.sqrt(np.mean(e.scored(residual) ** 2)))
            note.set_text(f"residual RMS {fmt(rms, 4)} {self.units.get(name, '')}".rstrip())
            lo, hi = np.nanmin(residual), np.nanmax(residual)
            pad = 0.05 * (hi - lo) if hi > lo else 1.0
            ax_r.set_ylim(lo - pad, hi + pad)
            both = np.concatenate([e.measured[:, j], sim.outputs[:, j]])
            lo, hi = np.nanmin(both), np.nanmax(both)
            pad = 0.05 * (hi - lo) if hi > lo else 1.0
            ax.set_ylim(lo - pad, hi + pad)
        self.title.set_text(title)
        return self.fig
