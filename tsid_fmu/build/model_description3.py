"""Generate the FMI 3.0 ``modelDescription.xml`` and ``sources/buildDescription.xml``.

The variables, value references, units and dependencies are those of the FMI 2.0 model
description (:mod:`.model_description`); FMI 3.0 adds

* the independent variable ``time`` (value reference ``N_REAL``, after the real array),
* one ``Float64`` variable per event indicator (``_eventIndicator_<k>``, value references
  after ``time``), listed in ``<ModelStructure><EventIndicator>`` as FMI 3.0 requires,
* ``intermediateUpdate="true"`` on the inputs: in Co-Simulation the FMU calls the
  importer's ``intermediateUpdate`` callback at the times its integrator needs inputs
  inside a step, so that the importer can set interpolated values (the FMI 3.0
  replacement of FMI 2.0's ``fmi2SetRealInputDerivatives``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from .causalize import Causalized, Layout
from .expressions import Relation
from .model_description import (
    TYPE_KEY,
    add_unit_definitions,
    default_experiment,
    dependency_vrs,
    description_root,
    initial_unknowns,
    variable_rows,
    xml_document,
)
from .modelica import FlatModel

__all__ = ["EVENT_INDICATOR_PREFIX", "build_description_xml", "model_description3_xml"]

#: Names of the FMI 3.0 event-indicator variables: ``_eventIndicator_1``, ...
EVENT_INDICATOR_PREFIX = "_eventIndicator_"


def model_description3_xml(
    model: FlatModel,
    causal: Causalized,
    *,
    token: str,
    step_size: float,
    generation_tool: str,
    relations: list[Relation],
) -> str:
    """Return the text of the FMI 3.0 ``modelDescription.xml``.

    Parameters
    ----------
    model, step_size, generation_tool
        As for :func:`~tsid_fmu.build.model_description.model_description_xml`.
    causal : Causalized
        Live form (layout and dependency structure).
    token : str
        The instantiation token.
    relations : list of Relation
        The relations whose indicators are the Model Exchange event indicators.

    Returns
    -------
    str
        The XML document.
    """
    lay = causal.layout
    root = description_root(model, "3.0", "instantiationToken", token, generation_tool)
    caps = {"modelIdentifier": model.short_name, "canGetAndSetFMUState": "true"}
    me_caps = {**caps, "needsCompletedIntegratorStep": "true"}
    ET.SubElement(root, "ModelExchange", me_caps)
    cs_caps = {
        **caps,
        "canHandleVariableCommunicationStepSize": "true",
        "providesIntermediateUpdate": "true",
    }
    ET.SubElement(root, "CoSimulation", cs_caps)
    add_unit_definitions(root, lay)
    log = ET.SubElement(root, "LogCategories")
    ET.SubElement(log, "Category", {"name": "logEvents", "description": "Log events"})
    ET.SubElement(log, "Category", {"name": "logStatusError", "description": "Log errors"})
    default_experiment(root, model)

    _model_variables(root, lay, step_size, relations)
    _model_structure(root, causal, len(relations))
    return xml_document(root)


def _model_variables(
    root: ET.Element, lay: Layout, step_size: float, relations: list[Relation]
) -> None:
    """FMI 3.0 ``<ModelVariables>``: the real array, ``time``, the event indicators."""
    mv = ET.SubElement(root, "ModelVariables")
    for attrs, real in variable_rows(lay, step_size):
        a = {**attrs, **real}
        if attrs["causality"] == "input":
            a["intermediateUpdate"] = "true"
        kind = a.pop(TYPE_KEY, "Real")
        ET.SubElement(mv, "Int32" if kind == "Integer" else "Float64", a)
    ET.SubElement(
        mv,
        "Float64",
        {
            "name": "time",
            "valueReference": str(lay.n_real),
            "causality": "independent",
            "variability": "continuous",
            "description": "Simulation time",
        },
    )
    for k, r in enumerate(relations):
        ET.SubElement(
            mv,
            "Float64",
            {
                "name": f"{EVENT_INDICATOR_PREFIX}{k + 1}",
                "valueReference": str(lay.n_real + 1 + k),
                "causality": "local",
                "variability": "continuous",
                "initial": "calculated",
                "description": f"Event indicator of the relation {r.text} (with hysteresis; "
                "> 0 while the relation holds)",
            },
        )


def _model_structure(root: ET.Element, causal: Causalized, n_rel: int) -> None:
    """FMI 3.0 ``<ModelStructure>``: variables by value reference."""
    lay = causal.layout
    dep_dx, dep_w = dependency_vrs(causal, with_parameters=True)
    ms = ET.SubElement(root, "ModelStructure")

    def deps(vrs: list[int]) -> str:
        return " ".join(map(str, vrs))

    for k in range(len(lay.outputs)):
        ET.SubElement(
            ms, "Output", {"valueReference": str(lay.y_off + k), "dependencies": deps(dep_w[k])}
        )
    for k in range(lay.nx):
        ET.SubElement(
            ms,
            "ContinuousStateDerivative",
            {"valueReference": str(lay.dx_off + k), "dependencies": deps(dep_dx[k])},
        )
    for vr in initial_unknowns(lay):
        ET.SubElement(ms, "InitialUnknown", {"valueReference": str(vr)})
    for k in range(n_rel):
        ET.SubElement(ms, "EventIndicator", {"valueReference": str(lay.n_real + 1 + k)})


def build_description_xml(ident: str, source_files: list[str]) -> str:
    """Return the text of ``sources/buildDescription.xml`` (FMI 3.0 source code FMUs).

    Parameters
    ----------
    ident : str
        The model identifier.
    source_files : list of str
        The C files to compile.

    Returns
    -------
    str
        The XML document.
    """
    root = ET.Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    bc = ET.SubElement(root, "BuildConfiguration", {"modelIdentifier": ident})
    sfs = ET.SubElement(bc, "SourceFileSet", {"language": "C99"})
    for f in source_files:
        ET.SubElement(sfs, "SourceFile", {"name": f})
    return xml_document(root)
