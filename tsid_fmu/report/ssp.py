"""The identified model as an SSP 1.0 package (``model.ssp``) other tools can simulate.

FMI forbids changing a vendor FMU's start values in ``modelDescription.xml``; the
standard way to hand on a parameterised FMU is an SSP archive (Modelica Association,
"System Structure and Parameterization" 1.0):

- ``SystemStructure.ssd``: a system with one component, the FMU, whose connectors are
  the FMU's inputs and outputs (with their types and units), connected to connectors of
  the same names on the system, and a parameter binding to the ``.ssv`` file;
- ``resources/<fmu file>``: the study's FMU, unchanged;
- ``resources/<Model>.ssv``: the identified values and the study's fixed start values,
  typed like the FMU's variables.

The archive is byte-for-byte reproducible (fixed member order and time stamps).
:func:`validate_ssp` checks the XML against the SSP 1.0 schemas that FMPy ships in its
package data (``fmpy/ssp/schema``).
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

from tsid_fmu.errors import FMUError
from tsid_fmu.fmu.delay import delay_input
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.result import IdentificationResult
from tsid_fmu.study.units import study_units
from tsid_fmu.trail.files import atomic_write

__all__ = ["SSD_NAME", "model_ssp", "validate_ssp", "write_model_ssp", "write_ssp"]

SSD_NAME = "SystemStructure.ssd"
"""The system structure description at the root of every SSP archive."""

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
}
_FMU_TYPE = "application/x-fmu-sharedlibrary"
_SSV_TYPE = "application/x-ssp-parameter-set"
_DATE = (2020, 1, 1, 0, 0, 0)  # fixed time stamps: the same content gives the same bytes
_REAL = {"Real", "Float64", "Float32"}
_INTEGER = {"Integer", "Enumeration", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32"}
_INTEGER |= {"Int64", "UInt64"}
_BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _kind(vtype: str) -> str | None:
    """SSP type element of an FMU variable type (None: not representable)."""
    if vtype in _REAL:
        return "Real"
    if vtype in _INTEGER:
        return "Integer"
    return "Boolean" if vtype == "Boolean" else None


def _xml(root: ET.Element) -> bytes:
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


def _connectors(parent: ET.Element, ports: list[tuple[str, str, str, str | None]]) -> None:
    box = ET.SubElement(parent, _q("ssd", "Connectors"))
    for name, kind, vtype, unit in ports:
        conn = ET.SubElement(box, _q("ssd", "Connector"), {"name": name, "kind": kind})
        ET.SubElement(conn, _q("ssc", vtype), {"unit": unit} if unit and vtype == "Real" else {})


def _units(root: ET.Element, md: Any, used: set[str]) -> None:
    defined = [u for u in getattr(md, "unitDefinitions", []) or [] if u.name in used]
    if not defined:
        return
    box = ET.SubElement(root, _q("ssd", "Units"))
    for unit in defined:
        elem = ET.SubElement(box, _q("ssc", "Unit"), {"name": unit.name})
        base = unit.baseUnit
        attrs = {k: str(getattr(base, k)) for k in _BASE if base and getattr(base, k, 0)}
        if base and getattr(base, "factor", 1.0) != 1.0:
            attrs["factor"] = repr(float(base.factor))
        if base and getattr(base, "offset", 0.0) != 0.0:
            attrs["offset"] = repr(float(base.offset))
        ET.SubElement(elem, _q("ssc", "BaseUnit"), attrs)


def _ports(md: Any) -> list[tuple[str, str, str, str | None]]:
    """``(name, kind, SSP type, unit)`` of the FMU's inputs and outputs."""
    ports = []
    for v in md.modelVariables:
        vtype = _kind(v.type)
        if v.causality in ("input", "output") and vtype is not None:
            unit = getattr(v, "unit", None)
            if unit is None and getattr(v, "declaredType", None) is not None:
                unit = getattr(v.declaredType, "unit", None)
            ports.append((v.name, v.causality, vtype, unit))
    return ports


def _ssd(md: Any, component: str, source: str, ssv: str, name: str) -> bytes:
    """Return the SSD: one component, its ports, its parameter set."""
    ports = _ports(md)
    root = ET.Element(_q("ssd", "SystemStructureDescription"), {"version": "1.0", "name": name})
    system = ET.SubElement(root, _q("ssd", "System"), {"name": name})
    _connectors(system, ports)
    elements = ET.SubElement(system, _q("ssd", "Elements"))
    attrs = {"name": component, "type": _FMU_TYPE, "source": source}
    comp = ET.SubElement(elements, _q("ssd", "Component"), attrs)
    _connectors(comp, ports)
    bindings = ET.SubElement(comp, _q("ssd", "ParameterBindings"))
    ET.SubElement(bindings, _q("ssd", "ParameterBinding"), {"type": _SSV_TYPE, "source": ssv})
    connections = ET.SubElement(system, _q("ssd", "Connections"))
    for port, kind, _vtype, _unit in ports:
        ends = (
            {"startConnector": port, "endElement": component, "endConnector": port}
            if kind == "input"
            else {"startElement": component, "startConnector": port, "endConnector": port}
        )
        ET.SubElement(connections, _q("ssd", "Connection"), ends)
    if not ports:
        system.remove(connections)
    _units(root, md, {unit for *_, unit in ports if unit})
    exp = getattr(md, "defaultExperiment", None)
    if exp is not None and (exp.startTime is not None or exp.stopTime is not None):
        times = {"startTime": exp.startTime, "stopTime": exp.stopTime}
        ET.SubElement(
            root,
            _q("ssd", "DefaultExperiment"),
            {k: repr(float(v)) for k, v in times.items() if v is not None},
        )
    return _xml(root)


