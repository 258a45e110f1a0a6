r"""TOML text for keys and strings that tsid writes by hand (the trail, ``tsid init``).

FMI names are free text: OpenModelica writes ``mass.m``, ``ampl[0]``, ``der(x)``, and
Modelica's quoted identifiers allow spaces, quotes and ``#``. As a bare TOML key
``mass.m`` reads back as a nested table, and the others are not TOML at all. Every key
tsid writes goes through :func:`toml_key`: bare where TOML's bare-key grammar allows,
else a basic string with TOML's own escapes (a name round-trips exactly, whatever
characters it holds).

Examples
--------
>>> toml_key("K_s"), toml_key("mass.m"), toml_key('a "b"')
('K_s', '"mass.m"', '"a \\"b\\""')
"""

from __future__ import annotations

import re

__all__ = ["comment_text", "toml_key", "toml_string"]

_BARE = re.compile(r"[A-Za-z0-9_-]+")
_ESCAPES = {
    '"': '\\"',
    "\\": "\\\\",
    "\b": "\\b",
    "\t": "\\t",
    "\n": "\\n",
    "\f": "\\f",
    "\r": "\\r",
}


def toml_string(text: str) -> str:
    r"""Return ``text`` as a TOML basic string (quoted, with TOML's escapes).

    Control characters (U+0000-U+001F, U+007F) are escaped as ``\uXXXX``; every other
    character, non-ASCII included, is written as it is (TOML files are UTF-8).
    """
    out = []
    for ch in str(text):
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def toml_key(name: str) -> str:
    """Return ``name`` as a TOML key: bare if TOML allows it, else quoted."""
    return name if _BARE.fullmatch(name) else toml_string(name)


_COMMENT_ESCAPES = {"\t": "\\t", "\n": "\\n", "\r": "\\r"}


def comment_text(text: str) -> str:
    r"""Return ``text`` fit for a TOML comment: one line, no control characters.

    Free text that tsid copies into a ``#`` comment (an FMU variable's description, a
    name, a data column) must not end the comment: a newline in it would start a line
    of TOML. Tab, newline and carriage return are written ``\t``, ``\n``, ``\r``;
    every other C0 or C1 control character, DEL and the line and paragraph separators
    U+2028 and U+2029 as ``\uXXXX`` (TOML forbids control characters in comments).

    Examples
    --------
    >>> comment_text("x\n[design]")
    'x\\n[design]'
    """
    out = []
    for ch in str(text):
        code = ord(ch)
        if ch in _COMMENT_ESCAPES:
            out.append(_COMMENT_ESCAPES[ch])
        elif code < 0x20 or 0x7F <= code <= 0x9F or code in (0x2028, 0x2029):
            out.append(f"\\u{code:04X}")
        else:
            out.append(ch)
    return "".join(out)
