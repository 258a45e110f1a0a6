"""Per-experiment parameters: one copy of a parameter for each identification experiment.

A parameter marked ``per_experiment = true`` (or named by an experiment's
``initial = { x0 = "identify" }``) is identified once per experiment, beside the
parameters all experiments share: a test's initial position, a sensor offset of the day.
Each identification experiment that does not fix the variable itself (in its
``start_values`` or by ``initial = "from_data..."``) gets a copy named
``<variable>[<experiment>]``, which sets the FMU variable in that experiment only.

The scheme (issue 29): the copies are nuisance parameters, refined conditionally, so that
the arrays do not grow with the number of experiments.

1. Before the arrays, each experiment's copies are fitted on that experiment alone by
   least squares, the shared parameters at the centre of their first levels
   (:mod:`tsid_fmu.search.nuisance`): a few simulations per copy.
2. The Taguchi arrays run over the shared parameters only; every row holds the copies at
   that estimate.
3. The least-squares refinement then moves every parameter at once, the shared ones and
   every copy, over the stacked residuals of all experiments. Each experiment's
   residuals depend on its own copies only (a block-sparse Jacobian), and the intervals
   come from the Jacobian of that stacked vector, so every copy gets its own interval.

Variable projection (the copies re-fitted inside every array row) would make each row
cost an inner optimisation; holding them costs nothing, and the joint refinement reaches
the same least-squares optimum from the arrays' answer.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

from tsid_fmu.errors import StudyError
from tsid_fmu.study.schema import IDENTIFY, Experiment, Parameter

__all__ = ["Copy", "copy_name", "expand", "per_experiment_names", "plan_copies"]


@dataclass(frozen=True)
class Copy:
    """One experiment's copy of a per-experiment parameter.

    Attributes
    ----------
    name : str
        Its parameter name, ``<variable>[<experiment>]`` (:func:`copy_name`).
    variable : str
        The FMU variable it sets (the study's parameter name).
    experiment : str
        The experiment it applies to.
    """

    name: str
    variable: str
    experiment: str


def copy_name(variable: str, experiment: str) -> str:
    """Return the name of ``variable``'s copy for ``experiment``: ``variable[experiment]``."""
    return f"{variable}[{experiment}]"


def _fixes(experiment: Experiment, variable: str) -> bool:
    """Whether ``experiment`` sets ``variable`` itself (start value or from the data)."""
    how = experiment.initial.get(variable)
    return variable in experiment.start_values or (how is not None and how != IDENTIFY)


def per_experiment_names(
    parameters: Sequence[Parameter], experiments: Sequence[Experiment]
) -> list[str]:
    """Return the per-experiment parameters' names, in study order.

    Raises
    ------
    StudyError
        An experiment's ``initial = "identify"`` names a variable that has no entry in
        the parameters (which would give its range).
    """
    declared = {p.name for p in parameters}
    named = set()
    for e in experiments:
        for variable, how in e.initial.items():
            if how != IDENTIFY:
                continue
            if variable not in declared:
                raise StudyError(
                    f'experiment {e.name!r}: initial {variable!r} = "identify" needs a range: '
                    f"add it to the parameters, e.g. [parameters] {variable} = "
                    "{ levels = [...], min = ..., max = ... }"
                )
            named.add(variable)
    return [p.name for p in parameters if p.per_experiment or p.name in named]


def plan_copies(parameters: Sequence[Parameter], experiments: Sequence[Experiment]) -> list[Copy]:
    """Return the copies of the per-experiment parameters, parameter by parameter.

    Raises
    ------
    StudyError
        A validation experiment would need a value it cannot be given (it must fix the
        variable itself), or every experiment fixes a per-experiment parameter.
    """
    out: list[Copy] = []
    for variable in per_experiment_names(parameters, experiments):
        mine = []
        for e in experiments:
            if _fixes(e, variable):
                continue
            if e.role != "identify":
                raise StudyError(
                    f"experiment {e.name!r} (role {e.role!r}): {variable!r} is identified per "
                    "experiment, and a validation experiment is not fitted; fix its value "
                    f'there (start_values = {{ {variable} = ... }} or initial = "from_data...")'
                )
            mine.append(Copy(copy_name(variable, e.name), variable, e.name))
        if not mine:
            raise StudyError(
                f"parameter {variable!r} is per experiment, but every experiment fixes it "
                "itself: nothing is left to identify; remove it from the parameters"
            )
        out += mine
    return out


def expand(parameters: Sequence[Parameter], copies: Sequence[Copy]) -> list[Parameter]:
    """Return the parameters identified: each per-experiment one replaced by its copies.

    A copy has its parameter's levels, bounds and unit.
    """
    by_variable: dict[str, list[Copy]] = {}
    for c in copies:
        by_variable.setdefault(c.variable, []).append(c)
    out: list[Parameter] = []
    for p in parameters:
        if p.name not in by_variable:
            out.append(p)
            continue
        out += [
            dataclasses.replace(p, name=c.name, per_experiment=False) for c in by_variable[p.name]
        ]
    return out
