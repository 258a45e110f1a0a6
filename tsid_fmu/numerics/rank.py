"""The rank threshold the search and the uncertainty share."""

from __future__ import annotations

import math

import numpy as np

from tsid_fmu.numerics.tuning import UNSEEN

__all__ = ["UNSEEN", "unseen_columns"]


def unseen_columns(jacobian: np.ndarray) -> np.ndarray:
    """Return which columns of ``jacobian`` are zero to rank (the outputs ignore them).

    A column of norm at most ``sqrt(UNSEEN)`` of the largest; non-finite entries count
    as 0. Every column is unseen where all are 0. One rule for the refinement, which
    holds such a parameter where it is (:mod:`tsid_fmu.search.local.problem`), and for
    the report's "no effect" (:func:`tsid_fmu.uncertainty.bounds.inert_parameters`).
    """
    jac = np.asarray(jacobian, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        norms = np.linalg.norm(np.where(np.isfinite(jac), jac, 0.0), axis=0)
    top = float(norms.max()) if norms.size else 0.0
    if not top > 0:
        return np.ones(jac.shape[1], dtype=bool)
    return norms <= math.sqrt(UNSEEN) * top
