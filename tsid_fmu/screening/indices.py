"""The numbers of a screening: SALib's Morris and Sobol indices, and eq. (7) from an array.

Pure numbers, no FMU: the sample designs (in search coordinates, each parameter's first
range one unit wide, ``[-0.5, 0.5]``), the indices of one screened quantity from its
values on that design, and the MISO paper's "% of error variation" (eq. 7) read off the
response table of an orthogonal array instead of one-at-a-time runs.

Thresholds ("not felt"):

* Morris: ``mu*`` below ``threshold`` (default :data:`MORRIS_THRESHOLD`, 5 %) of the
  largest ``mu*`` of the same quantity;
* Sobol: total index ``ST`` below ``threshold`` (default :data:`SOBOL_THRESHOLD`, 0.01).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tsid_fmu.doe.arrays import OrthogonalArray, select_array
from tsid_fmu.errors import StudyError
from tsid_fmu.search.phases.contribution import parameter_contribution

__all__ = [
    "CONF_LEVEL",
    "METHODS",
    "MORRIS_LEVELS",
    "MORRIS_THRESHOLD",
    "SOBOL_THRESHOLD",
    "array_contribution",
    "array_design",
    "default_n",
    "design",
    "indices",
    "not_felt",
]

METHODS = ("morris", "sobol")
MORRIS_LEVELS = 4
"""Grid levels of the Morris trajectories (SALib's default)."""
MORRIS_THRESHOLD = 0.05
"""Morris: a parameter whose ``mu*`` is below this fraction of the largest is not felt."""
SOBOL_THRESHOLD = 0.01
"""Sobol: a parameter whose total index ``ST`` is below this is not felt."""
CONF_LEVEL = 0.95
"""Confidence level of the bootstrap intervals of the indices."""
CONTRIBUTION_LEVELS = 5
"""Levels per parameter of the array behind eq. (7) (an L25 for up to six parameters)."""


def _salib() -> Any:
    try:
        import SALib  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise StudyError(
            "sensitivity screening needs SALib: pip install 'tsid-fmu[screen]'"
        ) from exc


def default_n(method: str) -> int:
    """Default size of the design: trajectories (Morris) or base samples (Sobol).

    Morris: 20 trajectories, ``20 (k + 1)`` simulations (120 for five parameters,
    against about 400 for an identification of the SISO example). Sobol: 64 base
    samples, ``64 (k + 2)`` simulations: thorough, dearer.
    """
    return 20 if method == "morris" else 64


def _problem(names: Sequence[str]) -> dict[str, Any]:
    return {"num_vars": len(names), "names": list(names), "bounds": [[-0.5, 0.5]] * len(names)}


def design(method: str, names: Sequence[str], n: int, seed: int = 0) -> np.ndarray:
    """Return the sample points in search coordinates, shape ``(runs, k)``.

    Parameters
    ----------
    method : {"morris", "sobol"}
        The screening method.
    names : sequence of str
        Parameter names (at least two).
    n : int
        Morris trajectories (``n (k + 1)`` points) or Sobol base samples (a power of
        two; ``n (k + 2)`` points without second-order indices).
    seed : int
        Seed of the design, so a screening repeats exactly.
    """
    _salib()
    if method not in METHODS:
        raise StudyError(f"screening method must be one of {', '.join(METHODS)}, got {method!r}")
    if len(names) < 2:
        raise StudyError(f"screening needs at least two parameters, got {len(names)}")
    problem = _problem(names)
    if method == "morris":
        if n < 2:
            raise StudyError(f"Morris needs at least 2 trajectories, got n={n}")
        from SALib.sample import morris

        return morris.sample(problem, n, num_levels=MORRIS_LEVELS, seed=seed)
    if n < 2 or n & (n - 1):
        raise StudyError(f"Sobol needs a power of two base samples (n=32, 64, ...), got n={n}")
    from SALib.sample import sobol

    return sobol.sample(problem, n, calc_second_order=False, seed=seed)


def indices(
    method: str, names: Sequence[str], x: np.ndarray, y: np.ndarray, seed: int = 0
) -> dict[str, dict[str, float]]:
    """Return the indices of one screened quantity, per parameter.

    Parameters
    ----------
    method : {"morris", "sobol"}
        The screening method the design ``x`` was made for.
    names : sequence of str
        Parameter names, in the columns' order.
    x : numpy.ndarray
        The design (:func:`design`), shape ``(runs, k)``.
    y : numpy.ndarray
        The quantity at each point (finite), shape ``(runs,)``.
    seed : int
        Seed of the bootstrap of the confidence intervals.

    Returns
    -------
    dict
        Parameter -> Morris ``mu_star``, ``mu_star_conf``, ``sigma``, ``mu`` and
        ``mu_star_norm``, ``sigma_norm`` (over the largest ``mu*``); or Sobol ``S1``,
        ``S1_conf``, ``ST``, ``ST_conf``. A constant quantity has every index 0.
    """
    _salib()
    y = np.asarray(y, dtype=float)
    problem = _problem(names)
    if method == "morris":
        from SALib.analyze import morris

        got = morris.analyze(
            problem, x, y, num_levels=MORRIS_LEVELS, conf_level=CONF_LEVEL, seed=seed
        )
        top = float(np.max(got["mu_star"]))
        out = {}
        for j, name in enumerate(names):
            row = {k: float(got[k][j]) for k in ("mu_star", "mu_star_conf", "sigma", "mu")}
            row["mu_star_norm"] = row["mu_star"] / top if top > 0 else 0.0
            row["sigma_norm"] = row["sigma"] / top if top > 0 else 0.0
            out[name] = row
        return out
    if not np.ptp(y) > 0:  # no variance to share out
        return {n: {"S1": 0.0, "S1_conf": 0.0, "ST": 0.0, "ST_conf": 0.0} for n in names}
    from SALib.analyze import sobol

    got = sobol.analyze(problem, y, calc_second_order=False, conf_level=CONF_LEVEL, seed=seed)
    keys = ("S1", "S1_conf", "ST", "ST_conf")
    return {n: {k: float(got[k][j]) for k in keys} for j, n in enumerate(names)}


def not_felt(
    method: str, found: Mapping[str, Mapping[str, float]], threshold: float | None = None
) -> list[str]:
    """Return the parameters one quantity does not feel (see the module's thresholds)."""
    if method == "morris":
        limit = MORRIS_THRESHOLD if threshold is None else threshold
        return [n for n, v in found.items() if v["mu_star_norm"] < limit]
    limit = SOBOL_THRESHOLD if threshold is None else threshold
    return [n for n, v in found.items() if v["ST"] < limit]


def array_design(k: int) -> tuple[OrthogonalArray, np.ndarray]:
    """Return the array behind eq. (7) and its points in search coordinates.

    Five levels per parameter, evenly spaced over the first range (``-0.5 .. 0.5``):
    an L25 for up to six parameters, the smallest five-level array that hosts them
    otherwise.
    """
    array, columns = select_array([CONTRIBUTION_LEVELS] * k)
    levels = np.linspace(-0.5, 0.5, CONTRIBUTION_LEVELS)
    return array, levels[np.asarray(array.table)[:, columns]]


def array_contribution(s: np.ndarray, names: Sequence[str], y: np.ndarray) -> dict[str, float]:
    """Return eq. (7) of the MISO paper per parameter, from an array's runs.

    For each parameter, the costs are averaged per level (its response table); its
    "% of error variation" is ``(largest - smallest level mean) / mean cost x 100``
    (:func:`tsid_fmu.search.phases.contribution.parameter_contribution` on the level means,
    whose mean is that of all runs in a balanced array).

    Parameters
    ----------
    s : numpy.ndarray
        The array's points (:func:`array_design`), shape ``(runs, k)``.
    names : sequence of str
        Parameter names, in the columns' order.
    y : numpy.ndarray
        The quantity of each run (finite), shape ``(runs,)``.
    """
    y = np.asarray(y, dtype=float)
    values: dict[str, list[float]] = {}
    means: list[float] = []
    for j, name in enumerate(names):
        levels = sorted(set(s[:, j].tolist()))
        values[name] = levels
        means += [float(y[s[:, j] == v].mean()) for v in levels]
    centre = {n: 0.0 for n in names}
    if not np.mean(means) > 0:  # a quantity that is 0 everywhere: nothing to share out
        return {n: 0.0 for n in names}
    return dict(parameter_contribution(values, centre, means).percent)
