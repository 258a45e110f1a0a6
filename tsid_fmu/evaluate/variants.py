"""Model variants: a parameter set routed to the FMU file its choice names.

A study with a choice among FMU files (:class:`~tsid_fmu.study.choice.ModelChoice`)
simulates each parameter set with the variant that the set's value of the choice names
(``0, 1, ...`` in the order given). Each variant gets only the values it has variables
for: a parameter of another variant is left out, so that it has no effect there (the
structure procedure then finds it not free in that variant). The choice's own value is
never set in an FMU.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from tsid_fmu.errors import StudyError
from tsid_fmu.fmu.delay import delay_input

__all__ = ["Variants", "variants_of"]


@dataclass(frozen=True)
class Variants:
    """The FMU files a choice selects among, and the variables each has.

    Parameters
    ----------
    name : str
        The choice's name (a parameter of every set, not an FMU variable).
    fmus : tuple of pathlib.Path
        The variants, in the choice's order.
    variables : tuple of frozenset of str
        Each variant's variable names (from its model description).
    """

    name: str
    fmus: tuple[Path, ...]
    variables: tuple[frozenset[str], ...]

    def index(self, values: Mapping[str, float]) -> int:
        """Return the variant a parameter set names (its value of the choice).

        Raises
        ------
        StudyError
            The set has no value of the choice, or one that names no variant.
        """
        value = values.get(self.name)
        i = -1 if value is None else round(float(value))
        if value is None or i != value or not 0 <= i < len(self.fmus):
            raise StudyError(
                f"{self.name} = {value!r} names no FMU variant (0 to {len(self.fmus) - 1})"
            )
        return i

    def keep(self, index: int, values: Mapping[str, float]) -> dict[str, float]:
        """Return the values variant ``index`` has variables for (input delays kept)."""
        have = self.variables[index]
        return {k: v for k, v in values.items() if k in have or delay_input(k) is not None}

    def names(self, index: int, names: list[str]) -> list[str]:
        """Return the names among ``names`` that variant ``index`` has (delays kept)."""
        have = self.variables[index]
        return [n for n in names if n in have or delay_input(n) is not None]


def variants_of(name: str, fmus: list[Path]) -> Variants:
    """Read each variant's variable names; return the :class:`Variants` of a choice."""
    from tsid_fmu.fmu.info import read_fmu_description

    variables = []
    for path in fmus:
        md = read_fmu_description(Path(path))
        variables.append(frozenset(v.name for v in md.modelVariables))
    return Variants(name, tuple(Path(p) for p in fmus), tuple(variables))
