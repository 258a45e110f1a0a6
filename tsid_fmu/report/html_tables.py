"""HTML building blocks of the reports: escaped tables, embedded images, the style sheet.

Everything is plain HTML and CSS (no script, no external resource), so a report opens
from disk in any browser, offline.
"""

from __future__ import annotations

import base64
import html
import struct
from collections.abc import Sequence
from typing import Any

from tsid_fmu.report.style import fmt

__all__ = ["CSS", "esc", "image", "png_size", "table", "table_from_frame"]

CSS = """
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; margin: 0 auto;
       max-width: 1180px; padding: 0 18px 40px; color: #1d1d1f; }
h1 { font-size: 22px; margin: 18px 0 6px; }
h2 { font-size: 18px; border-bottom: 1px solid #ccc; padding-bottom: 3px; margin-top: 30px; }
h3 { font-size: 15px; margin: 18px 0 6px; }
h4 { font-size: 14px; margin: 14px 0 4px; }
table { border-collapse: collapse; margin: 6px 0 10px; font-size: 12.5px; }
th, td { border: 1px solid #d5d5d5; padding: 2px 7px; text-align: right; vertical-align: top; }
th { background: #f2f2f4; font-weight: 600; }
td.text, th.text { text-align: left; }
td.text { max-width: 34em; overflow-wrap: anywhere; }  /* long reasons wrap, not the page */
tr.pooled td { color: #777; font-style: italic; }
tr.total td { font-weight: 600; }
tr.failed td { background: #fff0f0; }
.note { color: #555; font-size: 12.5px; max-width: 980px; }
.headline { font-size: 16px; padding: 6px 10px; border-radius: 4px; display: inline-block; }
.verdict-good { background: #e6f4ea; } .verdict-caution { background: #fff4e0; }
.verdict-bad { background: #fde8e8; } .verdict-paused { background: #e8f0fe; }
.warn { background: #fff4e0; padding: 4px 10px; margin: 4px 0; border-left: 3px solid #f0a030; }
details { margin: 6px 0; border: 1px solid #e2e2e2; border-radius: 4px; padding: 2px 10px; }
summary { cursor: pointer; font-weight: 600; padding: 3px 0; }
img { max-width: 100%; height: auto; display: block; margin: 6px 0; }
.scroll { overflow-x: auto; }
code { background: #f4f4f4; padding: 0 3px; border-radius: 3px; }
"""
"""The style sheet of ``report.html``."""


def esc(text: Any) -> str:
    r"""Return ``text`` escaped for HTML, its control characters written as escapes.

    Messages quote what an FMU printed: a raw ESC, BEL or NUL (``\x1b]0;x\x07``) is
    shown as its Python escape, as ``report.md`` shows it; line breaks and tabs stay.
    """
    text = "".join(c if c.isprintable() or c in "\n\t" else repr(c)[1:-1] for c in str(text))
    return html.escape(text, quote=True)


def _cell(v: Any, tag: str = "td") -> str:
    if isinstance(v, str):
        return f'<{tag} class="text">{esc(v)}</{tag}>'
    return f"<{tag}>{esc(fmt(v))}</{tag}>"


def _text_columns(n: int, rows: Sequence[Sequence[Any]]) -> list[bool]:
    """Return per column whether its cells are mostly text (left-aligned, as its header).

    The first column (the rows' names) is always text; a column with no cells counts as
    numbers.
    """
    out = [True] + [False] * max(n - 1, 0)
    for i in range(1, n):
        cells = [row[i] for row in rows if i < len(row)]
        out[i] = 2 * sum(isinstance(v, str) for v in cells) > len(cells)
    return out[:n]


def table(
    columns: Sequence[str],
    rows: Sequence[Sequence[Any]],
    caption: str | None = None,
    row_classes: Sequence[str] | None = None,
    css_class: str = "",
) -> str:
    """Return an HTML table; numbers to 5 significant figures, text escaped.

    The first column is a header cell of each row (the row's name).
    """
    text = _text_columns(len(columns), rows)
    head = "".join(
        f'<th class="text">{esc(c)}</th>' if text[i] else f"<th>{esc(c)}</th>"
        for i, c in enumerate(columns)
    )
    body = []
    for k, row in enumerate(rows):
        cls = f' class="{esc(row_classes[k])}"' if row_classes and row_classes[k] else ""
        cells = "".join(_cell(v, "th" if i == 0 else "td") for i, v in enumerate(row))
        body.append(f"<tr{cls}>{cells}</tr>")
    cap = f"<caption>{esc(caption)}</caption>" if caption else ""
    klass = f' class="{esc(css_class)}"' if css_class else ""
    return (
        f'<div class="scroll"><table{klass}>{cap}<thead><tr>{head}</tr></thead>'
        f"<tbody>{''.join(body)}</tbody></table></div>"
    )


def table_from_frame(frame: Any, caption: str | None = None) -> str:
    """Return a :class:`pandas.DataFrame` as an HTML table (its index as first column)."""
    columns = [str(frame.index.name or ""), *[str(c) for c in frame.columns]]
    rows = [
        [idx, *list(row)]
        for idx, row in zip(frame.index, frame.itertuples(index=False), strict=True)
    ]
    return table(columns, rows, caption)


def png_size(data: bytes) -> tuple[int, int]:
    """Return ``(width, height)`` in pixels of PNG ``data`` (0, 0 if it is no PNG)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or len(data) < 24:
        return 0, 0
    return struct.unpack(">II", data[16:24])


def image(data: bytes, alt: str, scale: int = 2) -> str:
    """Return an ``<img>`` with the image embedded.

    A PNG is shown at 1/``scale`` of its pixels (drawn at 2x for sharp screens); an SVG
    at its own size.
    """
    width, _ = png_size(data)
    size = f' width="{width // scale}"' if width else ""
    kind = "png" if width else "svg+xml"
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img alt="{esc(alt)}"{size} src="data:image/{kind};base64,{b64}">'
