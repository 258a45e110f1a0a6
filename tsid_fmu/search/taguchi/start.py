"""The start points a stage scores before its first array: never worse than doing nothing.

A user's first ranges are rough, and may not hold the truth; the FMU's own start values
are often a better guess than any row of the first array. So a Taguchi stage first
scores:

- the FMU's start values of its parameters (where the model description gives them,
  clipped to the study's bounds), or the values the earlier phases left;
- the centre of the first levels (search coordinates 0).

The best of them is the stage's best set before its first iteration, so its answer is
never worse than the best start point.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from tsid_fmu.errors import TsidError
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.variables import parse_start, variable_info
from tsid_fmu.search.space import Space

__all__ = ["fmu_start_values", "start_points"]


@functools.lru_cache(maxsize=16)
def _declared_starts(path: Path, stamp: float) -> dict[str, float]:
    """Start values of an FMU's variables (``stamp``: the file's mtime, for the cache)."""
    del stamp
    try:
        description = read_fmu_description(path)
    except TsidError:
        return {}
    out = {}
    for variable in description.modelVariables:
        value = parse_start(variable_info(variable))
        if value is not None and math.isfinite(value):
            out[variable.name] = value
    return out


def fmu_start_values(path: str | Path, names: Sequence[str]) -> dict[str, float]:
    """Return the start values the FMU at ``path`` declares for ``names`` (those it has)."""
    path = Path(path)
    try:
        stamp = path.stat().st_mtime
    except OSError:
        return {}
    declared = _declared_starts(path.resolve(), stamp)
    return {n: declared[n] for n in names if n in declared}


def start_points(
    space: Space,
    fmu: str | Path | None,
    current: Mapping[str, float] | None = None,
) -> list[tuple[dict[str, float], str]]:
    """Return the start points of a stage over ``space``'s parameters, with their source.

    Parameters
    ----------
    space : Space
        The stage's coordinates (its first levels and bounds).
    fmu : path, optional
        The FMU whose declared start values are a start point.
    current : mapping, optional
        Values the earlier stages left (a phase's start); used instead of the FMU's.

    Returns
    -------
    list of (dict, str)
        Distinct parameter sets, each with where it came from.
    """
    names = list(space.names)
    out: list[tuple[dict[str, float], str]] = []
    if current is not None and all(n in current for n in names):
        out.append(({n: float(current[n]) for n in names}, "the values before this stage"))
    elif fmu is not None:
        declared = fmu_start_values(fmu, names)
        if len(declared) == len(names):
            s = space.clip(space.to_s(declared))
            out.append((_exact(space, declared, s), "the FMU's start values"))
    centre = space.to_x(space.clip(np.zeros(space.dim)))
    if not any(x == centre for x, _ in out):
        out.append((centre, "the centre of the first levels"))
    return out


def _exact(space: Space, x: Mapping[str, float], s: np.ndarray) -> dict[str, float]:
    """``x`` itself where it is within the bounds, else its clipped value."""
    clipped = space.to_x(s)
    return {
        n: float(x[n]) if space.bounds[n][0] <= x[n] <= space.bounds[n][1] else clipped[n]
        for n in space.names
    }
