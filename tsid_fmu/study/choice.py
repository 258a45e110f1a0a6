"""Discrete factors: an FMU Integer, Boolean or Enumeration variable with its candidates.

A :class:`Choice` is written in a study's ``[parameters]`` table as::

    friction = { choices = ["coulomb", "stribeck"] }   # Enumeration item names
    damping_on = { choices = [true, false] }            # a Boolean
    n_masses = { choices = [1, 2] }                     # an Integer
    model = { fmus = ["one_mass.fmu", "two_mass.fmu"] } # a choice among FMU files

Its choices are the levels of its column in the orthogonal arrays (never re-leveled
numerically: a choice stays one of the candidates until the structure procedure of
:mod:`tsid_fmu.search.structure.arrays` fixes it). :func:`resolve_choices` checks each against
the FMU's model description and turns the choices into the numbers the FMU is set to
(Booleans 0/1, Enumeration items their declared integer values).

A :class:`ModelChoice` is a choice among FMU files (model variants): its column's levels
are the variants, numbered 0, 1, ... in the order given, and each parameter set is
simulated by the variant its number names, with the parameters that variant has (a
parameter another variant lacks has no effect in it: the structure procedure finds it
not free there). Its name is not an FMU variable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tsid_fmu.errors import FMUError, StudyError

__all__ = ["Choice", "ModelChoice", "resolve_choices"]

_SETTABLE = ("parameter", "structuralParameter")


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int"
    if isinstance(value, float) and math.isfinite(value) and value == round(value):
        return "int"
    if isinstance(value, str):
        return "str"
    return "other"


@dataclass
class Choice:
    """A discrete factor: an FMU Integer/Boolean/Enumeration variable and its candidates.

    Parameters
    ----------
    name : str
        The FMU variable (causality ``parameter``, or an FMI 3 ``structuralParameter``).
    choices : list of int, bool or str
        At least two distinct candidates, all of one kind: integers (an Integer or
        Enumeration variable), ``True``/``False`` (a Boolean), or item names of the
        variable's Enumeration type.

    Attributes
    ----------
    values : list of float
        The number each choice sets the FMU variable to, filled by
        :func:`resolve_choices` (when the study is made); not compared.
    """

    name: str
    choices: list[Any]
    values: list[float] = field(default_factory=list, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or not self.name.isprintable():
            raise StudyError(f"parameter name must be a non-empty printable string: {self.name!r}")
        where = f"parameter {self.name!r}"
        if isinstance(self.choices, str | bytes) or not hasattr(self.choices, "__iter__"):
            raise StudyError(f"{where}: choices must be a list, got {self.choices!r}")
        self.choices = [
            int(c) if _kind(c) == "int" and not isinstance(c, bool) else c for c in self.choices
        ]
        kinds = {_kind(c) for c in self.choices}
        if "other" in kinds or len(kinds) > 1:
            raise StudyError(
                f"{where}: choices must be all integers, all true/false or all Enumeration "
                f"item names, got {self.choices!r}"
            )
        if len(self.choices) < 2:
            raise StudyError(
                f"{where}: needs at least 2 choices (a single one is a fixed value: put it "
                f"in [study] start_values), got {self.choices!r}"
            )
        if len(set(map(repr, self.choices))) != len(self.choices):
            raise StudyError(f"{where}: choices must be distinct, got {self.choices!r}")
        if len(self.choices) > 5:
            raise StudyError(
                f"{where}: at most 5 choices fit an orthogonal array's column, got "
                f"{len(self.choices)}"
            )

    @property
    def labels(self) -> list[str]:
        """The choices as a person reads them (``true``, ``2``, ``stribeck``)."""
        return [label(c) for c in self.choices]

    def label_of(self, value: float) -> str:
        """Return the choice whose number is ``value`` (as :attr:`labels` writes it)."""
        for c, v in zip(self.choices, self.values, strict=False):
            if v == value:
                return label(c)
        return f"{value:g}"


@dataclass
class ModelChoice(Choice):
    """A discrete factor whose candidates are FMU files (model variants).

    Parameters
    ----------
    name : str
        The factor's name (``model``); it must not be a variable of any variant.
    choices : list of str or pathlib.Path
        Two to five distinct ``.fmu`` files, each with the study's inputs and outputs.

    Attributes
    ----------
    values : list of float
        ``0, 1, ...``: the variant's position in ``choices``.
    """

    def __post_init__(self) -> None:
        where = f"parameter {self.name!r}"
        if isinstance(self.choices, str | bytes | Path) or not hasattr(self.choices, "__iter__"):
            raise StudyError(f"{where}: fmus must be a list of FMU files, got {self.choices!r}")
        given = list(self.choices)
        if not all(isinstance(c, str | Path) and str(c) for c in given):
            raise StudyError(f"{where}: fmus must be file names, got {given!r}")
        self.choices = [str(Path(c).resolve()) for c in given]
        # the checks of a Choice (count, distinct, at most 5) on the file names
        Choice.__post_init__(self)
        stems = [Path(c).stem for c in self.choices]
        if len(set(stems)) != len(stems):
            raise StudyError(f"{where}: two FMU files share a name {stems}; rename one")
        self.values = [float(i) for i in range(len(self.choices))]

    @property
    def paths(self) -> list[Path]:
        """The variants' FMU files, in order."""
        return [Path(c) for c in self.choices]

    @property
    def labels(self) -> list[str]:
        """The variants as a person reads them: the FMU files' names without ``.fmu``."""
        return [Path(c).stem for c in self.choices]

    def label_of(self, value: float) -> str:
        """Return the variant whose number is ``value``."""
        i = round(value)
        return self.labels[i] if 0 <= i < len(self.choices) and i == value else f"{value:g}"


