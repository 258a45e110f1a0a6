"""A small SVG chart writer for the per-iteration figures.

A study can have hundreds of iterations; drawing each one's figures with matplotlib
costs a quarter of a second or more apiece, more than the iteration's simulations. The
per-iteration charts are simple (lines, markers, a dashed reference line, ticks), so
they are written here as SVG text directly: in microseconds, sharp at any zoom, with the
browser's own fonts. Numbers use :func:`tsid_fmu.report.style.fmt`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from xml.sax.saxutils import escape

import numpy as np

from tsid_fmu.report.style import SVG_TICK_PX, fmt

__all__ = ["Canvas", "Panel", "nice_ticks"]

WINDOW_FILL = "#fff3c4"
"""Fill of the time windows a study scores (:meth:`Panel.band`)."""
FONT = 'font-family="DejaVu Sans, Helvetica, Arial, sans-serif"'


def nice_ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """Return about ``n`` round tick values covering ``[lo, hi]`` (steps 1, 2, 2.5, 5 x 10^k)."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return []
    if hi <= lo:
        return [lo]
    raw = (hi - lo) / max(n - 1, 1)
    base = 10.0 ** math.floor(math.log10(raw))  # a float: an int prints every digit
    step = next(m * base for m in (1, 2, 2.5, 5, 10) if m * base >= raw)
    first = math.ceil(lo / step - 1e-9) * step
    ticks, k = [], 0
    while first + k * step <= hi + 1e-9 * step and k < 50:
        ticks.append(float(round(first + k * step, 12)))
        k += 1
    return ticks


def _num(v: float) -> str:
    return f"{v:.1f}"


def _text(
    x: float, y: float, text: str, size: float = 11, anchor: str = "middle", extra: str = ""
) -> str:
    return (
        f'<text x="{_num(x)}" y="{_num(y)}" font-size="{size}" text-anchor="{anchor}"{extra}>'
        f"{escape(text)}</text>"
    )


@dataclass
class Panel:
    """A plotting area at ``(x, y)`` of ``w`` x ``h`` pixels with data limits."""

    x: float
    y: float
    w: float
    h: float
    xlim: tuple[float, float] = (0.0, 1.0)
    ylim: tuple[float, float] = (0.0, 1.0)
    parts: list[str] = field(default_factory=list)

    def sx(self, v: float) -> float:
        """Pixel x of data ``v``."""
        lo, hi = self.xlim
        return self.x + (v - lo) / ((hi - lo) or 1.0) * self.w

    def sy(self, v: float) -> float:
        """Pixel y of data ``v``."""
        lo, hi = self.ylim
        return self.y + self.h - (v - lo) / ((hi - lo) or 1.0) * self.h

    def frame(self, yticks: Sequence[float], labels: bool = True, grid: bool = True) -> None:
        """Draw the box, the y grid and (optionally) the y tick labels."""
        for t in yticks:
            py = self.sy(t)
            if grid:
                self.parts.append(
                    f'<line x1="{_num(self.x)}" x2="{_num(self.x + self.w)}" y1="{_num(py)}" '
                    f'y2="{_num(py)}" stroke="#e3e3e3"/>'
                )
            if labels:
                self.parts.append(_text(self.x - 4, py + 4, fmt(t, 4), SVG_TICK_PX, "end"))
        self.parts.append(
            f'<rect x="{_num(self.x)}" y="{_num(self.y)}" width="{_num(self.w)}" '
            f'height="{_num(self.h)}" fill="none" stroke="#333"/>'
        )

    def xticks(self, values: Sequence[float], labels: Sequence[str], rotate: bool = False) -> None:
        """Draw x tick marks and labels under the panel."""
        base = self.y + self.h
        for v, label in zip(values, labels, strict=True):
            px = self.sx(v)
            self.parts.append(
                f'<line x1="{_num(px)}" x2="{_num(px)}" y1="{_num(base)}" y2="{_num(base + 4)}" '
                'stroke="#333"/>'
            )
            if rotate:
                extra = f' transform="rotate(-30 {_num(px)} {_num(base + 15)})"'
                self.parts.append(_text(px, base + 15, label, SVG_TICK_PX, "end", extra))
            else:
                self.parts.append(_text(px, base + 17, label, SVG_TICK_PX))

    def line(
        self,
        xs: Sequence[float],
        ys: Sequence[float],
        color: str,
        width: float = 1.5,
        dash: str = "",
    ) -> None:
        """Draw a polyline through the finite points (gaps where a value is not finite)."""
        x = np.asarray(xs, dtype=float)
        y = np.asarray(ys, dtype=float)
        (xlo, xhi), (ylo, yhi) = self.xlim, self.ylim
        px = self.x + (x - xlo) / ((xhi - xlo) or 1.0) * self.w
        py = self.y + self.h - (y - ylo) / ((yhi - ylo) or 1.0) * self.h
        ok = np.isfinite(px) & np.isfinite(py)
        style = f' stroke-dasharray="{dash}"' if dash else ""
        edges = np.flatnonzero(np.diff(np.concatenate([[False], ok, [False]]).astype(int)))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            pts = " ".join(
                f"{a:.1f},{b:.1f}"
                for a, b in zip(px[start:stop].tolist(), py[start:stop].tolist(), strict=True)
            )
            self.parts.append(
                f'<polyline points="{pts}" fill="none" stroke="{color}" '
                f'stroke-width="{width}"{style}/>'
            )

    def markers(
        self, xs: Sequence[float], ys: Sequence[float], color: str, shape: str = "circle"
    ) -> None:
        """Draw filled circles or open squares at the finite points."""
        for a, b in zip(xs, ys, strict=True):
            if not (math.isfinite(a) and math.isfinite(b)):
                continue
            px, py = self.sx(a), self.sy(b)
            if shape == "circle":
                self.parts.append(
                    f'<circle cx="{_num(px)}" cy="{_num(py)}" r="3.2" fill="{color}"/>'
                )
            else:
                self.parts.append(
                    f'<rect x="{_num(px - 7)}" y="{_num(py - 7)}" width="14" height="14" '
                    f'fill="none" stroke="{color}" stroke-width="2"/>'
                )

    def band(self, x0: float, x1: float, color: str = WINDOW_FILL) -> None:
        """Shade the panel's full height from data ``x0`` to ``x1`` (a scored window)."""
        left, right = self.sx(x0), self.sx(x1)
        self.parts.append(
            f'<rect class="window" x="{_num(left)}" y="{_num(self.y)}" '
            f'width="{_num(max(right - left, 0.5))}" height="{_num(self.h)}" fill="{color}"/>'
        )

    def title(self, lines: Sequence[str], size: float = 11) -> None:
        """Write title lines above the panel (the last line just above the box)."""
        for k, text in enumerate(reversed(lines)):
            self.parts.append(_text(self.x + self.w / 2, self.y - 6 - k * 13, text, size))

    def label(self, text: str, size: float = 10) -> None:
        """Write a note in the upper left corner inside the panel."""
        self.parts.append(_text(self.x + 5, self.y + 13, text, size, "start"))


