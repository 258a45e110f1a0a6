"""Files other tools and scripts read: ``result.json``, ``parameters.csv``, ``parameters.ssv``."""

from __future__ import annotations

from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import numpy as np

from tsid_fmu.result import IdentificationResult
from tsid_fmu.study.units import study_units
from tsid_fmu.trail.files import atomic_write, write_json
from tsid_fmu.trail.integrity import seal, sha256_file

__all__ = ["JACOBIAN", "parameter_set_ssv", "write_result_files"]

JACOBIAN = "jacobian.npy"
"""The file of :attr:`IdentificationResult.jac` in a results folder (NumPy's ``.npy``)."""


def parameter_set_ssv(
    values: dict[str, float], descriptions: dict[str, str] | None = None, name: str = "tsid"
) -> str:
    """Return an SSP 1.0 parameter-value document (``.ssv``) holding ``values``."""
    ns = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    ET.register_namespace("ssv", ns)
    root = ET.Element(f"{{{ns}}}ParameterSet", {"version": "1.0", "name": name})
    params = ET.SubElement(root, f"{{{ns}}}Parameters")
    for key, value in values.items():
        attrs = {"name": key}
        if descriptions and descriptions.get(key):
            attrs["description"] = descriptions[key]
        p = ET.SubElement(params, f"{{{ns}}}Parameter", attrs)
        ET.SubElement(p, f"{{{ns}}}Real", {"value": repr(float(value))})
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _write_jacobian(jac: np.ndarray, out: Path) -> dict[str, Any]:
    """Write ``jac`` to :data:`JACOBIAN` in ``out``; return what result.json says of it."""

    def save(path: Path) -> None:
        with open(path, "wb") as fh:  # np.save(path) would append ".npy" to the temporary name
            np.save(fh, np.asarray(jac, dtype=float), allow_pickle=False)

    atomic_write(out / JACOBIAN, save)
    return {"file": JACOBIAN, "shape": list(jac.shape), "sha256": sha256_file(out / JACOBIAN)}


def write_result_files(result: IdentificationResult, out: Path) -> None:
    """Write ``result.json``, ``parameters.csv`` and ``parameters.ssv`` into ``out``.

    ``result.json`` ends with a ``digest`` of the rest (:func:`~tsid_fmu.trail.integrity.seal`),
    which :func:`tsid_fmu.load` checks before it trusts the file. Where the result has a
    Jacobian (:attr:`IdentificationResult.jac`), it is written bit for bit to
    ``jacobian.npy`` (8 bytes per residual and parameter), and ``result.json`` holds
    its shape and SHA-256 under ``jac``, so that ``load`` gives the same array back.
    """
    study = result.study
    data = result.to_dict()
    if result.jac is not None:
        data["jac"] = _write_jacobian(result.jac, out)
    if study is not None:
        data = {"study": study.name, "fmu": str(study.simulated_fmu), **data}
        if study.source is not None:  # the folder the paths of the copied study.toml start at
            data["study_folder"] = str(Path(study.source).resolve().parent)
    write_json(out / "result.json", seal(data))
    if study is None:
        return
    atomic_write(out / "parameters.csv", result.parameters_frame().to_csv())
    units = study_units(study)  # the study's, else the FMU's declared ones
    # a per-experiment parameter's copies are no FMU variables: one set cannot hold them
    copies = {c.name for c in study.copies}
    values = {k: v for k, v in result.params.items() if k not in copies}
    values.update({k: v for k, v in study.start_values.items() if k not in values})
    desc = {k: f"identified, unit {units[k]}" if units.get(k) else "identified" for k in values}
    desc.update({k: "fixed in the study" for k in study.start_values})
    atomic_write(out / "parameters.ssv", parameter_set_ssv(values, desc, name=study.name))