def label(choice: Any) -> str:
    """Return a choice as a study file writes it, without quotes."""
    if isinstance(choice, bool):
        return "true" if choice else "false"
    return str(choice)


def _items(info: Any) -> dict[str, int]:
    declared = getattr(info, "declaredType", None)
    return {str(i.name): int(i.value) for i in getattr(declared, "items", None) or []}


def _number(choice: Any, variable: Any, where: str) -> float:
    vtype = variable.type
    if vtype == "Boolean":
        if not isinstance(choice, bool) and choice not in (0, 1):
            raise StudyError(f"{where}: a Boolean takes true or false, got {choice!r}")
        return float(bool(choice))
    if vtype == "Enumeration":
        items = _items(variable)
        if isinstance(choice, str):
            if choice not in items:
                tname = getattr(getattr(variable, "declaredType", None), "name", "")
                raise StudyError(
                    f"{where}: {choice!r} is not an item of its Enumeration type {tname} "
                    f"(items: {', '.join(items) or 'none declared'})"
                )
            return float(items[choice])
        if isinstance(choice, bool) or (items and choice not in items.values()):
            raise StudyError(
                f"{where}: {choice!r} is not a value of its Enumeration type (items: "
                + ", ".join(f"{k} = {v}" for k, v in items.items())
                + ")"
            )
        return float(choice)
    if isinstance(choice, bool | str):
        raise StudyError(f"{where}: an {vtype} variable takes integers, got {choice!r}")
    low, high = _int_range(vtype)
    if not low <= choice <= high:
        raise StudyError(
            f"{where}: {choice!r} does not fit an FMI {vtype} ({low} .. {high}); the FMU "
            "would be set to a wrapped value"
        )
    from tsid_fmu.fmu.variables import variable_info

    info = variable_info(variable)
    if (info.min is not None and choice < info.min) or (info.max is not None and choice > info.max):
        raise StudyError(
            f"{where}: {choice!r} is outside the range the FMU declares "
            f"({'-inf' if info.min is None else f'{info.min:g}'} .. "
            f"{'inf' if info.max is None else f'{info.max:g}'})"
        )
    return float(choice)


