"""Initial states from the data: ``initial = { x0 = "from_data:x_m" }`` in an experiment.

Each such FMU variable is set, for that experiment only, to the named column's value at
the record's first sample: the instant the simulation starts, whatever the experiment's
windows score (a state set from a later sample would be that sample's state at the
wrong time). The value is one noisy sample; where the noise matters, identify the state
per experiment instead (a parameter with ``per_experiment = true``).

The variable must be one the FMU lets a caller set before it initialises: a parameter
(such as a state's ``x0``) or a continuous state whose start value is its initial value
(``initial="exact"``). Anything else is refused, naming the experiment and the variable.
"""

from __future__ import annotations

from pathlib import Path

from tsid_fmu.data.measured import MeasuredData
from tsid_fmu.errors import DataError, FMUError, StudyError
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.variables import REAL_TYPES, find_variable, initial_state, variable_info
from tsid_fmu.study.schema import IDENTIFY, Experiment, initial_column

__all__ = ["check_settable", "initial_values"]


def check_settable(fmu: Path, names: list[str], where: str) -> None:
    """Refuse a variable of ``names`` that the FMU does not let a caller set before it starts.

    Raises
    ------
    StudyError
        Naming ``where`` (the experiment and key) and the variable, with the reason.
    """
    if not names:
        return
    md = read_fmu_description(Path(fmu))
    variables = {v.name: variable_info(v) for v in md.modelVariables}
    for name in names:
        try:
            info = find_variable(variables, Path(fmu).name, name, "variable")
        except FMUError as exc:
            raise StudyError(f"{where} {name!r}: {exc}") from None
        settable = (
            info.causality == "parameter" and info.variability in ("fixed", "tunable")
        ) or initial_state(info)
        if not settable or info.type not in REAL_TYPES:
            raise StudyError(
                f"{where} {name!r}: {Path(fmu).name} does not let it be set before the "
                f"simulation starts (causality {info.causality!r}, variability "
                f"{info.variability!r}, initial {info.initial!r}, type {info.type}); name "
                "the Real parameter that sets it (such as its x0), or a state with "
                "initial 'exact'"
            )


def initial_values(fmu: Path, experiment: Experiment, data: MeasuredData) -> dict[str, float]:
    """Return the start values that ``experiment.initial`` takes from ``data``.

    Variables marked ``"identify"`` are checked settable too, but take no value here:
    they are per-experiment parameters (:mod:`tsid_fmu.study.copies`).

    Raises
    ------
    StudyError
        A variable cannot be set (:func:`check_settable`), or its column is missing.
    """
    where = f"experiment {experiment.name!r}: initial"
    check_settable(fmu, list(experiment.initial), where)
    out = {}
    for name, how in experiment.initial.items():
        if how == IDENTIFY:
            continue
        column = initial_column(experiment, name) or ""
        try:
            out[name] = float(data.column(column)[0])
        except DataError as exc:
            raise StudyError(f"{where} {name!r} = {experiment.initial[name]!r}: {exc}") from None
    return out