@dataclass
class Canvas:
    """An SVG document of ``width`` x ``height`` pixels made of panels and free text."""

    width: float
    height: float
    parts: list[str] = field(default_factory=list)

    def text(self, x: float, y: float, text: str, size: float = 11, anchor: str = "middle",
             rotate: bool = False) -> None:  # fmt: skip
        """Write text; ``rotate`` turns it to run upwards (a y-axis label)."""
        extra = f' transform="rotate(-90 {_num(x)} {_num(y)})"' if rotate else ""
        self.parts.append(_text(x, y, text, size, anchor, extra))

    def legend(self, x: float, y: float, items: Sequence[tuple[str, str, str]]) -> None:
        """Write a one-line legend of ``(kind, color, label)``: kind line, dash, circle, square."""
        for kind, color, label in items:
            if kind in ("line", "dash"):
                dash = ' stroke-dasharray="5,3"' if kind == "dash" else ""
                self.parts.append(
                    f'<line x1="{_num(x)}" x2="{_num(x + 22)}" y1="{_num(y - 4)}" '
                    f'y2="{_num(y - 4)}" stroke="{color}" stroke-width="1.8"{dash}/>'
                )
            elif kind == "circle":
                self.parts.append(
                    f'<line x1="{_num(x)}" x2="{_num(x + 22)}" y1="{_num(y - 4)}" '
                    f'y2="{_num(y - 4)}" stroke="{color}" stroke-width="1.5"/>'
                    f'<circle cx="{_num(x + 11)}" cy="{_num(y - 4)}" r="3.2" fill="{color}"/>'
                )
            else:
                self.parts.append(
                    f'<rect x="{_num(x + 4)}" y="{_num(y - 11)}" width="14" height="14" '
                    f'fill="none" stroke="{color}" stroke-width="2"/>'
                )
            self.parts.append(_text(x + 27, y, label, 10.5, "start"))
            x += 27 + 6.2 * len(label) + 18

    def svg(self, panels: Sequence[Panel] = ()) -> str:
        """Return the SVG document."""
        body = "".join(self.parts) + "".join(p for panel in panels for p in panel.parts)
        return (
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{_num(self.width)}" '
            f'height="{_num(self.height)}" viewBox="0 0 {_num(self.width)} {_num(self.height)}" '
            f'{FONT}><rect width="100%" height="100%" fill="white"/>{body}</svg>\n'
        )
