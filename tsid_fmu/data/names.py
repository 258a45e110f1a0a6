"""Column names in messages: a data file's first line is shown only if it is a header.

A study may point ``file`` at any file, e.g. ``/etc/passwd`` or a colleague's private
notes, and the message of a failed load must not show what that file holds. A data
file's "column names" are its first line, so they are named in a message only when
*every* one of them looks like a header written by a person or a logger: printable,
short, starting with a letter or ``_`` and made of letters, digits and the usual unit
and index punctuation (``x_m``, ``F_of``, ``Time (s)``, ``u[1]``). Otherwise columns
are named by their position (``column 3``), and lists of columns are left out.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

__all__ = ["MAX_NAME_LENGTH", "column_label", "describe_columns", "header_like", "safe_names"]

MAX_NAME_LENGTH = 64
"""Longest column name shown in a message."""

_PUNCTUATION = frozenset(" _.-+:/%()[]{}#*^'°µ")


def header_like(name: object) -> bool:
    """Return True if ``name`` looks like a column header a person would write."""
    if not isinstance(name, str) or not 0 < len(name) <= MAX_NAME_LENGTH:
        return False
    if not name.isprintable() or not (name[0].isalpha() or name[0] == "_"):
        return False
    return all(c.isalnum() or c in _PUNCTUATION for c in name)


def safe_names(names: Iterable[object]) -> bool:
    """Return True if every name looks like a header (so the names may be listed)."""
    names = list(names)
    return bool(names) and all(header_like(n) for n in names)


def column_label(name: object, names: Sequence[object]) -> str:
    """Return ``"column 'x'"``, or ``"column 3"`` when the names are not a header."""
    if safe_names(names):
        return f"column {name!r}"
    position = next((i for i, n in enumerate(names) if n == name), None)
    return f"column {position + 1}" if position is not None else "a column"


def describe_columns(names: Sequence[object]) -> str:
    """Return ``"columns are a, b, c"``, or a sentence that does not quote the file."""
    if safe_names(names):
        return "columns are " + ", ".join(str(n) for n in names)
    return (
        f"the file has {len(names)} column(s), but its first line does not look like a "
        "header of column names, so they are not shown"
    )
