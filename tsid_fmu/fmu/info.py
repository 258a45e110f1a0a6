"""A human-readable summary of an FMU, for ``tsid info FMU``."""

from __future__ import annotations

import os
import unicodedata
import zipfile
from pathlib import Path
from typing import Any

from tsid_fmu.errors import FMUError
from tsid_fmu.fmu.fmufile import check_fmu_file
from tsid_fmu.fmu.variables import VariableInfo, check_fmi_version, variable_info

__all__ = ["fmu_info", "printable", "read_fmu_description"]

MAX_DESCRIPTION_BYTES = 256 * 1024**2
"""Largest modelDescription.xml that :func:`fmu_info` reads into memory."""


def printable(line: str) -> str:
    r"""Return ``line`` with control and format characters written as escapes.

    Names, units and descriptions come from a vendor's ``modelDescription.xml``; printed
    as they are, a newline would break a table and an escape sequence would drive the
    terminal. ``"a\x1b[2Jb"`` reads ``a\x1b[2Jb``; every other character is kept.
    """
    if line.isprintable():
        return line
    return "".join(
        c if not unicodedata.category(c).startswith("C") else c.encode("unicode_escape").decode()
        for c in line
    )


def read_fmu_description(path: Path) -> Any:
    """Return FMPy's model description of the FMU file ``path``, read from the archive.

    Raises
    ------
    FMUError
        The file is missing, not a ZIP archive, has no readable ``modelDescription.xml``
        or one larger than :data:`MAX_DESCRIPTION_BYTES`.
    """
    from fmpy.model_description import read_model_description

    check_fmu_file(path)
    try:
        with zipfile.ZipFile(path) as archive:
            size = archive.getinfo("modelDescription.xml").file_size
            if size <= MAX_DESCRIPTION_BYTES:
                with archive.open("modelDescription.xml") as fh:
                    check_fmi_version(fh, path)
    except KeyError:
        raise FMUError(f"{path}: not a valid FMU, modelDescription.xml is missing") from None
    except (zipfile.BadZipFile, OSError) as exc:
        raise FMUError(f"{path}: cannot read the FMU: {exc}") from None
    if size > MAX_DESCRIPTION_BYTES:
        raise FMUError(
            f"{path}: modelDescription.xml expands to {size} bytes, more than the limit of "
            f"{MAX_DESCRIPTION_BYTES}; refusing the FMU"
        )
    try:
        return read_model_description(str(path), validate=False)
    except Exception as exc:  # FMPy raises bare Exception, KeyError for a missing member
        raise FMUError(f"{path}: cannot read modelDescription.xml: {exc}") from exc


def type_text(v: VariableInfo) -> str:
    """``Float64``, or ``Float64[5]`` for an FMI 3 array variable."""
    dims = ",".join("?" if n < 0 else str(n) for n in v.shape)
    return f"{v.type}[{dims}]" if v.shape else v.type


def _variable_table(md: Any) -> list[str]:
    groups = (
        ("Inputs", lambda v: v.causality == "input"),
        ("Outputs", lambda v: v.causality == "output"),
        ("Parameters", lambda v: v.causality == "parameter" and v.variability != "constant"),
    )
    lines = []
    for title, keep in groups:
        chosen = [variable_info(v) for v in md.modelVariables if keep(v)]
        lines.append("")
        lines.append(f"{title} ({len(chosen)})")
        if chosen:
            width = max(len(v.name) for v in chosen)
            tw = max(8, *(len(type_text(v)) for v in chosen))
            for v in chosen:
                lines.append(
                    f"  {v.name:<{width}}  {type_text(v):<{tw}} {v.unit or '':<8} "
                    f"start={v.start if v.start is not None else '-':<10} "
                    f"{v.description or ''}".rstrip()
                )
    return lines


def fmu_info(path: str | os.PathLike[str]) -> str:
    """Return a human-readable summary of an FMU (for ``tsid info FMU``).

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.fmu`` file.

    Returns
    -------
    str
        FMI version, model name, generation tool, interfaces, platforms, and the
        inputs, outputs and parameters with type, unit, start value and description.

    Raises
    ------
    FMUError
        The file is missing or not a readable FMU.
    """
    from fmpy import supported_platforms

    path = Path(path)
    md = read_fmu_description(path)
    platforms = supported_platforms(str(path))
    interfaces = [
        name
        for name, d in (("Co-Simulation", md.coSimulation), ("Model Exchange", md.modelExchange))
        if d
    ]
    lines = [
        f"FMU              {path}",
        f"FMI version      {md.fmiVersion}",
        f"Model name       {md.modelName}",
        f"Description      {md.description or ''}",
        f"Generation tool  {md.generationTool or ''}",
        f"Interfaces       {', '.join(interfaces) or 'none'}",
        f"Platforms        {', '.join(platforms) or 'none'}",
    ]
    exp = md.defaultExperiment
    if exp is not None:
        lines.append(
            f"Experiment       start={exp.startTime} stop={exp.stopTime} "
            f"step={exp.stepSize} tolerance={exp.tolerance}"
        )
    return "\n".join(printable(line) for line in lines + _variable_table(md))
