"""Generate ``modelDescription.xml`` (FMI 2.0) from the Modelica declarations."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from typing import Any

from .causalize import Causalized, Layout
from .modelica import FlatModel, import_build_deps

__all__ = [
    "FIXED_STEP_NAME",
    "add_unit_definitions",
    "dependency_vrs",
    "der_unit",
    "description_root",
    "fmt",
    "initial_unknowns",
    "model_description_xml",
    "unit_base",
    "xml_document",
]

FIXED_STEP_NAME = "fixedStepSize"
TYPE_KEY = "_type"  # in variable_rows' type attributes: an Integer parameter's FMI type

# SI base-unit exponents (kg, m, s, A, K, mol, cd, rad) of the unit symbols we know.
_BASE: dict[str, dict[str, int]] = {
    "1": {},
    "kg": {"kg": 1},
    "g": {"kg": 1},  # factor handled below
    "m": {"m": 1},
    "s": {"s": 1},
    "A": {"A": 1},
    "K": {"K": 1},
    "mol": {"mol": 1},
    "cd": {"cd": 1},
    "rad": {"rad": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "Hz": {"s": -1},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
}
_FACTOR = {"g": 1e-3}


def unit_base(unit: str) -> tuple[dict[str, int], float] | None:
    """Base-unit exponents and factor of a Modelica unit string such as ``"N.s/m"``.

    Parameters
    ----------
    unit : str
        Unit string in Modelica syntax (``.`` multiplies, ``/`` divides, trailing
        integers are exponents: ``"m/s2"``).

    Returns
    -------
    tuple of (dict, float) or None
        Exponents by base unit and the factor, or ``None`` if a symbol is unknown.
    """
    exps: dict[str, int] = {}
    factor = 1.0
    parts = unit.split("/")
    for k, part in enumerate(parts):
        sign = 1 if k == 0 else -1
        for sym in part.split("."):
            sym = sym.strip("()")
            if not sym:
                continue
            m = re.fullmatch(r"([A-Za-z]+|1)(-?\d+)?", sym)
            if not m or m.group(1) not in _BASE:
                return None
            power = int(m.group(2) or 1) * sign
            for b, e in _BASE[m.group(1)].items():
                exps[b] = exps.get(b, 0) + e * power
            factor *= _FACTOR.get(m.group(1), 1.0) ** power
    return {b: e for b, e in exps.items() if e}, factor


def der_unit(unit: str) -> str | None:
    """Return the unit of the time derivative of a variable (``"m/s"`` -> ``"m/s2"``).

    Parameters
    ----------
    unit : str
        Unit of the variable.

    Returns
    -------
    str or None
        The derivative's unit, or ``None`` if ``unit`` is not understood.
    """
    m = re.fullmatch(r"(.*)/s(\d*)", unit)
    du = f"{m.group(1)}/s{int(m.group(2) or 1) + 1}" if m else f"{unit}/s"
    return du if unit_base(du) is not None else None


def fmt(v: float) -> str:
    """Return the shortest exact decimal text of a float (for XML attributes).

    Parameters
    ----------
    v : float
        The value.

    Returns
    -------
    str
        ``repr(float(v))``.
    """
    return repr(float(v))


def description_root(
    model: FlatModel,
    fmi_version: str,
    token_attribute: str,
    token: str,
    generation_tool: str,
    **extra: str,
) -> ET.Element:
    """Return the ``fmiModelDescription`` element with the attributes of FMI 2.0 and 3.0.

    Parameters
    ----------
    model : FlatModel
        The model (name and description).
    fmi_version : str
        ``"2.0"`` or ``"3.0"``.
    token_attribute : str
        Name of the token attribute: ``"guid"`` (FMI 2.0) or ``"instantiationToken"``.
    token : str
        Its value.
    generation_tool : str
        Value of the ``generationTool`` attribute.
    **extra : str
        Attributes of the version, after the common ones.

    Returns
    -------
    xml.etree.ElementTree.Element
        The root element.
    """
    attrs = {
        "fmiVersion": fmi_version,
        "modelName": model.name,
        token_attribute: token,
        "description": model.description,
        "generationTool": generation_tool,
        "variableNamingConvention": "structured",
    }
    return ET.Element("fmiModelDescription", {**attrs, **extra})


def xml_document(root: ET.Element) -> str:
    """Return the text of an XML document (indented, with the UTF-8 declaration).

    Parameters
    ----------
    root : xml.etree.ElementTree.Element
        The root element (indented in place).

    Returns
    -------
    str
        The document.
    """
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def add_unit_definitions(root: ET.Element, lay: Layout) -> None:
    """Add ``<UnitDefinitions>`` for every unit used (the same in FMI 2.0 and 3.0).

    Parameters
    ----------
    root : xml.etree.ElementTree.Element
        The ``fmiModelDescription`` element.
    lay : Layout
        The variables.
    """
    groups = [lay.states, lay.inputs, lay.outputs, lay.locals, lay.parameters]
    der_units = {der_unit(v.unit) for v in lay.states if v.unit and der_unit(v.unit)}
    units = sorted({v.unit for vs in groups for v in vs if v.unit} | {"s"} | der_units)
    ud = ET.SubElement(root, "UnitDefinitions")
    for u in units:
        ue = ET.SubElement(ud, "Unit", {"name": u})
        base = unit_base(u)
        if base is not None:
            exps, factor = base
            attrs = {b: str(e) for b, e in exps.items()}
            if factor != 1.0:
                attrs["factor"] = fmt(factor)
            ET.SubElement(ue, "BaseUnit", attrs)


def dependency_vrs(
    causal: Causalized, *, with_parameters: bool = False
) -> tuple[list[list[int]], list[list[int]]]:
    """Value references each derivative and each algebraic variable depends on.

    From the Jacobian sparsity of the live ``eval`` function (a relation counts as a
    dependency of every variable whose branch it selects).

    Parameters
    ----------
    causal : Causalized
        The live form of the model.
    with_parameters : bool, optional
        Also list parameters and time (FMI 3.0 counts them among the knowns; FMI 2.0
        lists only states and inputs). Time is given as value reference ``n_real``.

    Returns
    -------
    tuple of list
        ``(dx, w)``: per derivative and per algebraic variable (outputs, then locals), the
        sorted value references of the knowns it depends on.
    """
    ca, *_ = import_build_deps()
    lay = causal.layout
    ev = causal.eval
    args = ev.sx_in() if ev.is_a("SXFunction") else ev.mx_in()
    dx, w = ev.call(args)
    t, x, u, p = args[:4]
    known = [x, u] + ([p, t] if with_parameters else [])
    vrs = [lay.x_off + k for k in range(lay.nx)] + [lay.u_off + k for k in range(u.numel())]
    if with_parameters:
        vrs += [lay.p_off + k for k in range(p.numel())] + [lay.n_real]
    xu = ca.vertcat(*known)

    def deps(expr: Any) -> list[list[int]]:
        if expr.numel() == 0:
            return []
        sp = ca.jacobian(expr, xu).sparsity()
        return [
            sorted(vrs[j] for j in range(len(vrs)) if sp.has_nz(i, j)) for i in range(expr.numel())
        ]

    return deps(dx), deps(w)


def default_experiment(root: ET.Element, model: FlatModel) -> None:
    """Add ``<DefaultExperiment>`` to ``root`` from the ``experiment`` annotation of ``model``.

    ``root`` is the ``fmiModelDescription`` element (FMI 2.0 or 3.0); without the
    annotation the experiment runs from 0 to 1 s.
    """
    exp = model.experiment
    de = {"startTime": fmt(exp.get("StartTime", 0.0)), "stopTime": fmt(exp.get("StopTime", 1.0))}
    if "Interval" in exp:
        de["stepSize"] = fmt(exp["Interval"])
    ET.SubElement(root, "DefaultExperiment", de)


#: Description of the parameter ``fixedStepSize``.
FIXED_STEP_DESCRIPTION = (
    "Internal step of the fixed-step RK4 integrator in Co-Simulation "
    "(communication steps are split into steps of this size)"
)


def variable_rows(lay: Layout, step_size: float) -> list[tuple[dict[str, str], dict[str, str]]]:
    """Return the real variables in value-reference order, with their FMI attributes.

    Parameters
    ----------
    lay : Layout
        The variables.
    step_size : float
        Default of ``fixedStepSize``.

    Returns
    -------
    list of tuple
        ``(attributes, type attributes)`` per value reference: ``name``,
        ``valueReference``, ``description`` (where there is one), ``causality``,
        ``variability`` and ``initial`` (where given) of the variable; ``unit``,
        ``start`` and, for derivatives, ``derivative`` as the value reference of the
        state.
    """

    def unit_of(v: Any, der: bool = False) -> dict[str, str]:
        du = der_unit(v.unit) if v.unit and der else v.unit
        return {"unit": du} if du else {}

    def kind(causality: str, initial: str | None = None, variability: str = "continuous"):
        attrs = {"causality": causality, "variability": variability}
        return {**attrs, "initial": initial} if initial else attrs

    rows: list[tuple[str, dict[str, str], str, dict]] = []
    for v in lay.states:
        # computed from the parameters at initialization: start is its value at their start
        initial = "approx" if getattr(v, "init", None) is not None else "exact"
        rows.append(
            (v.name, kind("local", initial), v.description, {**unit_of(v), "start": fmt(v.start)})
        )
    for k, v in enumerate(lay.states):
        rows.append(
            (
                f"der({v.name})",
                kind("local", "calculated"),
                f"Time derivative of {v.name}",
                {**unit_of(v, der=True), "derivative": str(lay.x_off + k)},
            )
        )
    for v in lay.inputs:
        rows.append((v.name, kind("input"), v.description, {**unit_of(v), "start": fmt(v.start)}))
    for v in lay.outputs:
        rows.append((v.name, kind("output", "calculated"), v.description, unit_of(v)))
    for v in lay.locals:
        rows.append((v.name, kind("local", "calculated"), v.description, unit_of(v)))
    fixed = kind("parameter", "exact", "fixed")
    for v in lay.parameters:
        if getattr(v, "integer", False):  # the writers turn TYPE_KEY into the element's type
            ints = {TYPE_KEY: "Integer", "start": str(int(v.start))}
            rows.append((v.name, fixed, v.description, ints))
        else:
            rows.append((v.name, fixed, v.description, {**unit_of(v), "start": fmt(v.start)}))
    rows.append(
        (FIXED_STEP_NAME, fixed, FIXED_STEP_DESCRIPTION, {"unit": "s", "start": fmt(step_size)})
    )
    variables: list[tuple[dict[str, str], dict[str, str]]] = []
    for vr, (name, attrs, desc, real) in enumerate(rows):
        head = {"name": name, "valueReference": str(vr)}
        if desc:
            head["description"] = desc
        variables.append(({**head, **attrs}, real))
    return variables


def model_description_xml(
    model: FlatModel,
    causal: Causalized,
    *,
    guid: str,
    step_size: float,
    source_files: list[str],
    generation_tool: str,
    n_event_indicators: int = 0,
) -> str:
    """Return the text of the FMI 2.0 ``modelDescription.xml``.

    Parameters
    ----------
    model : FlatModel
        Flattened model (names, units, descriptions, start values).
    causal : Causalized
        Explicit form (layout and dependency structure).
    guid : str
        The FMU's GUID.
    step_size : float
        Default of ``fixedStepSize``.
    source_files : list of str
        C files in ``sources/`` to compile (``SourceFiles``).
    generation_tool : str
        Value of the ``generationTool`` attribute.
    n_event_indicators : int, optional
        Number of event indicators of Model Exchange (one per relation).

    Returns
    -------
    str
        The XML document.
    """
    lay = causal.layout
    root = description_root(
        model, "2.0", "guid", guid, generation_tool, numberOfEventIndicators=str(n_event_indicators)
    )
    caps = {
        "modelIdentifier": model.short_name,
        "canGetAndSetFMUstate": "true",
        "canNotUseMemoryManagementFunctions": "true",
    }
    me = ET.SubElement(root, "ModelExchange", caps)
    cs_caps = {
        **caps,
        "canHandleVariableCommunicationStepSize": "true",
        "canInterpolateInputs": "true",
    }
    cs = ET.SubElement(root, "CoSimulation", cs_caps)
    for parent in (me, cs):
        sf = ET.SubElement(parent, "SourceFiles")
        for f in source_files:
            ET.SubElement(sf, "File", {"name": f})
    add_unit_definitions(root, lay)
    default_experiment(root, model)

    mv = ET.SubElement(root, "ModelVariables")
    for attrs, real in variable_rows(lay, step_size):
        if "derivative" in real:  # FMI 2.0 refers to the state by its 1-based index
            real = {**real, "derivative": str(int(real["derivative"]) + 1)}
        sv = ET.SubElement(mv, "ScalarVariable", attrs)
        real = dict(real)
        ET.SubElement(sv, real.pop(TYPE_KEY, "Real"), real)
    _model_structure(root, causal)
    return xml_document(root)


def _model_structure(root: ET.Element, causal: Causalized) -> None:
    """FMI 2.0 ``<ModelStructure>``: variables by 1-based index (= value reference + 1)."""
    lay = causal.layout
    dep_dx, dep_w = dependency_vrs(causal)

    def idx(vrs: list[int]) -> str:
        return " ".join(str(v + 1) for v in vrs)

    ms = ET.SubElement(root, "ModelStructure")
    outs = ET.SubElement(ms, "Outputs")
    for k in range(len(lay.outputs)):
        ET.SubElement(
            outs, "Unknown", {"index": str(lay.y_off + k + 1), "dependencies": idx(dep_w[k])}
        )
    ders = ET.SubElement(ms, "Derivatives")
    for k in range(lay.nx):
        ET.SubElement(
            ders, "Unknown", {"index": str(lay.dx_off + k + 1), "dependencies": idx(dep_dx[k])}
        )
    init = ET.SubElement(ms, "InitialUnknowns")
    for vr in initial_unknowns(lay):
        ET.SubElement(init, "Unknown", {"index": str(vr + 1)})


def initial_unknowns(lay: Layout) -> list[int]:
    """Return the value references of the initial unknowns.

    They are the outputs, the derivatives and the states whose initial value is
    computed from the parameters (``initial="approx"``).

    Parameters
    ----------
    lay : Layout
        The variables.

    Returns
    -------
    list of int
        Sorted (FMI 2.0 and 3.0 list the initial unknowns in this order).
    """
    unknowns = [lay.y_off + k for k in range(len(lay.outputs))]
    unknowns += [lay.dx_off + k for k in range(lay.nx)]
    unknowns += [lay.x_off + k for k, v in enumerate(lay.states) if v.init is not None]
    return sorted(unknowns)