def _ssv(md: Any, values: Mapping[str, float], descriptions: Mapping[str, str], name: str) -> bytes:
    """Return the parameter set, each value typed like its FMU variable."""
    types = {v.name: v.type for v in md.modelVariables}
    root = ET.Element(_q("ssv", "ParameterSet"), {"version": "1.0", "name": name})
    params = ET.SubElement(root, _q("ssv", "Parameters"))
    for key, value in values.items():
        if key not in types:
            raise FMUError(f"{md.modelName}: no variable {key!r} for the SSP parameter set")
        attrs = {"name": key}
        if descriptions.get(key):
            attrs["description"] = descriptions[key]
        param = ET.SubElement(params, _q("ssv", "Parameter"), attrs)
        kind = _kind(types[key]) or "Real"
        text = (
            repr(float(value))
            if kind == "Real"
            else str(round(float(value)))
            if kind == "Integer"
            else ("true" if value else "false")
        )
        ET.SubElement(param, _q("ssv", kind), {"value": text})
    return _xml(root)


def model_ssp(
    fmu: str | Path,
    values: Mapping[str, float],
    *,
    name: str = "identified",
    descriptions: Mapping[str, str] | None = None,
) -> bytes:
    """Return the bytes of an SSP archive of ``fmu`` parameterised with ``values``.

    Parameters
    ----------
    fmu : str or Path
        The FMU file (FMI 2.0 or 3.0).
    values : mapping of str to float
        FMU variables and their values (parameters, start values).
    name : str
        Name of the SSD and of its system.
    descriptions : mapping of str to str, optional
        A description per value (e.g. "identified, unit N").

    Raises
    ------
    FMUError
        The FMU cannot be read, or a value names no variable of it.
    """
    fmu = Path(fmu)
    md = read_fmu_description(fmu)
    desc = md.coSimulation or md.modelExchange
    component = desc.modelIdentifier if desc is not None else fmu.stem
    source, ssv = f"resources/{fmu.name}", f"resources/{component}.ssv"
    members = [
        (SSD_NAME, _ssd(md, component, source, ssv, name)),
        (source, fmu.read_bytes()),
        (ssv, _ssv(md, values, descriptions or {}, name)),
    ]
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for member, data in members:
            info = zipfile.ZipInfo(member, date_time=_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, data)
    return buffer.getvalue()


def write_ssp(path: Path, fmu: str | Path, values: Mapping[str, float], **kwargs: Any) -> Path:
    """Write :func:`model_ssp` atomically to ``path``; return ``path``."""
    atomic_write(path, model_ssp(fmu, values, **kwargs))
    return path


def write_model_ssp(result: IdentificationResult, out: Path) -> Path | None:
    """Write ``model.ssp`` of an identification into ``out`` (None without a study).

    The parameter set holds the identified values and the study's fixed start values.
    """
    study = result.study
    if study is None:
        return None
    units = study_units(study)  # the study's, else the FMU's declared ones
    # an input delay is applied to the data by tsid-fmu, not an FMU variable: SSP 1.0
    # has no place for it, so the report names it instead
    copies = {c.name for c in study.copies}  # one value per experiment: no FMU variable
    values = {
        k: v
        for k, v in {**result.params, **study.start_values}.items()
        if not delay_input(k) and k not in copies
    }
    desc = {k: f"identified, unit {units[k]}" if units.get(k) else "identified" for k in values}
    desc.update(dict.fromkeys(study.start_values, "fixed in the study"))
    values = study.fmu_values(values)  # a choice among FMU files: its variant's own values
    return write_ssp(
        out / "model.ssp", study.simulated_fmu, values, name=study.name, descriptions=desc
    )


def validate_ssp(path: str | Path) -> list[str]:
    """Check an SSP archive's SSD and ``.ssv`` files against the SSP 1.0 XML schemas.

    The schemas are FMPy's copies of the Modelica Association's SSP 1.0 schemas
    (``fmpy/ssp/schema``).

    Returns
    -------
    list of str
        One message per schema violation or missing part (empty: valid).
    """
    import fmpy
    from lxml import etree

    schemas = Path(fmpy.__file__).parent / "ssp" / "schema"
    problems: list[str] = []
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        if SSD_NAME not in names:
            return [f"{path}: no {SSD_NAME}"]
        checks = [(SSD_NAME, "SystemStructureDescription.xsd")]
        checks += [(n, "SystemStructureParameterValues.xsd") for n in names if n.endswith(".ssv")]
        for member, xsd in checks:
            schema = etree.XMLSchema(etree.parse(str(schemas / xsd)))
            doc = etree.fromstring(archive.read(member))
            if not schema.validate(doc):
                problems += [f"{member}:{e.line}: {e.message}" for e in schema.error_log]
        ssd = etree.fromstring(archive.read(SSD_NAME))
        for comp in ssd.iter(_q("ssd", "Component"), _q("ssd", "ParameterBinding")):
            source = comp.get("source")
            if source and source not in names:
                problems.append(f"{SSD_NAME}: {source} is referenced but not in the archive")
    return problems
