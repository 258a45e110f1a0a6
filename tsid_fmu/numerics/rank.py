"""The rank threshold the search and the uncertainty share."""

from __future__ import annotations

__all__ = ["UNSEEN"]

UNSEEN = 1e-14
"""Share of the largest eigenvalue of ``J^T J`` below which a direction is unseen: a
singular value of the Jacobian at most ``sqrt(UNSEEN)`` = 1e-7 of the largest is one
the outputs do not depend on (:func:`tsid_fmu.uncertainty.intervals.seen_inverse`)."""
