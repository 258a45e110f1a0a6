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

from tsid_fmu.numerics.rank import UNSEEN
from tsid_fmu.search.space import Space

__all__ = ["EXACT", "PARALLEL", "named_pairs", "parallel_pairs"]

PARALLEL = 1e-2
"""Two Jacobian columns are taken as parallel where ``1 - |cos|`` of their angle is below
this. Measured on the SISO plant at law 3's answers (dev seeds 101 to 103), with relative
forward-difference steps: viscous friction and spring damping 1.7e-4 to 1.0e-3 (event
noise: their different steps shift different events; with steps matched to their sum,
4e-9 to 6e-8), every other pair 0.03 or more. A pair taken wrongly costs the runs of
:func:`~tsid_fmu.search.local.combined.combined_refinement`, whose answer is kept only where it
is lower."""


EXACT = 2.0 * UNSEEN
"""Two columns closer than this (``1 - |cos|``) are exactly parallel: the smallest
eigenvalue of their Gram matrix is then at most
:data:`~tsid_fmu.numerics.rank.UNSEEN` of the largest, so the direction along the
pair is one the outputs do not see at all, with no slope to follow (OpenModelica's
``Mass_Damper``: its three offsets and the force act only through their sum, ``1 - |cos|``
of 0 to 4e-16). The covariance reports it open; a refinement along it only wanders
(measured there: the force moved from 1 N to -8839 N for a gain of 4e-6 of the cost, 90
runs, and left an offset by its logarithmic floor, where the profiles then closed the
common scale of mass, damping and stiffness around a point away from the truth)."""


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
