"""Parameters whose effects are parallel: pairs of Jacobian columns at the same angle.

Where two parameters act on the outputs only through a combination (a viscous friction
coefficient and a spring's damping, on a motion that depends on their sum), their
Jacobian columns are parallel. The angle between two columns does not depend on the
columns' scales, so a Jacobian in any coordinates that are a function of one parameter
each (the search's logarithmic ones, or the parameters' own) finds the same pairs; the
ratio of the pair's effects is read in the parameters' own units.
:mod:`~tsid_fmu.search.local.combined` refines in those combinations.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tsid_fmu.numerics.tuning import EXACT, PARALLEL
from tsid_fmu.search.space import Space

__all__ = ["EXACT", "PARALLEL", "named_pairs", "parallel_pairs"]


def parallel_pairs(jac: np.ndarray, tol: float = PARALLEL) -> list[tuple[int, int, float]]:
    """Return disjoint pairs ``(i, j, a)`` of parallel columns, ``jac[:, j] ~ a jac[:, i]``.

    The most nearly parallel first; each column in one pair at most. Exactly parallel
    columns (:data:`EXACT`) are not such a pair: there is no valley along them.
    """
    norms = np.linalg.norm(jac, axis=0)
    found = []
    for i in range(jac.shape[1]):
        for j in range(i + 1, jac.shape[1]):
            if norms[i] > 0 and norms[j] > 0:
                cos = float(jac[:, i] @ jac[:, j]) / (norms[i] * norms[j])
                if EXACT < 1.0 - abs(cos) < tol:
                    found.append((1.0 - abs(cos), i, j))
    used: set[int] = set()
    out = []
    for _, i, j in sorted(found):
        if i not in used and j not in used:
            used |= {i, j}
            out.append((i, j, float(jac[:, i] @ jac[:, j]) / float(jac[:, i] @ jac[:, i])))
    return out


def named_pairs(space: Space, x: Mapping[str, float], jac: np.ndarray) -> list[list]:
    """Return the parallel pairs of a Jacobian in ``space``'s coordinates, by name.

    Each as ``[name_i, name_j, a]``, with ``a`` the ratio of the columns per unit of the
    parameters themselves (the search coordinates' local scales at ``x`` divided out):
    the form a refinement keeps as its ``parallel`` (:class:`~tsid_fmu.search.stage.StageResult`).
    """
    scales = np.array([space.local_scale(k, float(x[n])) for k, n in enumerate(space.names)])
    physical = np.asarray(jac, float) / np.where(scales > 0, scales, 1.0)
    names = space.names
    return [[names[i], names[j], a] for i, j, a in parallel_pairs(physical)]
