"""The ``[design]`` table: the family of experiments ``tsid design`` may propose.

An engineer at a rig can apply some inputs and not others: an actuator has force
limits, a heater a power range, a controller a sample rate. The table states them; the
design (:mod:`tsid_fmu.design`) only proposes signals inside them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from tsid_fmu.errors import StudyError
from tsid_fmu.study.checks import check_choice, check_number, check_whole

__all__ = ["CRITERIA", "KINDS", "DesignOptions"]

KINDS = ("steps", "chirp", "multisine", "prbs")
"""Signal kinds a design may propose (:mod:`tsid_fmu.design.signals`)."""

CRITERIA = ("D", "A")
"""``criterion``: D-optimal over every parameter, or A-optimal on the weak combinations."""


@dataclass
class DesignOptions:
    """What experiments ``tsid design`` may propose, and how it ranks them.

    Parameters
    ----------
    inputs : mapping of str to list of float
        FMU input -> ``[min, max]``, the values the rig can apply to it. Default: each
        input of the template experiment, between the least and the largest value its
        data applied.
    band : list of float
        ``[f_min, f_max]`` in Hz: the frequencies the signals may carry. Default: from
        two periods per record to a twentieth of the sample rate.
    duration : float, optional
        Length of the proposed record (s); default the template experiment's.
    sample_time : float, optional
        Sample interval of the proposed input (s); default the template experiment's.
    kinds : list of str
        Signal kinds allowed: ``steps`` (square waves), ``chirp`` (a logarithmic
        sweep), ``multisine`` (Schroeder-phased, flat spectrum), ``prbs`` (a
        pseudo-random binary sequence). Default all four.
    criterion : {"D", "A"}
        ``D`` (the default) maximises the determinant of the Fisher matrix of every
        parameter, in the search coordinates (so the choice does not depend on units):
        it shrinks the joint confidence region most, and gains most where the study is
        weakest. ``A`` minimises the summed variances of the combinations the study
        leaves weak (every combination, where none is weak): a targeted design for a
        user who needs one quantity and not the others.
    bands : int
        How many sub-bands of ``band`` each kind is tried in (and square waves at as
        many frequencies); the candidates are ``bands`` plus the whole band, per kind.
    seed : int
        Seed of the random phases and sequences, so that a design is reproduced.
    experiment : str
        The template experiment: its outputs, sensors' noise, initial states and
        settings are those of the proposed one. Default the study's first
        identification experiment.
    """

    inputs: dict[str, list[float]] = field(default_factory=dict)
    band: list[float] = field(default_factory=list)
    duration: float | None = None
    sample_time: float | None = None
    kinds: list[str] = field(default_factory=lambda: list(KINDS))
    criterion: str = "D"
    bands: int = 3
    seed: int = 0
    experiment: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.inputs, dict):
            raise StudyError("[design] inputs must be a table: input = [min, max]")
        checked = {}
        for name, span in self.inputs.items():
            what = f"[design] inputs.{name}"
            if isinstance(span, str | bytes) or not hasattr(span, "__len__") or len(span) != 2:
                raise StudyError(f"{what} must be [min, max], got {span!r}")
            lo, hi = (check_number(v, what) for v in span)
            if not lo < hi:
                raise StudyError(f"{what}: min {lo} is not below max {hi}")
            checked[str(name)] = [lo, hi]
        self.inputs = checked
        if self.band:
            if len(self.band) != 2:
                raise StudyError(f"[design] band must be [f_min, f_max] in Hz, got {self.band}")
            lo, hi = (check_number(v, "[design] band") for v in self.band)
            if not 0 < lo < hi:
                raise StudyError(f"[design] band: need 0 < f_min < f_max, got [{lo}, {hi}]")
            self.band = [lo, hi]
        for key in ("duration", "sample_time"):
            value = getattr(self, key)
            if value is not None:
                value = check_number(value, f"[design] {key}")
                if not 0 < value < math.inf:
                    raise StudyError(f"[design] {key} must be a positive number, got {value}")
                setattr(self, key, value)
        if isinstance(self.kinds, str) or not self.kinds:
            raise StudyError(f"[design] kinds must be a non-empty list of {list(KINDS)}")
        self.kinds = [check_choice(k, "[design] kinds", KINDS) for k in self.kinds]
        self.criterion = check_choice(self.criterion, "[design] criterion", CRITERIA)
        self.bands = check_whole(self.bands, "[design] bands", 1, 12)
        self.seed = check_whole(self.seed, "[design] seed", 0)
        if not isinstance(self.experiment, str):
            raise StudyError("[design] experiment must be an experiment's name")
