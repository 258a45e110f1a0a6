"""Where a construct of a Modelica source file sits: the line numbers build errors name.

pymoca keeps no source positions, so :class:`SourceLines` scans the ``.mo`` text itself
(comments and strings blanked, ``if``/``for``/``when`` blocks and a trailing
``annotation`` skipped) and maps each declaration and equation to its line; where its
count disagrees with pymoca's (an ``extends``), the line is left out rather than guessed.
"""

from __future__ import annotations

import re

__all__ = ["SourceLines", "at_line"]


_BLANK_RE = re.compile(r'"(?:[^"\\]|\\.)*"|//[^\n]*|/\*.*?\*/', re.S)
_SECTION_RE = re.compile(r"^[ \t]*(initial\s+)?(equation|algorithm)\b", re.M)
_PREFIX_RE = re.compile(
    r"^\s*(?:(?:parameter|constant|input|output|discrete|final|flow|stream|inner|outer)\s+)*"
    r"[A-Za-z_][\w.]*\s+(.*)$",
    re.S,
)


def _blank(text: str) -> str:
    """``text`` with comments and strings replaced by spaces (lines and offsets kept)."""
    return _BLANK_RE.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)


def _statements(text: str, start: int, end: int) -> list[tuple[int, str]]:
    """``(offset, text)`` of each ``;``-terminated statement of ``text[start:end]``."""
    out: list[tuple[int, str]] = []
    depth, begin = 0, start
    for i in range(start, end):
        ch = text[i]
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch == ";" and depth <= 0:
            body = text[begin:i]
            stripped = body.lstrip()
            if stripped:
                out.append((begin + len(body) - len(stripped), stripped))
            begin = i + 1
    return out


_BLOCKS = ("if", "for", "when", "while")


def _equation_starts(text: str, start: int, end: int) -> list[int]:
    """Offsets of the equations of an equation section ``text[start:end]``.

    A structured equation (``if``/``for``/``when`` ... ``end if;``) counts once, from its
    keyword; an ``annotation(...);`` is no equation.
    """
    out: list[int] = []
    depth = 0
    for off, stmt in _statements(text, start, end):
        words = re.findall(r"[A-Za-z_]\w*", stmt[:40])
        first = words[0] if words else ""
        if depth == 0 and first != "annotation":
            out.append(off)
        if first in _BLOCKS:
            depth += 1
        elif first == "end" and len(words) > 1 and words[1] in _BLOCKS:
            depth = max(depth - 1, 0)
    return out


class SourceLines:
    """Line numbers of a model's declarations and equations in its Modelica source.

    pymoca keeps no positions, so they are found again in the text: the model's
    ``model Name ... end Name;`` region (the whole text if it is not found), its
    declarations before the first section, and the statements of its ``equation`` and
    ``initial equation`` sections in order. Lookups that do not match give ``None``.

    Parameters
    ----------
    text : str
        The Modelica source.
    short_name : str
        The model's short name.
    """

    def __init__(self, text: str, short_name: str) -> None:
        self.text = _blank(text)
        m = re.search(rf"\bmodel\s+{re.escape(short_name)}\b", self.text)
        lo = m.start() if m else 0
        e = re.search(rf"\bend\s+{re.escape(short_name)}\s*;", self.text[lo:])
        hi = lo + e.start() if e else len(self.text)
        sections = [
            (s.start(), s.end(), bool(s.group(1)), s.group(2))
            for s in _SECTION_RE.finditer(self.text, lo, hi)
        ]
        self.sections: dict[tuple[bool, str], list[int]] = {}
        self.equations: dict[bool, list[int]] = {False: [], True: []}
        for k, (start, head_end, initial, what) in enumerate(sections):
            self.sections.setdefault((initial, what), []).append(self.line(start))
            stop = sections[k + 1][0] if k + 1 < len(sections) else hi
            if what == "equation":
                self.equations[initial] += [
                    self.line(off) for off in _equation_starts(self.text, head_end, stop)
                ]
        decl_end = sections[0][0] if sections else hi
        head = re.match(r"\bmodel\s+\w+\s*", self.text[lo:]) if m else None
        first = lo + (head.end() if head else 0)
        self.declarations: dict[str, int] = {}
        for off, stmt in _statements(self.text, first, decl_end):
            d = _PREFIX_RE.match(stmt)
            if not d:
                continue
            rest, base = d.group(1), off + d.start(1)
            for part_off, part in _split_commas(rest):
                n = re.match(r"\s*([A-Za-z_]\w*)", part)
                if n:
                    self.declarations.setdefault(n.group(1), self.line(base + part_off))

    def line(self, offset: int) -> int:
        """1-based line of a character offset."""
        return self.text.count("\n", 0, offset) + 1

    def declaration(self, name: str) -> int | None:
        """Line of the declaration of ``name``."""
        return self.declarations.get(name)

    def equation(self, index: int, initial: bool = False, count: int | None = None) -> int | None:
        """Line of the ``index``-th (0-based) equation of the (initial) equation sections.

        With ``count`` (the number of equations pymoca found) ``None`` unless the text
        has as many: then the equations were not all written in this model's sections
        (inherited, generated) and their order there is not known.
        """
        eqs = self.equations[initial]
        if count is not None and count != len(eqs):
            return None
        return eqs[index] if 0 <= index < len(eqs) else None

    def section(self, what: str, initial: bool = False) -> int | None:
        """Line of the first ``[initial] equation``/``algorithm`` section header."""
        lines = self.sections.get((initial, what))
        return lines[0] if lines else None


def _split_commas(text: str) -> list[tuple[int, str]]:
    """Top-level comma-separated parts of ``text`` with their offsets."""
    out, depth, begin = [], 0, 0
    for i, ch in enumerate(text):
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append((begin, text[begin:i]))
            begin = i + 1
    out.append((begin, text[begin:]))
    return out


def at_line(where: str, line: int | None) -> str:
    """``where`` followed by ``: line N`` when the line is known."""
    return f"{where}: line {line}" if line else where
