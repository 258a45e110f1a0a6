"""What an FMU's model description says about its variables, and checks of names.

The checks raise :class:`~tsid_fmu.errors.FMUError` naming the FMU, the role the name
was given in (input, output, parameter, start value) and, for an unknown name, the
closest names the model has.
"""

from __future__ import annotations

import difflib
import math
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any
from xml.etree import ElementTree

from tsid_fmu.errors import FMUError
from tsid_fmu.fmu.logs import unescape_xml

__all__ = [
    "BOOL_TYPES",
    "INT_TYPES",
    "REAL_TYPES",
    "VariableInfo",
    "check_fmi_version",
    "choose_interface",
    "find_variable",
    "initial_state",
    "parse_start",
    "read_description",
    "real_reference",
    "restarts_instance",
    "setter_kind",
    "suggest",
    "variable_info",
]

REAL_TYPES = frozenset({"Real", "Float64"})
INT_TYPES = frozenset(
    {"Integer", "Enumeration", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32"}
    | {"Int64", "UInt64"}
)
BOOL_TYPES = frozenset({"Boolean"})


@dataclass(frozen=True)
class VariableInfo:
    """What the session knows about one model variable.

    Attributes
    ----------
    name, value_reference, type, causality, variability, initial, unit, description
        As in ``modelDescription.xml`` (``type`` is FMPy's: ``"Real"``, ``"Float64"``,
        ``"Integer"``, ``"Boolean"``, ...).
    start : str or None
        The start value as written in the model description.
    min, max : float or None
        The bounds the model description declares for the value (on the variable or
        its declared type), or None.
    items : tuple of str
        An Enumeration's item names, in declared order (empty for other types).
    shape : tuple of int
        An FMI 3 array variable's dimensions (``-1`` where a structural parameter sets
        one); empty for a scalar.
    """

    name: str
    value_reference: int
    type: str
    causality: str | None
    variability: str | None
    initial: str | None
    start: str | None
    unit: str | None
    description: str | None
    min: float | None = None
    max: float | None = None
    items: tuple[str, ...] = ()
    shape: tuple[int, ...] = ()


def _declared_unit(variable: Any) -> str | None:
    unit = getattr(variable, "unit", None)
    if unit is None and getattr(variable, "declaredType", None) is not None:
        unit = getattr(variable.declaredType, "unit", None)
    return unit


def _declared_bound(variable: Any, which: str) -> float | None:
    """Return the ``min`` or ``max`` of a variable (else of its declared type), or None."""
    value = getattr(variable, which, None)
    if value is None and getattr(variable, "declaredType", None) is not None:
        value = getattr(variable.declaredType, which, None)
    try:
        bound = float(str(value).split()[0]) if value is not None else None
    except (ValueError, IndexError):
        return None
    return bound if bound is not None and math.isfinite(bound) else None


def variable_info(variable: Any) -> VariableInfo:
    """Return the :class:`VariableInfo` of one of FMPy's ``ScalarVariable`` objects."""
    return VariableInfo(
        name=variable.name,
        value_reference=int(variable.valueReference),
        type=variable.type,
        causality=variable.causality,
        variability=variable.variability,
        initial=variable.initial,
        start=None if variable.start is None else str(variable.start),
        unit=_declared_unit(variable),
        # a tool that escaped its text twice (&amp;gt;) leaves FMPy's reading escaped once
        description=None if variable.description is None else unescape_xml(variable.description),
        min=_declared_bound(variable, "min"),
        max=_declared_bound(variable, "max"),
        items=tuple(
            str(i.name)
            for i in getattr(getattr(variable, "declaredType", None), "items", None) or ()
        ),
        shape=tuple(
            -1 if d.start is None else int(d.start) for d in getattr(variable, "dimensions", ())
        ),
    )


def parse_start(info: VariableInfo) -> float | None:
    """Return the start value as a float (Booleans as 0/1), or None if there is none."""
    if info.start is None:
        return None
    text = info.start.strip()
    if info.type in BOOL_TYPES:
        return 1.0 if text.lower() in ("true", "1") else 0.0
    try:
        return float(text.split()[0])
    except (ValueError, IndexError):
        return None


def suggest(name: str, candidates: Sequence[str]) -> str:
    """Return ``" Did you mean 'a', 'b'?"`` for the closest candidates, or ``""``."""
    close = difflib.get_close_matches(name, candidates, n=3, cutoff=0.6)
    return f" Did you mean {', '.join(repr(c) for c in close)}?" if close else ""


def check_fmi_version(source: str | Path | IO[bytes], fmu: object) -> str:
    """Return the ``fmiVersion`` of a model description if it is 2.0 or 3.x.

    Only the root element is read, before FMPy parses the rest, so that an FMI 1.0
    FMU, or one whose version string is damaged, is named as such (FMPy would fail on
    it with an unrelated ``int()`` or ``NoneType`` error).

    Raises
    ------
    FMUError
        Naming the FMU, the version found and what is supported.
    """
    try:
        root = next(iter(ElementTree.iterparse(source, events=("start",))))[1]
    except (ElementTree.ParseError, StopIteration, OSError, ValueError, EOFError, RuntimeError,
            NotImplementedError, zipfile.BadZipFile, zlib.error) as exc:  # fmt: skip
        raise FMUError(f"{fmu}: cannot read modelDescription.xml ({type(exc).__name__})") from None
    version = root.get("fmiVersion")
    fmi1 = root.get("numberOfContinuousStates") is not None  # an FMI 1.0 attribute
    if version == "2.0" or (version is not None and version.startswith("3.") and not fmi1):
        return version
    supported = "tsid-fmu supports FMI 2.0 and 3.0: export the model as one of these"
    if version is not None and version.strip() == "1.0":
        raise FMUError(f"{fmu}: an FMI 1.0 FMU (fmiVersion '1.0'); {supported}")
    if fmi1:
        raise FMUError(
            f"{fmu}: an FMI 1.0 FMU (it has numberOfContinuousStates) with a damaged "
            f"fmiVersion {version!r}; {supported}"
        )
    if version is None:
        raise FMUError(f"{fmu}: modelDescription.xml has no fmiVersion; {supported}")
    raise FMUError(f"{fmu}: FMI version {version!r} is not supported; {supported}")


def read_description(md_file: Path, fmu: Path) -> Any:
    """Read ``modelDescription.xml`` with FMPy (no schema validation).

    Raises
    ------
    FMUError
        The file is missing or unreadable, or the FMI version is not 2.0 or 3.x.
    """
    from fmpy.model_description import read_model_description

    if not md_file.is_file():
        raise FMUError(f"{fmu}: not a valid FMU, modelDescription.xml is missing")
    check_fmi_version(md_file, fmu)
    try:
        md = read_model_description(str(md_file), validate=False)
    except Exception as exc:  # FMPy raises bare Exception / lxml errors
        raise FMUError(f"{fmu}: cannot read modelDescription.xml: {exc}") from exc
    if not (md.fmiVersion == "2.0" or md.fmiVersion.startswith("3.")):
        raise FMUError(f"{fmu}: FMI version {md.fmiVersion} is not supported (FMI 2.0 and 3.0 are)")
    return md


def find_variable(
    variables: Mapping[str, VariableInfo], fmu: str, name: str, role: str
) -> VariableInfo:
    """Return the variable ``name``; FMUError with suggestions if there is none."""
    info = variables.get(name)
    if info is None:
        raise FMUError(
            f"{fmu}: unknown {role} {name!r}: the model has no "
            f"variable of that name.{suggest(name, list(variables))}"
        )
    return info


def real_reference(
    variables: Mapping[str, VariableInfo],
    fmu: str,
    name: str,
    role: str,
    causality: str | None = None,
) -> int:
    """Return the value reference of a Real variable, checking its causality if given."""
    info = find_variable(variables, fmu, name, role)
    if info.shape:
        dims = " x ".join("?" if n < 0 else str(n) for n in info.shape)
        raise FMUError(
            f"{fmu}: {role} {name!r} is an array variable ({dims} elements); tsid-fmu "
            "compares and sets scalar variables only: give the FMU a scalar output per "
            "measured element"
        )
    if causality is not None and info.causality != causality:
        raise FMUError(
            f"{fmu}: {role} {name!r} has causality {info.causality!r}, not {causality!r}"
        )
    if info.type not in REAL_TYPES:
        raise FMUError(
            f"{fmu}: {role} {name!r} is of type {info.type}, "
            "but a Real (Float64) variable is needed"
        )
    return info.value_reference


def initial_state(info: VariableInfo) -> bool:
    """Whether a variable's start value is an initial state an identification may set.

    A continuous local or output variable with ``initial="exact"`` (a state whose start
    value the FMU uses as its initial value, e.g. Modelica's ``fixed = true``) can be set
    before initialization like a parameter, so its initial value can be identified.
    """
    return (
        info.causality in ("local", "output")
        and info.variability == "continuous"
        and info.initial == "exact"
    )


def setter_kind(
    variables: Mapping[str, VariableInfo], fmu: str, name: str, role: str
) -> tuple[str, int]:
    """Check that ``name`` can be set before initialization.

    Returns
    -------
    kind : {"real", "int", "bool"}
        Which setter to use.
    value_reference : int
    """
    info = find_variable(variables, fmu, name, role)
    if info.variability == "constant":
        raise FMUError(f"{fmu}: {role} {name!r} is a constant and cannot be set")
    # an input without data is held at the value set before initialization: a constant
    # the FMU exposes as an input (OpenModelica's MassSpringSystem: masses, stiffnesses)
    settable = ("parameter", "structuralParameter", "input")
    if role == "parameter" and info.causality not in settable and not initial_state(info):
        hint = (
            " (a calculated parameter is computed by the FMU)"
            if info.causality == "calculatedParameter"
            else ""
        )
        raise FMUError(
            f"{fmu}: parameter {name!r} has causality {info.causality!r}, not 'parameter' "
            f"or 'input', and is no continuous variable with initial 'exact'; it cannot be "
            f"identified{hint}"
        )
    if info.causality == "independent" or (
        info.causality != "input" and info.initial == "calculated"
    ):
        raise FMUError(
            f"{fmu}: {role} {name!r} (causality {info.causality!r}, initial "
            f"{info.initial!r}) cannot be set"
        )
    if info.type in REAL_TYPES:
        return "real", info.value_reference
    if info.type in INT_TYPES:
        return "int", info.value_reference
    if info.type in BOOL_TYPES:
        return "bool", info.value_reference
    raise FMUError(
        f"{fmu}: {role} {name!r} is of type {info.type}; only "
        "Real, Integer and Boolean variables can be set"
    )


def restarts_instance(info: VariableInfo) -> bool:
    """Whether a changed value of this variable gets a fresh instance rather than a reset.

    A discrete (Integer, Boolean, Enumeration) variable with ``variability="fixed"``, or
    an FMI 3 ``structuralParameter``: such switches choose a model's structure, which
    vendors' FMUs often fix when they are instantiated. FMI allows setting ``fixed``
    values again after ``fmi2Reset``/``fmi3Reset``, but an FMU that evaluated them at
    instantiation would silently keep the old structure; a fresh instance honours the
    new value whatever the FMU does (structural parameters are then set in FMI 3's
    Configuration Mode, :meth:`tsid_fmu.fmu.instance.Instance.initialize`). A Real
    ``fixed`` parameter keeps the cheaper reset, as the standard allows.
    """
    discrete = info.type in INT_TYPES or info.type in BOOL_TYPES
    return info.causality == "structuralParameter" or (discrete and info.variability == "fixed")


def choose_interface(md: Any, interface: str, fmu: Path) -> str:
    """Return ``"cs"`` or ``"me"``: the one asked for, or for ``"auto"`` Co-Simulation first.

    Raises
    ------
    FMUError
        The FMU declares no interface, or not the one asked for.
    """
    available = [k for k, d in (("cs", md.coSimulation), ("me", md.modelExchange)) if d]
    if interface == "auto":
        if not available:
            raise FMUError(f"{fmu}: the FMU declares neither Co-Simulation nor Model Exchange")
        return available[0]
    if interface not in available:
        names = {"cs": "Co-Simulation", "me": "Model Exchange"}
        raise FMUError(
            f"{fmu}: interface {interface!r} requested but the FMU only supports "
            + (", ".join(names[a] for a in available) or "no interface")
            + f" (use interface={available[0]!r})" * bool(available)
        )
    return interface
