"""Typed outcomes of the local search: a stationarity test's verdict and why a refinement stopped.

A stage (:class:`~tsid_fmu.search.stage.StageResult`) carries them as attributes; the
trail and ``result.json`` keep them in the stage's ``extra`` under ``"stationarity"``
and ``"stop"`` (:meth:`Stationarity.to_dict`, :class:`LocalStop`'s value), and every
decision reads the attributes, never the JSON form.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

__all__ = ["GN_TEST", "GN_TRIED", "LocalStop", "SolverNotes", "Stationarity"]

GN_TEST = "projected Gauss-Newton"
"""The name of the projected Gauss-Newton test
(:func:`~tsid_fmu.search.verdict.gauss_newton_test`)."""

GN_TRIED = "projected Gauss-Newton, step tried"
"""Its name where it held by simulating its step (the model does not hold that close)."""


@dataclass
class Stationarity:
    """The outcome of a stationarity test at an answer.

    Attributes
    ----------
    holds : bool
        True where the test shows an optimum.
    test : str
        ``"projected Gauss-Newton"`` or ``"local probes"``.
    gap : float
        The decrease of the cost the test still sees (predicted, or found by a probe).
    cost : float
        The cost at the answer.
    detail : str
        One sentence for the log and the report.
    decided_by : {"model", "trial", "probe"}
        What decided it: the first-order model alone (no simulation), simulated steps
        along the model's step (the model does not hold this close), or local probes.
    lower : float
        How much a simulated step or probe lowered the cost, where that is more than
        the gate (0 otherwise: a point lower by no more than it refutes nothing): the
        test then fails with a lower point in hand.
    """

    holds: bool
    test: str
    gap: float
    cost: float
    detail: str
    decided_by: str = "model"
    lower: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form kept in a stage's ``extra["stationarity"]``."""
        return {
            "holds": self.holds,
            "test": self.test,
            "gap": self.gap if math.isfinite(self.gap) else None,
            "cost": self.cost if math.isfinite(self.cost) else None,
            "detail": self.detail,
            "decided_by": self.decided_by,
            "lower": self.lower,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | None) -> Stationarity | None:
        """Read back :meth:`to_dict`'s form (None where no test was made).

        A test written before ``decided_by`` existed reads as decided by the model,
        with no lower point.
        """
        if not data:
            return None

        def number(key: str) -> float:
            value = data.get(key)
            return math.inf if value is None else float(value)

        return cls(
            holds=bool(data.get("holds", False)),
            test=str(data.get("test", "")),
            gap=number("gap"),
            cost=number("cost"),
            detail=str(data.get("detail", "")),
            decided_by=str(data.get("decided_by", "model")),
            lower=float(data.get("lower") or 0.0),
        )

    @property
    def by_trial(self) -> bool:
        """Whether simulating its step decided it: held by a trial alone, or found lower.

        Held by a trial alone ("step tried": the first-order model does not hold this
        close to the answer), or failed with its step, simulated, lower: where the
        refinement in combinations (:mod:`~tsid_fmu.search.local.combined`) runs.
        """
        if self.test == GN_TRIED:
            return True
        return not self.holds and self.decided_by != "probe" and self.lower > 0


class LocalStop(StrEnum):
    """Why a refinement (or a refinement in combinations) stopped.

    ``GTOL``, ``FTOL``, ``XTOL``: a tolerance of the least-squares driver, SciPy's or
    the refinement's own on an accepted step; ``VALLEY``: it crawled along parallel
    Jacobian columns; ``WAYPOINT``: a horizon (a waypoint of the continuation, not an
    answer) ended at the first step that gained less than the stationarity gate's share
    of the cost; ``LIMIT``: it ran out of simulations; ``NONE``: none of these (SciPy's
    own evaluation limit, a failed solve, or a stage that is no refinement).
    """

    NONE = ""
    GTOL = "gtol"
    FTOL = "ftol"
    XTOL = "xtol"
    VALLEY = "valley"
    WAYPOINT = "waypoint"
    LIMIT = "limit"

    @property
    def unfinished(self) -> bool:
        """Whether the refinement's own tests did not end it: it crawled or ran out of runs.

        It crawled along parallel columns (:mod:`~tsid_fmu.search.local.problem`), or it
        ran out of runs. Where its last Jacobian has parallel columns, the refinement in
        their combination (:mod:`~tsid_fmu.search.local.combined`) follows whatever its
        stationarity test said: that test's linear model sees only the valley's local
        slope. Measured on the SISO plant's damped law 2 (``structure_damping.py``, seed
        2): a structure candidate's refinement out of runs at 1.0027 times the
        least-squares cost, whose Gauss-Newton step predicted a decrease of 1.75 against a
        gate of 1.85, held its test and was chosen there; another run's arithmetic,
        predicting 2.12, had failed it and gone on to the optimum.
        """
        return self in (LocalStop.VALLEY, LocalStop.LIMIT)


@dataclass
class SolverNotes:
    """What the least-squares solver of a refinement reported, for the report.

    Attributes
    ----------
    method : str
        The solver, e.g. ``"scipy.optimize.least_squares(method='trf')"``.
    nfev, njev : int or None
        SciPy's own counts of residual and Jacobian evaluations (the simulations are
        the stage's ``nfev``).
    first_pass : dict or None
        Where a second pass with wider difference steps ran: the first pass's stop and
        counts.
    off_the_floor : dict or None
        Where the answer sat on a log floor: the parameters, and the cost the test in
        linear coordinates reached.
    """

    method: str = ""
    nfev: int | None = None
    njev: int | None = None
    first_pass: dict[str, Any] | None = None
    off_the_floor: dict[str, Any] | None = None
