"""What a solver-fidelity check found, and what a study keeps of it.

:class:`Fidelity` is the answer of :func:`~tsid_fmu.uncertainty.fidelity.check_fidelity`;
the functions here put it into a result (``result.fidelity``, the warnings) and read
back what later commands reuse: the interface and the Co-Simulation tolerance the study
chose. They live apart from the check so that readers of a result need not import it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.numerics.space import Space
from tsid_fmu.numerics.tuning import THRESHOLD
from tsid_fmu.study.definition import Study
from tsid_fmu.uncertainty.solvers import Deviation, Solver

__all__ = [
    "THRESHOLD",
    "Fidelity",
    "chosen_cs_tolerance",
    "chosen_interface",
    "fidelity_record",
    "fidelity_warnings",
    "start_point",
    "study_noise",
]


@dataclass
class Fidelity:
    """What :func:`~tsid_fmu.uncertainty.fidelity.check_fidelity` found at one parameter set.

    Attributes
    ----------
    where : str
        ``"start point"`` or ``"answer"``.
    x : dict
        The parameter set simulated.
    requested : str
        The study's interface (``"auto"``, ``"cs"`` or ``"me"``).
    interface : str
        The interface the study uses after the check (``"cs"`` or ``"me"``).
    reference : Solver or None
        The reference solution's solver (None: nothing to compare with).
    used : Deviation or None
        The study's solver against the reference.
    alternatives : list of Deviation
        Other solvers tried because the difference mattered.
    threshold : float
        :data:`THRESHOLD`.
    matters : bool
        The study's solver differs from the reference by more than the threshold, or
        its difference moves an estimate by more than
        :data:`~tsid_fmu.uncertainty.fidelity.BIAS_LIMIT` standard errors.
    bias : dict
        At the answer: how many standard errors the difference moves each estimate
        (:func:`~tsid_fmu.uncertainty.solvers.solver_bias`); empty at the start point.
    message : str
        One line with the figures (and the fix when it matters).
    simulations : int
        Simulations the check ran.
    seconds : float
        Their wall time.
    step : float or None
        The study's step (None: the data's sample interval).
    converges : bool or None
        A Co-Simulation-only FMU whose difference mattered: whether its outputs
        settle as the step shrinks (:data:`~tsid_fmu.uncertainty.fidelity.CONVERGES`);
        None when not tested.
    cs_tolerance : float or None
        The tolerance of the FMU's own Co-Simulation solver the study uses after the
        check: its own ``cs_tolerance``, :data:`~tsid_fmu.uncertainty.fidelity.CS_TOLERANCE`
        where the check adopted it
        (:func:`~tsid_fmu.uncertainty.fidelity.choose_cs_tolerance`), None where none is
        passed (the FMU's default).
    """

    where: str
    x: dict[str, float]
    requested: str
    interface: str
    reference: Solver | None = None
    used: Deviation | None = None
    alternatives: list[Deviation] = field(default_factory=list)
    threshold: float = THRESHOLD
    matters: bool = False
    bias: dict[str, float] = field(default_factory=dict)
    message: str = ""
    simulations: int = 0
    seconds: float = 0.0
    step: float | None = None
    converges: bool | None = None
    cs_tolerance: float | None = None

    @property
    def checked(self) -> bool:
        """True when the comparison ran (no simulation failed)."""
        return self.used is not None

    @property
    def switched(self) -> bool:
        """True when the study changed solver after this check.

        Another interface (``"auto"``), or a tighter tolerance for the FMU's own
        Co-Simulation solver (:attr:`adopted`).
        """
        return self.used is not None and (
            self.interface != self.used.solver.interface or self.adopted
        )

    @property
    def adopted(self) -> bool:
        """True when the study passes a tighter ``cs_tolerance`` since this check."""
        used = self.used
        return (
            used is not None
            and self.interface == "cs"
            and used.solver.interface == "cs"
            and self.cs_tolerance != used.solver.tolerance
        )

    def to_dict(self) -> dict[str, Any]:
        """Return strict-JSON data (for ``result.json``)."""
        return {
            "where": self.where,
            "x": self.x,
            "requested": self.requested,
            "interface": self.interface,
            "step": self.step,
            "reference": self.reference.label if self.reference else None,
            "used": self.used.to_dict() if self.used else None,
            "alternatives": [a.to_dict() for a in self.alternatives],
            "threshold": self.threshold,
            "matters": self.matters,
            "bias": self.bias,
            "message": self.message,
            "simulations": self.simulations,
            "seconds": self.seconds,
            "converges": self.converges,
            "cs_tolerance": self.cs_tolerance,
        }


def start_point(study: Study) -> dict[str, float]:
    """Return the centre of a study's first levels (search coordinates 0).

    With an open choice among FMU files, the point names the study's ``fmu`` among them
    (the first file where ``fmu`` is none of them): a set simulates only in the variant
    it names, and the check runs in that one.
    """
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    x = space.to_x(np.zeros(space.dim))
    v = study.variants
    if v is not None and v.name not in study.start_values:  # both already resolved
        x[v.name] = float(v.paths.index(study.fmu)) if study.fmu in v.paths else v.values[0]
    return x


def study_noise(study: Study) -> dict[str, dict[str, float]]:
    """Return the known sensor noise of each experiment's outputs (``noise = {...}``)."""
    return {e.name: dict(e.noise) for e in study.experiments}


def fidelity_record(start: Fidelity, answer: Fidelity | None) -> dict[str, Any]:
    """Return ``result.fidelity``: the interface used, why, and both checks."""
    return {
        "requested": start.requested,
        "interface": start.interface,
        "step": start.step,
        "cs_tolerance": start.cs_tolerance,
        "threshold": start.threshold,
        "reason": start.message,
        "start": start.to_dict(),
        "answer": answer.to_dict() if answer is not None else None,
    }


def chosen_interface(fidelity: Mapping[str, Any] | None) -> str | None:
    """Return the interface a result's fidelity check chose, or ``None`` where none ran.

    ``fidelity`` is ``result.fidelity`` (or ``result.json``'s ``["extra"]["fidelity"]``).
    Whatever simulates at the answer again (``tsid simulate --result``, ``tsid design``)
    uses it: OpenModelica's ``Mass_Damper`` simulated by its Co-Simulation (a fixed
    explicit Euler step) left residuals 330 times the noise where the identification had
    chosen Model Exchange.
    """
    return (fidelity or {}).get("interface")


def chosen_cs_tolerance(fidelity: Mapping[str, Any] | None) -> float | None:
    """Return the Co-Simulation tolerance a result's fidelity check chose (or the study's).

    None where none was passed or no check ran; whatever simulates at the answer again
    uses it, as :func:`chosen_interface`.
    """
    return (fidelity or {}).get("cs_tolerance")


def fidelity_warnings(start: Fidelity, answer: Fidelity | None) -> list[str]:
    """Return the warnings of the checks: the answer's, else the start point's.

    A difference that ``"auto"`` removed by switching the interface is no warning (it is
    recorded); a check that could not run is, and so is an FMU whose outputs depend on
    the step by design (the data must then be sampled at the FMU's step).
    """
    last = answer if answer is not None else start
    if not last.checked or (last.matters and not last.switched) or last.converges is False:
        return [last.message]
    return []
