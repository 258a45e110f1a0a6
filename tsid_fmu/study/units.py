"""Units of a study's quantities: the study's own, else the FMU's model description."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tsid_fmu.errors import TsidError
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.variables import variable_info

__all__ = ["fmu_units", "study_units"]


def fmu_units(fmu: str | Path) -> dict[str, str]:
    """Return the unit of each variable of an FMU that declares one (``{}`` if unreadable)."""
    try:
        md = read_fmu_description(Path(fmu))
    except TsidError:
        return {}
    out = {}
    for v in md.modelVariables:
        unit = variable_info(v).unit
        if unit:
            out[v.name] = unit
    return out


def study_units(study: Any) -> dict[str, str]:
    """Return units by name: the FMU's variables, overridden by ``Parameter.unit``."""
    if study is None:
        return {}
    units = fmu_units(study.fmu)
    variants = getattr(study, "variants", None)
    for path in [] if variants is None else variants.paths:  # every variant's, in order
        units = {**fmu_units(path), **units}
    simulated = getattr(study, "simulated_fmu", study.fmu)
    if simulated != study.fmu:  # a fixed variant's own units first
        units.update(fmu_units(simulated))
    units.update({p.name: p.unit for p in study.parameters if p.unit})
    # a per-experiment parameter's copies in its variable's unit
    units.update({c.name: units[c.variable] for c in study.copies if units.get(c.variable)})
    return units
