"""Figures of the Taguchi search: main effects, convergence, parameter trajectories.

Every function returns a :class:`matplotlib.figure.Figure` (see :mod:`.style`); nothing
is written here. :class:`MainEffects` keeps one figure per layout and redraws only its
data, so a study with many iterations pays for its axes once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.report.style import (
    COLORS,
    TICK_PT,
    axis_formatter,
    fmt,
    fmt_levels,
    margins,
    new_figure,
    short_combination,
    with_unit,
)
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageKind, StageResult

__all__ = ["MainEffects", "convergence_figure", "trajectory_figure"]

_LEGEND = {
    "mean": "mean of the runs at the level",
    "grand": "grand mean (all runs)",
    "chosen": "chosen level (largest S/N)",
}


class MainEffects:
    """Main-effects plots of S/N (top row) and of the mean cost (bottom row).

    Parameters
    ----------
    cost_name : str
        What the cost is (``"SSE, weighted"``), for the axis label of the bottom row.
    """

    def __init__(self, cost_name: str = "cost") -> None:
        self.cost_name = cost_name
        self._figures: dict[int, tuple[Any, list[dict[str, Any]]]] = {}

    def _layout(self, n: int) -> tuple[Any, list[dict[str, Any]]]:
        if n in self._figures:
            return self._figures[n]
        fig = new_figure(1.9 * n + 1.1, 4.6)
        axes = fig.subplots(2, n, squeeze=False)
        fig.subplots_adjust(
            left=0.9 / (1.9 * n + 1.1), right=0.985, top=0.84, bottom=0.2, wspace=0.12, hspace=0.75
        )
        panels = []
        for row in range(2):
            for col in range(n):
                ax = axes[row][col]
                grand = ax.axhline(0.0, color="0.55", lw=0.9, ls="--", label=_LEGEND["grand"])
                (line,) = ax.plot([], [], "o-", color=COLORS[0], ms=4, label=_LEGEND["mean"])
                (mark,) = ax.plot(
                    [],
                    [],
                    "s",
                    color=COLORS[1],
                    mfc="none",
                    ms=10,
                    mew=1.5,
                    label=_LEGEND["chosen"],
                )
                title = ax.text(
                    0.5, 1.04, "", transform=ax.transAxes, ha="center", va="bottom", fontsize=8
                )
                ax.yaxis.set_major_formatter(axis_formatter())
                ax.tick_params(labelsize=TICK_PT, labelleft=col == 0)
                ax.grid(True, alpha=0.3)
                panels.append(
                    {"ax": ax, "grand": grand, "line": line, "mark": mark, "title": title}
                )
        axes[0][0].set_ylabel("mean S/N [dB]", fontsize=8)
        axes[1][0].set_ylabel(f"mean {self.cost_name}", fontsize=8)
        handles = [panels[0]["line"], panels[0]["grand"], panels[0]["mark"]]
        fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=7, frameon=False)
        heading = fig.text(0.5, 0.97, "", ha="center", va="top", fontsize=9)
        self._figures[n] = (fig, [*panels, {"heading": heading}])
        return self._figures[n]

    def draw(
        self,
        rec: IterationRecord,
        describe: Mapping[str, str] | None = None,
        units: Mapping[str, str] | None = None,
    ) -> Any:
        """Return the figure of ``rec`` (the same object for every record of a layout)."""
        n = len(rec.names)
        fig, panels = self._layout(n)
        tables = (rec.response, rec.response_means)
        for row, table in enumerate(tables):
            for col, name in enumerate(rec.names):
                p = panels[row * n + col]
                y = np.asarray(table.means[name], dtype=float)
                x = np.arange(1, len(y) + 1)
                chosen = rec.response.best_level[name]
                p["grand"].set_ydata([table.grand_mean, table.grand_mean])
                p["line"].set_data(x, y)
                p["mark"].set_data([x[chosen]], [y[chosen]])
                _limits(p["ax"], [*y, table.grand_mean], len(y))
                p["ax"].set_xticks(x)
                p["ax"].set_xticklabels(_level_labels(rec, name), fontsize=TICK_PT, rotation=30)
                p["title"].set_text(_panel_title(rec, name, row, table, describe, units))
        panels[-1]["heading"].set_text(
            f"{rec.stage}, iteration {rec.index} ({rec.array}): main effects "
            f"(S/N = -10 lg mean(cost²), larger is better)"
        )
        return fig


def _limits(ax: Any, values: Sequence[float], n: int) -> None:
    finite = [v for v in values if math.isfinite(v)]
    lo, hi = (min(finite), max(finite)) if finite else (0.0, 1.0)
    pad = 0.08 * (hi - lo) if hi > lo else max(abs(hi) * 0.05, 1e-12)
    ax.set_ylim(lo - pad, hi + pad)
    ax.set_xlim(0.6, n + 0.4)


def _level_labels(rec: IterationRecord, name: str) -> list[str]:
    return fmt_levels(rec.levels[name])


def _panel_title(
    rec: IterationRecord,
    name: str,
    row: int,
    table: Any,
    describe: Mapping[str, str] | None,
    units: Mapping[str, str] | None,
) -> str:
    factor = next(f for f in rec.frame.factors if f.name == name)
    if factor.values is None:
        short = short_combination((describe or {}).get(name, ""))
        label = f"{name}: {short}" if short else f"{name} (offset)"
    else:
        label = with_unit(name, (units or {}).get(name))
    unit = " dB" if row == 0 else ""
    return f"{label}\nΔ {fmt(table.delta[name], 3)}{unit}, rank {table.rank[name]}"


def _measure(stage: StageResult) -> tuple[str, ...]:
    return tuple(stage.experiments) or ("the study's experiments",)


def _costs(stage: StageResult) -> list[float]:
    return [r.best_cost for r in stage.records] if stage.records else [stage.cost]


def _cost_axis(ax: Any, costs: Sequence[float]) -> None:
    """Log scale where the costs span more than a decade, else linear; plain tick labels."""
    from matplotlib.ticker import NullFormatter

    finite = [c for c in costs if math.isfinite(c) and c > 0]
    if finite and max(finite) / min(finite) > 10:
        ax.set_yscale("log")
        ax.yaxis.set_minor_formatter(NullFormatter())
    else:
        ax.yaxis.set_major_formatter(axis_formatter())


def points(result: Any) -> dict[str, int]:
    """Return the points each study figure would draw: ``{"convergence.png": n, ...}``.

    A figure of fewer than two points carries nothing a sentence does not: the report
    draws only those with two or more (:data:`MIN_POINTS`).
    """
    stages = result.stages
    best = sum(len(s.records) for s in stages)
    best += sum(1 for s in stages if not s.records and s.kind == StageKind.REFINEMENT)
    return {"convergence.png": best, "parameters.png": len(result.iterations)}


MIN_POINTS = 2
"""Fewest points a convergence or parameter-trajectory figure is drawn with."""


def convergence_figure(stages: Sequence[StageResult], cost_name: str = "cost") -> Any:
    """Best cost after each iteration: one panel per measure (set of experiments).

    Stages that score different experiments have costs that cannot be compared; each
    set of experiments gets its own axis. The x axis counts the study's simulations.
    """
    measures: dict[tuple[str, ...], list[tuple[StageResult, int]]] = {}
    total = 0
    for st in stages:
        if st.records or (st.kind == StageKind.REFINEMENT and math.isfinite(st.cost)):
            measures.setdefault(_measure(st), []).append((st, total))
        total += st.nfev
    n = max(len(measures), 1)
    fig = new_figure(8.0, 2.6 * n + 0.4)
    axes = fig.subplots(n, 1, squeeze=False)
    for k, (exps, entries) in enumerate(measures.items()):
        ax = axes[k][0]
        for j, (st, before) in enumerate(entries):
            color = COLORS[j % len(COLORS)]
            if st.records:
                x = np.cumsum([r.nfev for r in st.records]) + before
                y = [r.best_cost for r in st.records]
                ax.plot(x, y, "o-", ms=3, color=color, label=st.name)
            else:
                ax.plot([before + st.nfev], [st.cost], "*", ms=11, color=color, label=st.name)
        _cost_axis(ax, [c for st, _ in entries for c in _costs(st)])
        ax.set_ylabel(f"best {cost_name}", fontsize=8)
        label = "experiment" if len(exps) == 1 else "experiments"
        ax.set_title(
            f"on the measured inputs of the {label} {', '.join(exps)}", fontsize=8, loc="left"
        )
        ax.legend(fontsize=7, loc="upper right", framealpha=0.85)
        ax.grid(True, which="major", alpha=0.3)
        ax.tick_params(labelsize=TICK_PT)
    axes[-1][0].set_xlabel("simulations of the study so far", fontsize=8)
    margins(fig, 0.45, 0.5, left=0.1, right=0.98, hspace=0.45)
    return fig


def _window(rec: IterationRecord, name: str) -> tuple[float, float] | None:
    for f in rec.frame.factors:
        if f.name == name and f.values is not None:
            return min(f.values), max(f.values)
    return None


def trajectory_figure(
    records: Sequence[IterationRecord],
    names: Sequence[str],
    units: Mapping[str, str] | None = None,
    final: Mapping[str, float] | None = None,
) -> Any:
    """Each parameter's best value per iteration, with its level window where it is a factor.

    Iterations on rotated factors have no window per parameter (their factors move
    combinations); the axis is logarithmic where the values span more than a decade.
    """
    from matplotlib.ticker import MaxNLocator

    n = max(len(names), 1)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig = new_figure(3.2 * cols + 0.4, 2.5 * rows + 0.5)
    axes = fig.subplots(rows, cols, squeeze=False)
    k = np.arange(1, len(records) + 1)
    for i, name in enumerate(names):
        ax = axes[i // cols][i % cols]
        y = np.array([r.best_x.get(name, math.nan) for r in records], dtype=float)
        win = [_window(r, name) for r in records]
        lo = np.array([w[0] if w else math.nan for w in win])
        hi = np.array([w[1] if w else math.nan for w in win])
        if np.isfinite(lo).any():
            ax.vlines(k, lo, hi, color="0.6", lw=4, alpha=0.6, label="level window")
        ax.plot(k, y, "o-", color=COLORS[0], ms=3, label="best value so far")
        if final and name in final and math.isfinite(final[name]):
            ax.axhline(final[name], color=COLORS[1], lw=0.9, ls=":", label="identified")
        values = np.concatenate([y, lo, hi])
        values = values[np.isfinite(values) & (values > 0)]
        if values.size and values.min() > 0 and values.max() / values.min() > 10:
            ax.set_yscale("log")
        else:
            ax.yaxis.set_major_formatter(axis_formatter())
        ax.set_title(with_unit(name, (units or {}).get(name)), fontsize=8)
        ax.tick_params(labelsize=TICK_PT)
        ax.grid(True, which="major", alpha=0.3)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlim(0.5, len(records) + 0.5)
        ax.set_xlabel("iteration (all stages in order)", fontsize=7)
    for j in range(n, rows * cols):
        axes[j // cols][j % cols].set_visible(False)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7, frameon=False)
    margins(fig, 0.35, 0.9, left=0.07, right=0.98, hspace=0.6, wspace=0.25)
    return fig
