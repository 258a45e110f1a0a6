"""A study's parameter units against the units the FMU declares.

``unit = "kN/mm"`` on an FMU variable declared in ``N/m`` used to pass as a label, while
the levels went to the FMU as N/m: a value 1e6 times off, silently. :func:`check_units`
compares each parameter's ``unit`` with its variable's declared unit:

- the same unit, written alike or in another notation (``N.s/m``, ``N*s/m``, ``N s m-1``):
  accepted;
- the same dimension with another scale (``kN/mm`` against ``N/m``): refused, naming the
  FMU's unit and the factor, since the levels go to the FMU as they are written;
- another dimension (``kg`` against ``N/m``): refused, naming both;
- a unit either side cannot read (``"rpm"`` against ``"1/min"``...), or an FMU without a
  declared unit: accepted as a label, as before.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

from tsid_fmu.errors import StudyError

__all__ = ["check_units", "parse_unit"]

# base dimensions: m, kg, s, A, K, mol, cd, rad (kept apart so that rad/s is not 1/s)
_BASE = {
    "m": (1.0, (1, 0, 0, 0, 0, 0, 0, 0)),
    "g": (1e-3, (0, 1, 0, 0, 0, 0, 0, 0)),
    "s": (1.0, (0, 0, 1, 0, 0, 0, 0, 0)),
    "A": (1.0, (0, 0, 0, 1, 0, 0, 0, 0)),
    "K": (1.0, (0, 0, 0, 0, 1, 0, 0, 0)),
    "mol": (1.0, (0, 0, 0, 0, 0, 1, 0, 0)),
    "cd": (1.0, (0, 0, 0, 0, 0, 0, 1, 0)),
    "rad": (1.0, (0, 0, 0, 0, 0, 0, 0, 1)),
    "N": (1.0, (1, 1, -2, 0, 0, 0, 0, 0)),
    "Pa": (1.0, (-1, 1, -2, 0, 0, 0, 0, 0)),
    "J": (1.0, (2, 1, -2, 0, 0, 0, 0, 0)),
    "W": (1.0, (2, 1, -3, 0, 0, 0, 0, 0)),
    "V": (1.0, (2, 1, -3, -1, 0, 0, 0, 0)),
    "Ohm": (1.0, (2, 1, -3, -2, 0, 0, 0, 0)),
    "F": (1.0, (-2, -1, 4, 2, 0, 0, 0, 0)),
    "H": (1.0, (2, 1, -2, -2, 0, 0, 0, 0)),
    "C": (1.0, (0, 0, 1, 1, 0, 0, 0, 0)),
    "Hz": (1.0, (0, 0, -1, 0, 0, 0, 0, 0)),
    "bar": (1e5, (-1, 1, -2, 0, 0, 0, 0, 0)),
    "l": (1e-3, (3, 0, 0, 0, 0, 0, 0, 0)),
    "L": (1e-3, (3, 0, 0, 0, 0, 0, 0, 0)),
    "min": (60.0, (0, 0, 1, 0, 0, 0, 0, 0)),
    "h": (3600.0, (0, 0, 1, 0, 0, 0, 0, 0)),
    "deg": (math.pi / 180, (0, 0, 0, 0, 0, 0, 0, 1)),
}
_PREFIX = {
    "Y": 1e24, "Z": 1e21, "E": 1e18, "P": 1e15, "T": 1e12, "G": 1e9, "M": 1e6, "k": 1e3,
    "h": 1e2, "da": 1e1, "d": 1e-1, "c": 1e-2, "m": 1e-3, "u": 1e-6, "µ": 1e-6, "μ": 1e-6,
    "n": 1e-9, "p": 1e-12, "f": 1e-15, "a": 1e-18,
}  # fmt: skip
_FACTOR = re.compile(r"^([A-Za-zµμΩ]+)(?:\^?([-+]?\d+))?$")

Unit = tuple[float, tuple[int, ...]]


def _symbol(text: str) -> Unit | None:
    """Return the scale and dimension of one symbol with an optional prefix (``kN``)."""
    text = "Ohm" if text in ("Ω", "ohm") else text
    if text in _BASE:
        return _BASE[text]
    for prefix, scale in sorted(_PREFIX.items(), key=lambda p: -len(p[0])):
        rest = text[len(prefix) :]
        if text.startswith(prefix) and rest in _BASE:
            base, dims = _BASE[rest]
            return scale * base, dims
    return None


def parse_unit(text: str) -> Unit | None:
    """Return ``(scale to SI, dimension exponents)`` of a unit string, or None if unread.

    Products are written with ``.``, ``*``, ``·`` or a space, one ``/`` divides by what
    follows, exponents follow a symbol (``m2``, ``m^2``, ``s-1``); ``1`` is
    dimensionless.
    """
    text = text.strip()
    if text in ("", "1", "-"):
        return (1.0, (0,) * 8) if text == "1" else None
    num, slash, den = text.partition("/")
    scale, dims = 1.0, [0] * 8
    for part, sign in ((num, 1), (den, -1)) if slash else ((num, 1),):
        factors = [f for f in re.split(r"[.*·\s]+", part.strip("() ")) if f]
        if sign == -1 and not factors:
            return None
        for factor in factors:
            if factor == "1":
                continue
            m = _FACTOR.match(factor)
            if not m:
                return None
            found = _symbol(m[1])
            if found is None:
                return None
            power = sign * int(m[2] or 1)
            scale *= found[0] ** power
            dims = [d + power * e for d, e in zip(dims, found[1], strict=True)]
    return scale, tuple(dims)


def check_units(parameters: Any, declared: Mapping[str, str], fmu: str) -> None:
    """Refuse a parameter whose ``unit`` disagrees with the FMU's declared one.

    Parameters
    ----------
    parameters : iterable of Parameter
        The study's parameters (``name``, ``variable``, ``unit``).
    declared : mapping
        The FMU's declared unit by variable name.
    fmu : str
        The FMU's file name, for the message.

    Raises
    ------
    StudyError
        A unit of the same dimension at another scale, or of another dimension.
    """
    for p in parameters:
        unit = getattr(p, "unit", "") or ""
        variable = getattr(p, "variable", None) or p.name
        theirs = declared.get(variable, "")
        if not unit or not theirs or unit == theirs:
            continue
        ours, fmus = parse_unit(unit), parse_unit(theirs)
        if ours is None or fmus is None:
            continue  # a label tsid cannot read: as before
        if ours[1] != fmus[1]:
            raise StudyError(
                f"parameter {p.name}: unit = {unit!r} is not a unit of {variable}, which "
                f"{fmu} declares in {theirs!r}: give the unit the FMU uses"
            )
        ratio = ours[0] / fmus[0]
        if not math.isclose(ratio, 1.0, rel_tol=1e-9):
            raise StudyError(
                f"parameter {p.name}: unit = {unit!r}, but {fmu} declares {variable} in "
                f"{theirs!r} (1 {unit} = {ratio:g} {theirs}) and takes the levels as they "
                f"are written: give the levels and bounds in {theirs} with unit = "
                f"{theirs!r}"
            )