def _int_range(vtype: str) -> tuple[int, int]:
    """Return the values an FMI integer type holds (FMI 2's Integer is 32-bit)."""
    bits = {"Integer": 32, "Int8": 8, "Int16": 16, "Int32": 32, "Int64": 64}
    if vtype in bits:
        return -(2 ** (bits[vtype] - 1)), 2 ** (bits[vtype] - 1) - 1
    if vtype.startswith("UInt") and vtype[4:].isdigit():
        return 0, 2 ** int(vtype[4:]) - 1
    return -(2**31), 2**31 - 1


def variables_of(fmus: list[Path]) -> set[str]:
    """Return the names of every variable of any of ``fmus`` (unreadable ones: none)."""
    from tsid_fmu.fmu.info import read_fmu_description

    names: set[str] = set()
    for path in fmus:
        try:
            names.update(v.name for v in read_fmu_description(Path(path)).modelVariables)
        except FMUError:
            continue
    return names


def resolve_choices(fmus: Path | list[Path], choices: list[Choice]) -> None:
    """Check each choice against the FMUs' model descriptions; fill its ``values``.

    ``fmus`` is the study's FMU, or its variants: a choice's variable is read from the
    first variant that has it (whatever their order), and the others lack it.

    Raises
    ------
    StudyError
        No FMU has such a variable, it is a Real (give levels), it cannot be set, or
        a choice is not a value of its type (the message names the parameter).
    """
    models = [c for c in choices if isinstance(c, ModelChoice)]
    choices = [c for c in choices if not isinstance(c, ModelChoice)]
    if len(models) > 1:
        raise StudyError(
            f"parameters {', '.join(repr(m.name) for m in models)}: one choice among FMU "
            "files (fmus = [...]) per study"
        )
    for m in models:
        _check_variants(m)
    if not choices:
        return
    from tsid_fmu.fmu.info import read_fmu_description
    from tsid_fmu.fmu.variables import suggest

    paths = [Path(f) for f in (fmus if isinstance(fmus, list) else [fmus])]
    variables: dict[str, Any] = {}
    for path in reversed(paths):  # the first variant that has a variable gives it
        try:
            md = read_fmu_description(path)
        except FMUError as exc:
            raise StudyError(f"choices need the FMU's model description: {exc}") from None
        variables.update({v.name: v for v in md.modelVariables})
    for c in choices:
        where = f"parameter {c.name!r}"
        v = variables.get(c.name)
        if v is None:
            files = ", ".join(p.name for p in paths)
            who = f"no FMU variant ({files}) has a" if len(paths) > 1 else "the FMU has no"
            raise StudyError(
                f"{where}: {who} variable of that name.{suggest(c.name, list(variables))}"
            )
        if v.type in ("Real", "Float64", "Float32"):
            raise StudyError(
                f"{where} is a Real variable: give it levels = [...] (choices are for "
                "Integer, Boolean and Enumeration variables)"
            )
        if v.type not in ("Boolean", "Enumeration") and not v.type.startswith(("Int", "UInt")):
            raise StudyError(
                f"{where} is of type {v.type}; choices need an Integer, Boolean or "
                "Enumeration variable"
            )
        if v.causality not in _SETTABLE or v.variability == "constant":
            raise StudyError(
                f"{where} has causality {v.causality!r} and variability {v.variability!r}; "
                "only a parameter (or an FMI 3 structural parameter) can be a choice"
            )
        c.values = [_number(x, v, where) for x in c.choices]
        if len(set(c.values)) != len(c.values):
            raise StudyError(f"{where}: two choices set the same value {c.values}")


def _check_variants(model: ModelChoice) -> None:
    """Check that each variant is a readable FMU and that no variant has the name."""
    from tsid_fmu.fmu.info import read_fmu_description

    for path in model.paths:
        where = f"parameter {model.name!r}: {path.name}"
        if not path.is_file():
            raise StudyError(f"{where}: no such file {path}")
        try:
            md = read_fmu_description(path)
        except FMUError as exc:
            raise StudyError(f"{where}: {exc}") from None
        if any(v.name == model.name for v in md.modelVariables):
            raise StudyError(
                f"{where} has a variable named {model.name!r}; name the choice among FMU "
                "files otherwise (it selects the file, it is not set in the FMU)"
            )
