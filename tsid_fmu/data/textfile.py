"""The first line of a text data file, read with bounds before pandas reads the rest.

A study may name any file as its data, and three kinds of file misled the reader:

* files that are not regular files (``/dev/zero``, ``/dev/urandom``, a named pipe):
  reading them never ends, so they are refused before a byte is read
  (:func:`check_regular`);
* a file without a line break (a binary blob, a gigabyte on one line): only
  :data:`HEAD_BYTES` are read while looking for the header (:func:`read_head`);
* a file that is not a table, such as a secrets file ``API_KEY="sk-live-..."`` or
  ``/etc/os-release``: pandas' delimiter sniffer takes ``=`` for the delimiter and the
  secret for a column name. The delimiter is sniffed here among :data:`DELIMITERS`
  only, and a frame none of whose first rows holds a number has its column names
  hidden (:func:`hide_names_unless_table`), so no message quotes them.

The header is also checked for repeated names (pandas renames the second ``F_m`` to
``F_m.1``, and a study would silently use the first one): :func:`check_duplicates`.
"""

from __future__ import annotations

import csv
import os
import re
import stat
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tsid_fmu.data.names import header_like, safe_names
from tsid_fmu.errors import DataError

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "DELIMITERS",
    "HEAD_BYTES",
    "check_duplicates",
    "check_regular",
    "header_fields",
    "hide_names_unless_table",
    "read_head",
    "sniff_decimal",
    "sniff_delimiter",
]

HEAD_BYTES = 1 << 20
"""Most bytes read while looking for the header line (1 MiB)."""

DELIMITERS = ",;\t| "
"""The delimiters a data file may use (the sniffer picks among these only)."""

TABLE_ROWS = 20
"""Rows looked at to decide whether a file is a table of numbers."""


def check_regular(path: Path) -> None:
    """Refuse a path that is not a regular file (a device, a pipe, a folder, a socket).

    Raises
    ------
    DataError
        Naming the path and what it is.
    """
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise DataError(f"data file not found: {path}") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read the file: {exc.strerror}") from None
    if stat.S_ISREG(mode):
        return
    kind = (
        "a folder"
        if stat.S_ISDIR(mode)
        else "a device"
        if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
        else "a named pipe"
        if stat.S_ISFIFO(mode)
        else "not a regular file"
    )
    raise DataError(f"{path}: not a file ({kind}); give a data file such as a CSV")


def read_head(path: Path, encoding: str = "utf-8-sig") -> str:
    """Return the first non-blank line of a text file, reading at most :data:`HEAD_BYTES`.

    A UTF-8 byte order mark (as Excel writes it) is dropped.

    Raises
    ------
    DataError
        No line break in the first :data:`HEAD_BYTES` of a longer file, no non-blank
        line, or the line is not text in ``encoding``.
    """
    with open(path, "rb") as fh:
        head = fh.read(HEAD_BYTES + 1)
    complete = len(head) <= HEAD_BYTES
    head = head[:HEAD_BYTES]
    lines = re.split(rb"\r\n|\r|\n", head)
    if not complete:
        lines = lines[:-1]  # the last one may be cut off
    line = next((x for x in lines if x.strip()), None)
    if line is None:
        if complete:
            raise DataError(f"{path}: the file is empty (blank lines only)")
        raise DataError(
            f"{path}: no header line in its first {HEAD_BYTES} bytes: not a table of measured data"
        )
    try:
        return line.decode(encoding)
    except (UnicodeDecodeError, LookupError) as exc:
        where = f" (byte {exc.start + 1})" if isinstance(exc, UnicodeDecodeError) else ""
        raise DataError(f"{path}: cannot read the file: not {encoding} text{where}") from None


def sniff_delimiter(line: str) -> str:
    """Return the delimiter of a header line among :data:`DELIMITERS` (``,`` if none)."""
    try:
        return csv.Sniffer().sniff(line, delimiters=DELIMITERS).delimiter
    except csv.Error:  # one column, or no usual delimiter: then not split at all
        return ","


_COMMA_NUMBER = re.compile(r"\s*[+-]?\d*,\d+(?:[eE][+-]?\d+)?\s*")
_POINT_NUMBER = re.compile(r"\s*[+-]?(?:\d+\.\d*|\.\d+)(?:[eE][+-]?\d+)?\s*")


def sniff_decimal(path: Path, sep: str, encoding: str = "utf-8-sig") -> str:
    """Return ``","`` if the rows below the header write decimal commas, else ``"."``.

    A European spreadsheet writes ``0,25;1,5``: with ``;`` as the delimiter (never
    ``,``), the first :data:`TABLE_ROWS` rows of the first :data:`HEAD_BYTES` are
    looked at, and decimal commas are taken where some cell is a number with a comma
    (``0,25``, ``-1,5e-3``) and none one with a point.
    """
    if sep == "," or len(sep) != 1:
        return "."
    with open(path, "rb") as fh:
        head = fh.read(HEAD_BYTES)
    text = head.decode(encoding, errors="replace")
    rows = [x for x in re.split(r"\r\n|\r|\n", text) if x.strip()][1 : TABLE_ROWS + 1]
    cells = [c for row in rows for c in row.split(sep)]
    comma = any(_COMMA_NUMBER.fullmatch(c) for c in cells)
    point = any(_POINT_NUMBER.fullmatch(c) for c in cells)
    return "," if comma and not point else "."


def header_fields(line: str, sep: str) -> list[str]:
    """Split a header line as the reader will (``sep`` one character or a regex)."""
    if len(sep) == 1:
        try:
            return next(csv.reader([line], delimiter=sep), [])
        except csv.Error:
            return []
    return re.split(sep, line.strip())


def check_duplicates(names: Sequence[object], source: str) -> None:
    """Refuse a header that names a column twice, naming both positions.

    Names are compared as the data's columns are (surrounding spaces stripped); the
    name is quoted only if the header looks like one (:mod:`tsid_fmu.data.names`).

    Raises
    ------
    DataError
        ``columns 2 and 5 are both named 'F_m'``.
    """
    seen: dict[str, int] = {}
    stripped = [str(n).strip(" ") for n in names]
    for i, name in enumerate(stripped):
        if name in seen:
            what = f"named {name!r}" if safe_names(stripped) else "named alike"
            raise DataError(
                f"{source}: columns {seen[name] + 1} and {i + 1} are both {what}; "
                "each column needs its own name"
            )
        seen[name] = i


def _numeric_cell(value: Any) -> bool:
    if isinstance(value, int | float):
        return True
    try:
        float(str(value).strip())
    except ValueError:
        return False
    return True


def hide_names_unless_table(frame: pd.DataFrame) -> pd.DataFrame:
    """Rename the columns to ``#1, #2, ...`` if the frame does not look like a table.

    A table of measured data holds numbers: if none of its first :data:`TABLE_ROWS`
    rows has a numeric cell (while some cell is filled in), the file is something else
    and its first line is no header, whatever it looks like. Names that would not be
    shown anyway are left alone.
    """
    if not any(header_like(c) for c in frame.columns):
        return frame
    head = frame.head(TABLE_ROWS)
    cells = [v for v in head.to_numpy().ravel().tolist() if not _blank(v)]
    if not cells or any(_numeric_cell(v) for v in cells):
        return frame
    out = frame.copy()
    out.columns = [f"#{i + 1}" for i in range(frame.shape[1])]
    return out


def _blank(value: Any) -> bool:
    if value is None:
        return True
    if isinstance(value, float):
        return value != value  # NaN: an empty cell
    return not str(value).strip()
