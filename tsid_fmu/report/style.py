"""One look for every report: number formatting and the figure canvas.

Numbers are shown to :data:`SIGNIFICANT` significant figures everywhere (tables, tick
labels, legends), in plain notation between 1e-3 and 1e6 and in one scientific notation
outside it, so that one axis never mixes ``1e+04`` and ``1.178e+04``.

Figures are :class:`matplotlib.figure.Figure` objects on an Agg canvas (no pyplot, no
global state), rendered to PNG at twice the resolution they are shown at
(:data:`SCREEN_DPI` CSS pixels per inch, :data:`PNG_DPI` dots per inch).
"""

from __future__ import annotations

import io
import math
import re
from collections.abc import Sequence
from typing import Any

__all__ = [
    "PNG_DPI",
    "SCREEN_DPI",
    "SIGNIFICANT",
    "SVG_TICK_PX",
    "TICK_PT",
    "axis_formatter",
    "cost_name",
    "fit_text",
    "fmt",
    "fmt_levels",
    "input_contribution",
    "margins",
    "new_figure",
    "png_bytes",
    "short_combination",
    "with_unit",
]

SIGNIFICANT = 5
"""Significant figures of every number in a report."""

SCREEN_DPI = 80
"""CSS pixels per inch a figure is shown at in ``report.html``."""

PNG_DPI = 2 * SCREEN_DPI
"""Dots per inch of the PNG files (2x: sharp on high-density screens)."""

TICK_PT = 8.5
"""Font size of the tick labels of the matplotlib figures, in points (9.4 CSS pixels at
:data:`SCREEN_DPI`; 7 points were under 8 pixels, too small to read)."""

SVG_TICK_PX = 12.0
"""Font size of the tick labels of the SVG figures of each iteration, in CSS pixels."""

COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf")
"""Line colours, in order of use."""


def fmt(x: Any, sig: int = SIGNIFICANT) -> str:
    """Return ``x`` to ``sig`` significant figures (plain notation from 1e-3 to 1e6).

    Integers and text are returned as they are; NaN as ``-``; infinities as ``inf``.
    """
    if isinstance(x, bool) or x is None:
        return "-" if x is None else str(x)
    if isinstance(x, int):
        return str(x)
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(v):
        return "-"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if v == 0:
        return "0"
    if 1e-3 <= abs(v) < 1e6:
        digits = max(sig - 1 - math.floor(math.log10(abs(v))), 0)
        text = f"{round(v, digits):.{digits}f}"
        return text.rstrip("0").rstrip(".") if "." in text else text
    mantissa, exponent = f"{v:.{sig - 1}e}".split("e")
    mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{mantissa}e{int(exponent)}"


def counted(n: int, word: str) -> str:
    """``n`` and ``word``, plural unless ``n`` is 1: "1 Taguchi iteration", "2 simulations"."""
    return f"{n} {word}" + ("" if n == 1 else "s")


def fmt_levels(values: Sequence[float]) -> list[str]:
    """Format the levels of one factor alike: as few figures as tell them apart (3-6)."""
    labels = [fmt(v, 3) for v in values]
    for sig in range(3, 7):
        labels = [fmt(v, sig) for v in values]
        if len(set(labels)) == len(set(float(v) for v in values)):
            break
    return labels


def fit_text(per_output: Any, units: Any = None) -> str:
    """Return the fit of one experiment in the outputs' units, one clause per output.

    Parameters
    ----------
    per_output : mapping
        Output name -> the :func:`~tsid_fmu.evaluate.cost.metrics` of that output
        (``rmse``, ``nrmse``, ``fit_percent``), as ``result.fit[experiment]`` or
        ``result.validation[experiment]["fit"]`` hold them; an entry that is not a
        mapping (a failed simulation's message) is given as it is.
    units : mapping, optional
        Output name -> unit (``study_units``); an output without one is shown bare.

    Returns
    -------
    str
        ``"RMSE y 0.35 V, NRMSE 0.167, fit 83.3 %"``, the outputs joined by ``"; "``.
    """
    units = units or {}
    parts = []
    for output, m in per_output.items():
        if not isinstance(m, dict):
            parts.append(f"{output}: {m}")
            continue
        unit = units.get(output)
        rmse = f"{fmt(m.get('rmse'), 3)} {unit}" if unit else fmt(m.get("rmse"), 3)
        parts.append(
            f"RMSE {output} {rmse}, NRMSE {fmt(m.get('nrmse'), 3)}, "
            f"fit {fmt(m.get('fit_percent'), 3)} %"
        )
    return "; ".join(parts)


def with_unit(name: str, unit: str | None) -> str:
    """Return an axis label: ``name [unit]``, or the name alone without a unit."""
    return f"{name} [{unit}]" if unit else name


def short_combination(describe: str, terms: int = 2) -> str:
    """Return the first ``terms`` terms of a rotated factor's description, whole.

    ``"+0.71 lg F_vm -0.70 lg B_s +0.05 M_m"`` gives ``"+0.71 lg F_vm -0.70 lg B_s …"``:
    a term is a signed weight and its coordinate (``lg X`` or ``X``), never cut apart.
    """
    found = re.findall(r"[+-]\d+(?:\.\d+)? (?:lg )?\S+", describe)
    if not found:
        return describe
    return " ".join(found[:terms]) + (" …" if len(found) > terms else "")


def axis_formatter() -> Any:
    """Return a tick formatter that writes every tick with :func:`fmt`."""
    from matplotlib.ticker import FuncFormatter

    return FuncFormatter(lambda v, _pos: fmt(v, 4))


def new_figure(width: float, height: float) -> Any:
    """Return an empty figure of ``width`` x ``height`` inches on an Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig


def margins(fig: Any, top: float, bottom: float, **spacing: float) -> None:
    """Lay out ``fig``'s subplots with ``top`` and ``bottom`` margins in inches.

    Titles and axis labels keep the same room whatever the figure's height; ``spacing``
    passes ``left``, ``right``, ``hspace`` and ``wspace`` (fractions) on.
    """
    height = fig.get_figheight()
    fig.subplots_adjust(top=1 - top / height, bottom=bottom / height, **spacing)


def png_bytes(fig: Any, dpi: int = PNG_DPI) -> bytes:
    """Render ``fig`` to PNG bytes (fast zlib level: plots are small either way)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, pil_kwargs={"compress_level": 1})
    return buf.getvalue()


def cost_name(study: Any) -> str:
    """Name the study's cost as a reader needs it: ``SSE, weighted by 1/noise²``."""
    if study is None:
        return "cost"
    method = study.method
    name = str(method.cost).upper()
    weighting = getattr(method, "weighting", None)
    if weighting == "noise":
        return f"{name}, weighted by 1/noise²"
    if weighting and weighting != "none":
        return f"{name}, weighted ({weighting})"
    return name


def input_contribution(stage: Any) -> list[list[Any]]:
    """Rows of the MISO paper's step i in a contribution stage, main contributor first.

    One row per experiment: its name, the inputs acting in it, and its output's RMS and
    range (NaN where not measured); no rows for any other stage.
    """
    found = getattr(stage, "contribution", None)
    inputs = (found.input or {}) if found is not None else {}
    return [
        [
            e,
            ", ".join(inputs["inputs"].get(e, [])),
            inputs["rms"].get(e, math.nan),
            inputs["range"].get(e, math.nan),
        ]
        for e in inputs.get("experiments") or []
    ]
