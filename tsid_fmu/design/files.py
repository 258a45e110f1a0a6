"""The files of a design: the input to replay, a plot, the tables, JSON and reports.

``design_input.csv`` has the columns ``time`` and one per designed FMU input, at the
proposal's sample times: what a rig's controller replays. ``design.png`` shows the
input, the outputs the model predicts for it at the answer, and each parameter's 95 %
interval now and predicted with the proposal, relative to its value.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from tsid_fmu.design.outcome import Design, width

__all__ = ["plot_design", "write_design"]


def plot_design(d: Design, path: Path) -> Path:
    """Draw the proposed input, the predicted outputs and the intervals before and after."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = 3 if d.proposal is not None else 1
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.4 * rows + 0.6), squeeze=False)
    axes = axes[:, 0]
    if d.proposal is not None:
        for i, name in enumerate(d.inputs):
            axes[0].plot(d.time, d.proposal.values[:, i], lw=0.7, label=name)
        axes[0].set_title(f"proposed input: {d.proposal.name}")
        axes[0].set_xlabel("time [s]")
        axes[0].legend(fontsize=8)
        out = d.predicted_outputs
        for k, name in enumerate(d.output_names):
            y = out[:, k]  # type: ignore[index]
            scale = max(float(np.max(np.abs(y))), 1e-300)
            axes[1].plot(d.time, y / scale, lw=0.7, label=f"{name} / {scale:.3g}")
        axes[1].set_title("outputs predicted at the answer")
        axes[1].set_xlabel("time [s]")
        axes[1].legend(fontsize=8)
    ax = axes[-1]
    y = np.arange(len(d.names))
    for j, n in enumerate(d.names):
        value = abs(d.values[n]) or 1.0
        for iv, colour, dy, label in (
            (d.study_intervals.get(n), "0.5", -0.2, "study"),
            (d.after[j] if d.after else None, "C3", 0.2, "predicted with the proposal"),
        ):
            w = width(iv)
            if math.isfinite(w):
                ax.plot([iv[0] / value, iv[1] / value], [y[j] + dy] * 2, color=colour, lw=3,  # type: ignore[index]
                        label=label if j == 0 else None)  # fmt: skip
            elif iv is not None:
                ax.text(1.0, y[j] + dy, "open", color=colour, fontsize=8, va="center")
    ax.axvline(1.0, color="0.8", lw=0.8)
    ax.set_yticks(y, d.names)
    ax.set_xlabel("95 % interval / value")
    ax.set_title("intervals")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _html(d: Design, png: bytes) -> str:
    """Return ``design.html``: the report section, with ``report.html``'s tables and style."""
    from tsid_fmu.report.html_tables import CSS, esc, image, table

    part = d.section()
    body = ["<h1>Experiment design</h1>", f"<p><strong>{esc(d.verdict)}</strong></p>",
            "<ul>" + "".join(f"<li>{esc(f)}</li>" for f in part["facts"]) + "</ul>",
            table(*part["intervals"])]  # fmt: skip
    if part["separate"] is not None:
        said, columns, rows = part["separate"]
        body += [f"<p>{esc(said)}</p>", table(columns, rows)]
    body += [f"<p>{esc(sentence)}</p>" for sentence in part["structural"]]
    body.append(image(png, "the proposed input, the outputs it gives, and the intervals"))
    return (
        "<!doctype html><html><head><meta charset='utf-8'><title>tsid design</title>"
        f"<style>{CSS}</style></head><body>{''.join(body)}</body></html>"
    )


def write_design(d: Design, out: str | Path) -> list[Path]:
    """Write the design's files into ``out``; return their paths.

    ``design_input.csv`` (with a proposal), ``design_structures_input.csv`` (where the
    study's structures tied), ``design.png``, ``design.json``, ``design.md`` and
    ``design.html``.
    """
    import pandas as pd

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for signal, name in ((d.proposal, "design_input.csv"),
                         (d.separating, "design_structures_input.csv")):  # fmt: skip
        if signal is not None:
            frame = pd.DataFrame(signal.values, columns=d.inputs)
            frame.insert(0, "time", d.time)
            frame.to_csv(out / name, index=False)
            files.append(out / name)
    js = out / "design.json"
    js.write_text(json.dumps(d.to_dict(), indent=1, allow_nan=False), encoding="utf-8")
    md = out / "design.md"
    md.write_text(d.markdown(), encoding="utf-8")
    png = plot_design(d, out / "design.png")
    page = out / "design.html"
    page.write_text(_html(d, png.read_bytes()), encoding="utf-8")
    return [*files, png, js, md, page]
