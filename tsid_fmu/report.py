"""Reports of a study: plots, a Markdown report, and parameter sets other tools open.

Outputs are plain files: PNG plots, CSV tables, ``result.json``, a Markdown report and
the identified parameter set as an SSP parameter-value file (``parameters.ssv``, the
Modelica Association's exchange format that FMI tools import), so the result can be
used outside tsid-fmu.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any
from xml.etree import ElementTree as ET

import numpy as np

from tsid_fmu.trail import atomic_write

if TYPE_CHECKING:
    from tsid_fmu.engine import IdentificationResult, IterationRecord

__all__ = [
    "convergence_plot",
    "fit_plot",
    "main_effects_plot",
    "parameter_set_ssv",
    "write_outputs",
    "write_phased_outputs",
]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> None:
    plt = _pyplot()
    atomic_write(path, lambda p: fig.savefig(p, dpi=110, bbox_inches="tight", format="png"))
    plt.close(fig)


def main_effects_plot(rec: IterationRecord, path: Path) -> None:
    """Plot the mean S/N of each level of each parameter (the papers' Figs. 7-9).

    Parameters
    ----------
    rec : IterationRecord
        The iteration.
    path : Path
        PNG file to write.
    """
    plt = _pyplot()
    means = rec.sn_means()
    n = len(rec.names)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n + 0.6, 3.0), sharey=True, squeeze=False)
    decisions = {d.name: d for d in rec.decision.parameters}
    for ax, name in zip(axes[0], rec.names, strict=True):
        y = means[name]
        x = np.arange(1, len(y) + 1)
        ax.plot(x, y, "o-", color="tab:blue")
        best = int(np.nanargmax(y))
        ax.plot(x[best], y[best], "o", color="tab:red", ms=9, mfc="none")
        ax.set_xticks(x)
        ax.set_xticklabels([f"{v:.4g}" for v in rec.levels[name]], rotation=45, fontsize=7)
        d = decisions.get(name)
        ax.set_title(
            f"{name}\n{d.case if d else ''} ({d.delta_db:.2g} dB)" if d else name, fontsize=9
        )
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("mean S/N [dB]")
    fig.suptitle(
        f"Iteration {rec.index}: main effects of the S/N ratio ({rec.array})", fontsize=10, y=1.06
    )
    _save(fig, path)


def fit_plot(simulated: Sequence[tuple[Any, Any, str | None]], path: Path, title: str = "") -> None:
    """Plot measured and simulated outputs (and their difference) for each experiment.

    Parameters
    ----------
    simulated : sequence of tuple
        ``(prepared experiment, simulated outputs or None, error or None)`` as returned by
        :meth:`tsid_fmu.runner.Evaluator.simulate_clean`.
    path : Path
        PNG file to write.
    title : str
        Figure title.
    """
    plt = _pyplot()
    panels = [(p, y, err, j) for p, y, err in simulated for j in range(len(p.output_names))]
    fig, axes = plt.subplots(
        2 * len(panels), 1, figsize=(9, 3.2 * len(panels)), squeeze=False,
        gridspec_kw={"height_ratios": [3, 1] * len(panels)},
    )  # fmt: skip
    for k, (p, y, err, j) in enumerate(panels):
        ax, ax_e = axes[2 * k][0], axes[2 * k + 1][0]
        name = p.output_names[j]
        ax.plot(p.time, p.measured[:, j], color="0.4", lw=0.8, label="measured")
        if y is not None:
            ax.plot(p.time, y[:, j], color="tab:red", lw=0.9, label="simulated")
            ax_e.plot(p.time, y[:, j] - p.measured[:, j], color="tab:red", lw=0.6)
        else:
            ax.text(0.5, 0.5, f"simulation failed: {err}", transform=ax.transAxes, ha="center")
        ax.set_ylabel(name)
        ax.set_title(f"{p.experiment.name}: {name}", fontsize=9)
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(True, alpha=0.3)
        ax_e.set_ylabel("sim - meas")
        ax_e.grid(True, alpha=0.3)
    axes[-1][0].set_xlabel("time [s]")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    _save(fig, path)


def convergence_plot(result: IdentificationResult, path: Path) -> None:
    """Plot the best cost and each parameter's level range over the iterations."""
    plt = _pyplot()
    recs = result["iterations"]
    it = [r.index for r in recs]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
    ax1.semilogy(it, [r.best_cost for r in recs], "o-", label="best so far")
    ax1.semilogy(it, [np.min(r.mean_costs) for r in recs], "s--", alpha=0.6, label="best row")
    canon = result.get("canonical")
    if canon:
        ax1.semilogy(
            [len(recs) + r.index for r in canon],
            [r.best_cost for r in canon],
            "d-",
            label="canonical factors (measured input)",
        )
    ax1.set_xlabel("iteration")
    ax1.set_ylabel("cost")
    ax1.legend(fontsize=8)
    ax1.grid(True, which="both", alpha=0.3)
    x = result["x"]
    for name in recs[0].names:
        lo = [min(r.levels[name]) / x[name] if x[name] else math.nan for r in recs]
        hi = [max(r.levels[name]) / x[name] if x[name] else math.nan for r in recs]
        line = ax2.plot(it, hi, "-", label=name)[0]
        ax2.plot(it, lo, "-", color=line.get_color())
    ax2.set_yscale("log")
    ax2.set_xlabel("iteration")
    ax2.set_ylabel("level range / identified value")
    ax2.legend(fontsize=8)
    ax2.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    _save(fig, path)


def parameter_set_ssv(
    values: dict[str, float], descriptions: dict[str, str] | None = None, name: str = "tsid"
) -> str:
    """Return an SSP 1.0 parameter-value document (``.ssv``) holding ``values``."""
    ns = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    ET.register_namespace("ssv", ns)
    root = ET.Element(f"{{{ns}}}ParameterSet", {"version": "1.0", "name": name})
    params = ET.SubElement(root, f"{{{ns}}}Parameters")
    for key, value in values.items():
        attrs = {"name": key}
        if descriptions and descriptions.get(key):
            attrs["description"] = descriptions[key]
        p = ET.SubElement(params, f"{{{ns}}}Parameter", attrs)
        ET.SubElement(p, f"{{{ns}}}Real", {"value": repr(float(value))})
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _write_parameter_sets(result: IdentificationResult, out: Path) -> Any:
    """Write ``parameters.csv`` and ``parameters.ssv``; return the parameter table."""
    study = result["study"]
    params = result.parameters_frame()
    atomic_write(out / "parameters.csv", params.to_csv())
    units = {p.name: p.unit for p in study.parameters}
    values = dict(result["x"])
    values.update({k: v for k, v in study.start_values.items() if k not in values})
    desc = {k: f"identified, unit {units[k]}" if units.get(k) else "identified" for k in values}
    desc.update({k: "fixed in the study" for k in study.start_values})
    atomic_write(out / "parameters.ssv", parameter_set_ssv(values, desc, name=study.name))
    return params


def _markdown_table(frame: Any) -> str:
    cols = [frame.index.name or ""] + [str(c) for c in frame.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for idx, row in frame.iterrows():
        cells = [str(idx)] + [f"{v:.6g}" if isinstance(v, float) else str(v) for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_outputs(result: IdentificationResult, out: Path, simulated: Sequence[Any] | None) -> None:
    """Write ``result.json``, ``parameters.csv``, ``parameters.ssv``, plots and ``report.md``."""
    study = result["study"]
    out = Path(out)
    params = _write_parameter_sets(result, out)
    summary = {
        "study": study.name,
        "fmu": str(study.fmu),
        "x": result["x"],
        "fun": result["fun"] if math.isfinite(result["fun"]) else None,
        "success": result["success"],
        "status": result["status"],
        "message": result["message"],
        "nfev": result["nfev"],
        "nit": result["nit"],
        "best_source": result["best_source"],
        "weak": result["weak"],
        "contribution": result["contribution"],
        "fit": result["fit"],
        "noise": result.get("noise"),
    }
    atomic_write(out / "result.json", json.dumps(summary, indent=2) + "\n")
    if simulated is not None:
        convergence_plot(result, out / "convergence.png")
        fit_plot(simulated, out / "fit.png", title="Identified model vs measured data")
    cost_kind = (
        "on the measured inputs"
        if result.get("canonical")
        else f"mean over {study.replicates} noisy-input replicates"
    )
    lines = [
        f"# Identification report: {study.name}",
        "",
        f"- FMU: `{study.fmu}`",
        f"- Result: **{result['message']}** ({result['nit']} iterations, "
        f"{result['nfev']} simulations)",
        f"- Best cost ({study.cost}, {cost_kind}): {result['fun']:.6g}, "
        f"found at {result['best_source']}",
        "",
        "## Identified parameters",
        "",
        _markdown_table(params),
        "",
        "## Fit at the identified parameters (measured input, no added noise)",
        "",
    ]
    noise = result.get("noise") or {}
    for exp, per_output in result["fit"].items():
        for output, m in per_output.items():
            if isinstance(m, dict):
                sigma = noise.get(exp, {}).get(output)
                beside = f" (noise in the data: {sigma:.3g})" if sigma is not None else ""
                lines.append(
                    f"- {exp} / {output}: fit {m['fit_percent']:.3f} %, IAE {m['iae']:.6g}, "
                    f"RMSE {m['rmse']:.6g}{beside}"
                )
            else:
                lines.append(f"- {exp}: {m}")
    if result["weak"]:
        lines += ["", "## Weakly constrained parameters", ""]
        lines += [f"- **{k}**: {v}" for k, v in result["weak"].items()]
    lines += _failed_runs(result["iterations"])
    lines += ["", "## Iterations", "", "| iteration | array | case | best cost | simulations |",
              "|---|---|---|---|---|"]  # fmt: skip
    for rec in result["iterations"]:
        lines.append(
            f"| [{rec.index}](iteration_{rec.index:02d}/) | {rec.array} | {rec.decision.case} | "
            f"{rec.best_cost:.6g} | {rec.nfev} |"
        )
    lines += _canonical_lines(result.get("canonical", []))
    if simulated is not None:
        lines += ["", "![fit](fit.png)", "", "![convergence](convergence.png)"]
    atomic_write(out / "report.md", "\n".join(lines) + "\n")


def _canonical_lines(records: Sequence[Any]) -> list[str]:
    """Return the report's table of iterations on canonical factors (none: no lines)."""
    if not records:
        return []
    lines = [
        "",
        "## Iterations on canonical factors",
        "",
        "Taguchi arrays over the principal axes of the local cost surface "
        "(`tsid_fmu/canonical.py`); costs on the measured inputs, S/N over the replicates.",
        "",
        "| iteration | array | best cost | found at | largest S/N spread [dB] | converged "
        "| simulations |",
        "|---|---|---|---|---|---|---|",
    ]
    for rec in records:
        spreads = [v for v in rec.extra.get("sn_spread_db", []) if not math.isnan(v)]
        spread = max(spreads) if spreads else math.nan
        lines.append(
            f"| [C{rec.index}](canonical_{rec.index:02d}/) | {rec.array} | {rec.best_cost:.6g} "
            f"| {rec.best_source} | {spread:.3g} | {'yes' if rec.converged else 'no'} "
            f"| {rec.nfev} |"
        )
    return lines


def write_phased_outputs(result: IdentificationResult, out: Path) -> None:
    """Write the files of a phased study: result, parameter sets and ``report.md``."""
    study = result["study"]
    out = Path(out)
    params = _write_parameter_sets(result, out)

    def clean(v: Any) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, list):
            return [clean(x) for x in v]
        return v

    summary = {
        "study": study.name,
        "fmu": str(study.fmu),
        "x": result["x"],
        "fun": result["fun"],
        "success": result["success"],
        "message": result["message"],
        "nfev": result["nfev"],
        "nit": result["nit"],
        "phases": result["phases"],
        "groups": result["groups"],
        "weak": result["weak"],
        "validation": result["validation"],
        "comparison": result["comparison"],
    }
    atomic_write(out / "result.json", json.dumps(clean(summary), indent=2) + "\n")
    lines = [
        f"# Phased identification report: {study.name}",
        "",
        f"- FMU: `{study.fmu}`",
        f"- Result: **{result['message']}** ({result['nit']} iterations, "
        f"{result['nfev']} simulations)",
        f"- Cost ({study.cost}) at the identified parameters, identification experiments, "
        f"no added noise: {result['fun']:.6g}",
        "",
    ]
    inc = result["input_contribution"]
    if inc is not None:
        lines += [
            "## Input contribution (Step i)",
            "",
            _markdown_table(inc.to_pandas()),
            "",
            f"Main contributor: **{inc.experiments[0]}** (identified first).",
            "",
        ]
    if result["parameter_contribution"]:
        lines += ["## Parameter contribution (Step ii, % of error variation)", ""]
        for exp, pc in result["parameter_contribution"].items():
            ranked = sorted(pc.percent.items(), key=lambda kv: -kv[1])
            lines.append(
                f"- {exp}: "
                + ", ".join(f"{k} {v:.3g} %" for k, v in ranked)
                + f"; groups {result['groups'].get(exp, [])}"
            )
        lines.append("")
    lines += ["## Phases", "", "| phase | parameters | experiments | iterations | "
              "simulations | cost | outcome |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for i, ph in enumerate(result["phases"], start=1):
        lines.append(
            f"| [{ph['name']}](phase_{i:02d}/report.md) | {', '.join(ph['parameters'])} | "
            f"{', '.join(ph['experiments'])} | {ph['nit']} | {ph['nfev']} | {ph['fun']:.6g} | "
            f"{ph['message']} |"
        )
    lines += ["", "## Identified parameters", "", _markdown_table(params), ""]
    if result["weak"]:
        lines += ["## Weakly constrained parameters", ""]
        lines += [f"- **{k}**: {v}" for k, v in result["weak"].items()]
        lines.append("")
    lines += _failed_runs(result["iterations"])
    val = result["validation"]
    if val:
        lines += ["## Superposition check (all inputs together)", ""]
        for name, v in val.items():
            if name.startswith("_"):
                continue
            if "error" in v:
                lines.append(f"- {name}: simulation failed: {v['error']}")
                continue
            fits = ", ".join(f"{o} fit {m['fit_percent']:.2f} %" for o, m in v["fit"].items())
            lines.append(f"- {name}: {v['cost_kind']} cost {v['cost']:.6g}; {fits}")
        lines += ["", "![validation](validation/fit.png)", ""]
    comp = result["comparison"]
    if comp:
        ph, un = comp["phased"], comp["ungrouped"]
        lines += [
            "## Why grouping: the same study without it",
            "",
            "| | cost (identification experiments) | validation cost | simulations |",
            "|---|---|---|---|",
            f"| grouped, in phases | {ph['cost']:.6g} | {_num(ph['validation_cost'])} | "
            f"{ph['nfev']} |",
            f"| all parameters in one array | {un['cost']:.6g} | {_num(un['validation_cost'])} | "
            f"{un['nfev']} |",
            "",
        ]
    atomic_write(out / "report.md", "\n".join(lines) + "\n")


def _num(v: Any) -> str:
    return f"{v:.6g}" if isinstance(v, (int, float)) else "-"


def _failed_runs(records: Sequence[IterationRecord]) -> list[str]:
    """Markdown lines listing every run that failed (scored worst), with its reason."""
    rows = [
        (rec.index, run + 1, err) for rec in records for run, err in enumerate(rec.errors) if err
    ]
    if not rows:
        return []
    out = ["", f"## Failed runs ({len(rows)}, each scored worst; the study went on)", ""]
    out += ["| iteration | run | reason |", "|---|---|---|"]
    out += [f"| {i} | {r} | {e.replace('|', '/')} |" for i, r, e in rows]
    return out
