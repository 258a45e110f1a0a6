"""Generate ``modelDescription.xml`` (FMI 2.0) from the Modelica declarations."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from typing import Any

from .codegen import Causalized
from .modelica import FlatModel, import_build_deps

__all__ = ["FIXED_STEP_NAME", "model_description_xml", "unit_base"]

FIXED_STEP_NAME = "fixedStepSize"

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


def _fmt(v: float) -> str:
    return repr(float(v))


def model_description_xml(
    model: FlatModel,
    causal: Causalized,
    *,
    guid: str,
    step_size: float,
    source_files: list[str],
    generation_tool: str,
) -> str:
    """Return the text of ``modelDescription.xml``.

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

    Returns
    -------
    str
        The XML document.
    """
    ca, *_ = import_build_deps()
    lay = causal.layout
    ident = model.short_name
    exp = model.experiment
    root = ET.Element(
        "fmiModelDescription",
        {
            "fmiVersion": "2.0",
            "modelName": model.name,
            "guid": guid,
            "description": model.description,
            "generationTool": generation_tool,
            "variableNamingConvention": "structured",
            # The event indicators are used inside Co-Simulation only: exposed to an ME
            # solver, the stick band of dry friction makes it chatter at the band edge.
            "numberOfEventIndicators": "0",
        },
    )
    caps = {
        "modelIdentifier": ident,
        "canGetAndSetFMUstate": "true",
        "canNotUseMemoryManagementFunctions": "true",
    }
    me = ET.SubElement(root, "ModelExchange", caps)
    cs = ET.SubElement(
        root, "CoSimulation", {**caps, "canHandleVariableCommunicationStepSize": "true"}
    )
    for parent in (me, cs):
        sf = ET.SubElement(parent, "SourceFiles")
        for f in source_files:
            ET.SubElement(sf, "File", {"name": f})

    groups: list[tuple[str, list[Any]]] = [
        ("state", lay.states),
        ("der", lay.states),
        ("input", lay.inputs),
        ("output", lay.outputs),
        ("local", lay.locals),
        ("parameter", lay.parameters),
    ]
    der_units = {der_unit(v.unit) for v in lay.states if v.unit and der_unit(v.unit)}
    units = sorted({v.unit for _, vs in groups for v in vs if v.unit} | {"s"} | der_units)
    ud = ET.SubElement(root, "UnitDefinitions")
    for u in units:
        ue = ET.SubElement(ud, "Unit", {"name": u})
        base = unit_base(u)
        if base is not None:
            exps, factor = base
            attrs = {b: str(e) for b, e in exps.items()}
            if factor != 1.0:
                attrs["factor"] = _fmt(factor)
            ET.SubElement(ue, "BaseUnit", attrs)

    start_time = exp.get("StartTime", 0.0)
    de = {"startTime": _fmt(start_time), "stopTime": _fmt(exp.get("StopTime", 1.0))}
    if "Interval" in exp:
        de["stepSize"] = _fmt(exp["Interval"])
    ET.SubElement(root, "DefaultExperiment", de)

    mv = ET.SubElement(root, "ModelVariables")
    index: dict[int, int] = {}  # value reference -> 1-based index
    vr = 0

    def add(name: str, attrs: dict[str, str], desc: str, real: dict[str, str]) -> None:
        nonlocal vr
        a = {"name": name, "valueReference": str(vr)}
        if desc:
            a["description"] = desc
        a.update(attrs)
        sv = ET.SubElement(mv, "ScalarVariable", a)
        ET.SubElement(sv, "Real", real)
        index[vr] = len(index) + 1
        vr += 1

    def unit_of(v: Any, der: bool = False) -> dict[str, str]:
        if not v.unit:
            return {}
        if not der:
            return {"unit": v.unit}
        du = der_unit(v.unit)
        return {"unit": du} if du else {}

    for v in lay.states:
        add(
            v.name,
            {"causality": "local", "variability": "continuous", "initial": "exact"},
            v.description,
            {**unit_of(v), "start": _fmt(v.start or 0.0)},
        )
    for k, v in enumerate(lay.states):
        add(
            f"der({v.name})",
            {"causality": "local", "variability": "continuous", "initial": "calculated"},
            f"Time derivative of {v.name}",
            {**unit_of(v, der=True), "derivative": str(index[lay.x_off + k])},
        )
    for v in lay.inputs:
        add(
            v.name,
            {"causality": "input", "variability": "continuous"},
            v.description,
            {**unit_of(v), "start": _fmt(v.start or 0.0)},
        )
    for v in lay.outputs:
        add(
            v.name,
            {"causality": "output", "variability": "continuous", "initial": "calculated"},
            v.description,
            unit_of(v),
        )
    for v in lay.locals:
        add(
            v.name,
            {"causality": "local", "variability": "continuous", "initial": "calculated"},
            v.description,
            unit_of(v),
        )
    for v in lay.parameters:
        add(
            v.name,
            {"causality": "parameter", "variability": "fixed", "initial": "exact"},
            v.description,
            {**unit_of(v), "start": _fmt(v.start)},
        )
    add(
        FIXED_STEP_NAME,
        {"causality": "parameter", "variability": "fixed", "initial": "exact"},
        "Internal step of the fixed-step RK4 integrator in Co-Simulation "
        "(communication steps are split into steps of this size)",
        {"unit": "s", "start": _fmt(step_size)},
    )

    # Dependencies from the Jacobian sparsity of (der(x), w) w.r.t. (x, u).
    ev = causal.eval
    nx, nu = lay.nx, len(lay.inputs)
    x_in = ev.sx_in(1) if ev.is_a("SXFunction") else ev.mx_in(1)
    u_in = ev.sx_in(2) if ev.is_a("SXFunction") else ev.mx_in(2)
    args = ev.sx_in() if ev.is_a("SXFunction") else ev.mx_in()
    args[1], args[2] = x_in, u_in
    dx, w = ev.call(args)
    xu = ca.vertcat(x_in, u_in)

    def deps(expr: Any) -> list[list[int]]:
        if expr.numel() == 0:
            return []
        sp = ca.jacobian(expr, xu).sparsity()
        out = []
        for i in range(expr.numel()):
            cols = [j for j in range(nx + nu) if sp.has_nz(i, j)]
            out.append(
                [index[lay.x_off + j] if j < nx else index[lay.u_off + j - nx] for j in cols]
            )
        return out

    dep_dx = deps(dx)
    dep_w = deps(w)
    ms = ET.SubElement(root, "ModelStructure")
    outs = ET.SubElement(ms, "Outputs")
    for k in range(len(lay.outputs)):
        ET.SubElement(
            outs,
            "Unknown",
            {"index": str(index[lay.y_off + k]), "dependencies": " ".join(map(str, dep_w[k]))},
        )
    ders = ET.SubElement(ms, "Derivatives")
    for k in range(nx):
        ET.SubElement(
            ders,
            "Unknown",
            {"index": str(index[lay.dx_off + k]), "dependencies": " ".join(map(str, dep_dx[k]))},
        )
    init = ET.SubElement(ms, "InitialUnknowns")
    for k in range(len(lay.outputs)):
        ET.SubElement(init, "Unknown", {"index": str(index[lay.y_off + k])})
    for k in range(nx):
        ET.SubElement(init, "Unknown", {"index": str(index[lay.dx_off + k])})
    # InitialUnknowns must be sorted by index.
    init[:] = sorted(init, key=lambda e: int(e.get("index", "0")))

    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
