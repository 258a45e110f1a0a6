"""``next_levels.toml``: the levels proposed for the next iteration, which a person may edit.

For parameters (axis-aligned factors) the file holds a ``[levels]`` table of parameter
values. For rotated factors it holds the ``[centre]`` (parameter values) and one
``[[factors]]`` table per factor: its ``direction`` in search coordinates and its level
``offsets`` along it. A person may replace either form by a ``[levels]`` table of
parameter values; the next iteration then runs those exact levels.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.errors import StudyError
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi.frame import Factor, Frame
from tsid_fmu.study.checks import parse_toml
from tsid_fmu.study.tomltext import toml_key, toml_string

__all__ = ["read_next_levels", "write_next_levels"]


def _fmt(values: Any) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def _comment(text: str) -> str:
    """``text`` on one line, fit for a TOML comment (a name may hold a line break)."""
    return " ".join(str(text).split()).translate({c: "?" for c in [*range(32), 127]})


def write_next_levels(
    path: Path, record: IterationRecord, space: Space, frame: Frame, note: str
) -> str:
    """Return the text of ``next_levels.toml`` for ``frame`` (proposed after ``record``)."""
    head = (
        f"# Levels for iteration {record.index + 1} of {record.stage}: {_comment(note)}.\n"
        "# Edit them if your judgement differs (a [levels] table of parameter values may\n"
        "# replace everything below), then continue with: tsid identify STUDY --out DIR --resume\n"
    )
    reasons = {d.name: f"{d.case}: {d.reason}" for d in record.decision.parameters}
    if frame.axis_aligned:
        body = "[levels]\n" + "".join(
            f"{toml_key(f.name)} = {_fmt(f.values)}"
            + (f"  # {_comment(reasons[f.name])}" if f.name in reasons else "")
            + "\n"
            for f in frame.factors
        )
        return head + body
    centre = frame.coords(space).to_x(frame.centre)
    body = "[centre]\n" + "".join(f"{toml_key(n)} = {float(centre[n])!r}\n" for n in space.names)
    for f in frame.factors:
        direction = ", ".join(
            f"{toml_key(n)} = {float(c)!r}" for n, c in zip(space.names, f.direction, strict=True)
        )
        body += (
            f"\n[[factors]]  # {_comment(frame.describe(space, f))}\nname = {toml_string(f.name)}\n"
            f"direction = {{ {direction} }}\noffsets = {_fmt(f.offsets)}\n"
        )
    return (
        head
        + (
            "# Rotated factors: directions in coordinates (value - centre) / scale, where a\n"
            "# parameter's scale is its change per unit at the centre (see the report).\n"
        )
        + body
    )


def _numbers(path: Path, name: str, values: Any) -> list[float]:
    if not isinstance(values, list) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in values
    ):
        raise StudyError(f"{path}: {name} must be a list of numbers, got {values!r}")
    out = sorted(float(v) for v in values)
    if len(out) < 2 or len(set(out)) != len(out) or not all(map(math.isfinite, out)):
        raise StudyError(f"{path}: {name} needs at least 2 distinct finite levels, got {out}")
    return out


def _number(path: Path, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise StudyError(f"{path}: {name} must be a finite number, got {value!r}")
    return float(value)


def _levels_frame(path: Path, table: dict, space: Space) -> Frame:
    unknown = sorted(set(table) - set(space.names))
    missing = sorted(set(space.names) - set(table))
    if unknown or missing:
        raise StudyError(
            f"{path}: [levels] must list exactly the parameters {list(space.names)}; "
            f"unknown {unknown}, missing {missing}"
        )
    levels = {}
    for n in space.names:
        vals = _numbers(path, n, table[n])
        lo, hi = space.bounds[n]
        if vals[0] < lo or vals[-1] > hi:
            raise StudyError(f"{path}: {n} levels {vals} leave the bounds [{lo}, {hi}]")
        levels[n] = vals
    return Frame.from_levels(space, levels)


def _unit(d: np.ndarray) -> np.ndarray:
    """Return ``d`` scaled to length 1; a direction of length 1 already is kept as written.

    Dividing a unit vector by its computed norm changes the last bit of about a third
    of them, so a resumed study ran other levels than the uninterrupted one (issue 25).
    """
    norm = float(np.linalg.norm(d))
    return d if abs(norm - 1.0) <= 8 * np.finfo(float).eps else d / norm


def _rotated_frame(path: Path, doc: dict, space: Space) -> Frame:
    centre, factors = doc.get("centre"), doc.get("factors")
    if not isinstance(centre, dict) or not isinstance(factors, list) or not factors:
        raise StudyError(f"{path}: needs a [levels] table, or [centre] and [[factors]]")
    x = {n: _number(path, f"centre {n}", centre.get(n)) for n in space.names}
    out = []
    for i, f in enumerate(factors):
        if not isinstance(f, dict) or not isinstance(f.get("direction"), dict):
            raise StudyError(f"{path}: [[factors]] #{i + 1} needs name, direction and offsets")
        where = f"[[factors]] #{i + 1} direction {{}}"
        d = np.array(
            [_number(path, where.format(n), f["direction"].get(n, 0.0)) for n in space.names]
        )
        if not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
            raise StudyError(f"{path}: [[factors]] #{i + 1} direction must be finite, not zero")
        offsets = _numbers(path, f"[[factors]] #{i + 1} offsets", f.get("offsets"))
        out.append(Factor(str(f.get("name", f"A{i + 1}")), _unit(d), np.asarray(offsets)))
    if len(out) != space.dim:
        raise StudyError(f"{path}: needs {space.dim} [[factors]], got {len(out)}")
    return Frame(centre=np.zeros(space.dim), factors=out, anchor=x)


def read_next_levels(path: Path, space: Space) -> Frame:
    """Read ``next_levels.toml`` (as a person may have edited it) into a frame.

    Raises
    ------
    StudyError
        Not valid TOML, a parameter missing or unknown, levels outside the bounds,
        malformed factors; the message names the file.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(f"{path}: cannot read ({type(exc).__name__})") from None
    doc = parse_toml(text, str(path))
    if isinstance(doc.get("levels"), dict):
        return _levels_frame(path, doc["levels"], space)
    return _rotated_frame(path, doc, space)
