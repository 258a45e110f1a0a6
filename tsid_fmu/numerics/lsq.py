"""The one least-squares driver: SciPy's trust-region reflective method, typed outcome.

The refinement (:mod:`tsid_fmu.search.local.refine`), the refinement in combinations
(:mod:`tsid_fmu.search.local.combined`) and the nesting fit of structure
identification (:mod:`tsid_fmu.search.structure.nesting`) all run
:func:`trust_region`. It calls :func:`scipy.optimize.least_squares` with
``method="trf"`` and the caller's Jacobian (every one a :func:`~tsid_fmu.numerics.fdstep.
forward_jacobian`), and says why it stopped as a :class:`Stop`, never by a message:

- SciPy's own tests (``gtol``, ``ftol``, ``xtol``) or its ``max_nfev``;
- an exception of the caller's, raised from its residuals or Jacobian to stop early
  (a simulation budget, an accepted step that meets a tolerance, a fit that is good
  enough): it is kept as :attr:`Solved.raised`;
- SciPy could not go on (a Jacobian it cannot factor: failed runs beside finite ones),
  with its error's text in :attr:`Solved.error`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

__all__ = ["Solved", "Stop", "trust_region"]


class Stop(StrEnum):
    """Why :func:`trust_region` stopped."""

    GTOL = "gtol"
    FTOL = "ftol"
    XTOL = "xtol"
    MAX_NFEV = "max_nfev"
    RAISED = "raised"
    FAILED = "failed"


_STATUS = {0: Stop.MAX_NFEV, 1: Stop.GTOL, 2: Stop.FTOL, 3: Stop.XTOL, 4: Stop.XTOL}
"""SciPy's ``status`` codes (4: both ``ftol`` and ``xtol`` held, taken as ``xtol``)."""


@dataclass
class Solved:
    """What :func:`trust_region` ended with.

    Attributes
    ----------
    stop : Stop
        Why it stopped.
    x, fun, jac : numpy.ndarray or None
        SciPy's answer, its residuals and the last Jacobian; None where it did not
        return (``stop`` RAISED or FAILED): the caller keeps its own best point.
    nfev, njev : int
        SciPy's counts of residual and Jacobian evaluations (0 where it did not return).
    raised : BaseException or None
        The caller's exception that stopped it (``stop`` RAISED).
    error : str
        SciPy's error (``stop`` FAILED), else empty.
    """

    stop: Stop
    x: np.ndarray | None = None
    fun: np.ndarray | None = None
    jac: np.ndarray | None = None
    nfev: int = 0
    njev: int = 0
    raised: BaseException | None = None
    error: str = ""


def trust_region(
    fun: Callable[[np.ndarray], np.ndarray],
    z0: np.ndarray,
    jac: Callable[[np.ndarray], np.ndarray],
    *,
    bounds: tuple[Any, Any] = (-np.inf, np.inf),
    stops: tuple[type[BaseException], ...] = (),
    **options: Any,
) -> Solved:
    """Run SciPy's trust-region least squares from ``z0``; return a :class:`Solved`.

    Parameters
    ----------
    fun, jac : callable
        Residuals and their Jacobian at a point.
    z0 : numpy.ndarray
        The start, within ``bounds``.
    bounds : tuple
        Lower and upper bounds, as SciPy takes them.
    stops : tuple of exception types
        The caller's exceptions that end the run early (:attr:`Solved.raised`).
    **options
        ``ftol``, ``xtol``, ``gtol``, ``x_scale``, ``max_nfev``, passed to SciPy as
        given (its defaults otherwise).

    Returns
    -------
    Solved
    """
    from scipy.optimize import least_squares

    try:
        out = least_squares(fun, z0, jac=jac, bounds=bounds, method="trf", **options)
    except stops as exc:
        return Solved(Stop.RAISED, raised=exc)
    except (ValueError, np.linalg.LinAlgError) as exc:
        return Solved(Stop.FAILED, error=str(exc))
    return Solved(
        _STATUS.get(int(out.status), Stop.FAILED),
        x=np.asarray(out.x, dtype=float),
        fun=np.asarray(out.fun, dtype=float),
        jac=np.asarray(out.jac, dtype=float),
        nfev=int(out.nfev),
        njev=int(out.njev or 0),
    )
