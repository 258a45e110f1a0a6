"""Plots of a study: main effects, fit, convergence (PNG, written atomically)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.evaluate.protocol import Simulated
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageResult
from tsid_fmu.trail.files import atomic_write

__all__ = ["convergence_plot", "fit_plot", "main_effects_plot"]


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> None:
    plt = _pyplot()
    atomic_write(path, lambda p: fig.savefig(p, dpi=110, bbox_inches="tight", format="png"))
    plt.close(fig)


def main_effects_plot(
    rec: IterationRecord, path: Path, describe: dict[str, str] | None = None
) -> None:
    """Plot the mean S/N of each level of each factor (the papers' Figs. 7-9).

    Parameters
    ----------
    rec : IterationRecord
        The iteration.
    path : Path
        PNG file to write.
    describe : dict, optional
        What each rotated factor moves, shown under its name.
    """
    plt = _pyplot()
    means = rec.sn_means()
    n = len(rec.names)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n + 0.6, 3.2), sharey=True, squeeze=False)
    decisions = {d.name: d for d in rec.decision.parameters}
    grand = float(np.mean(rec.sn))
    for ax, name in zip(axes[0], rec.names, strict=True):
        y = np.asarray(means[name])
        x = np.arange(1, len(y) + 1)
        ax.axhline(grand, color="0.6", lw=0.8, ls="--", label="grand mean")
        ax.plot(x, y, "o-", color="tab:blue", label="mean S/N of the level")
        best = int(np.nanargmax(y))
        ax.plot(x[best], y[best], "o", color="tab:red", ms=10, mfc="none", label="best level")
        ax.set_xticks(x)
        ax.set_xticklabels([f"{v:.4g}" for v in rec.levels[name]], rotation=45, fontsize=7)
        d = decisions.get(name)
        label = name if not describe or name not in describe else f"{name}\n{describe[name]}"
        ax.set_title(f"{label}\n{d.case} ({d.delta_db:.2g} dB)" if d else label, fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("mean S/N [dB]")
    axes[0][-1].legend(fontsize=7, loc="best")
    fig.suptitle(
        f"{rec.stage}, iteration {rec.index}: S/N main effects ({rec.array})", fontsize=10, y=1.08
    )
    _save(fig, path)


def fit_plot(
    spec: EvaluationSpec,
    simulated: Sequence[Simulated],
    path: Path,
    title: str = "",
    units: dict[str, str] | None = None,
) -> None:
    """Plot measured and simulated outputs, and their difference, for each experiment."""
    plt = _pyplot()
    panels = [
        (e, sim, j)
        for e, sim in zip(spec.experiments, simulated, strict=True)
        for j in range(len(e.output_names))
    ]
    fig, axes = plt.subplots(
        2 * len(panels),
        1,
        figsize=(9, 3.2 * len(panels)),
        squeeze=False,
        gridspec_kw={"height_ratios": [3, 1] * len(panels)},
    )
    for k, (e, sim, j) in enumerate(panels):
        ax, ax_e = axes[2 * k][0], axes[2 * k + 1][0]
        name = e.output_names[j]
        unit = (units or {}).get(name, "")
        ax.plot(e.time, e.measured[:, j], color="0.4", lw=0.8, label="measured")
        if sim.outputs is not None:
            ax.plot(e.time, sim.outputs[:, j], color="tab:red", lw=0.9, label="simulated")
            ax_e.plot(e.time, sim.outputs[:, j] - e.measured[:, j], color="tab:red", lw=0.6)
        else:
            ax.text(
                0.5, 0.5, f"simulation failed: {sim.error}", transform=ax.transAxes, ha="center"
            )
        ax.set_ylabel(f"{name} [{unit}]" if unit else name)
        ax.set_title(f"{e.name}: {name}", fontsize=9)
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(True, alpha=0.3)
        ax_e.set_ylabel("sim - meas")
        ax_e.grid(True, alpha=0.3)
    axes[-1][0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def convergence_plot(stages: Sequence[StageResult], path: Path) -> None:
    """Plot the best cost on the measured inputs after each iteration of each stage."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.6))
    total = 0
    for st in stages:
        if st.records:
            nfev = [r.nfev_total for r in st.records]
            ax.semilogy(nfev, [r.best_cost for r in st.records], "o-", ms=3, label=st.name)
        elif st.kind == "refinement" and math.isfinite(st.cost):
            ax.semilogy([total + st.nfev], [st.cost], "k*", ms=10, label=st.name)
        total += st.nfev
    ax.set_xlabel("simulations")
    ax.set_ylabel("best cost (measured inputs)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    _save(fig, path)
