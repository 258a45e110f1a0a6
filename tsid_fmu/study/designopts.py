"""The ``[design]`` table: the family of experiments ``tsid design`` may propose.

An engineer at a rig can apply some inputs and not others: an actuator has force
limits, a heater a power range, a controller a sample rate. The table states them; the
design (:mod:`tsid_fmu.design`) only proposes signals inside them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.errors import StudyError
from tsid_fmu.study.checks import check_choice, check_number, check_whole

__all__ = ["CRITERIA", "KINDS", "LIMIT", "SAMPLES", "DesignOptions", "check_samples"]

LIMIT = 1e150
"""Largest magnitude of an input limit in ``[design] inputs``: beyond it a signal's
arithmetic (its middle, its half range, a derivative) overflows."""

SAMPLES = 1_000_000
"""Most samples a proposed record may have (``duration / sample_time``): every candidate
is simulated ``2p + 1`` times and held in memory."""

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
        FMU input -> ``[min, max]``, the values the rig can apply to it (within
        ±1e150). Default: each input of the template experiment, between the least and
        the largest value its data applied.
    band : list of float
        ``[f_min, f_max]`` in Hz: the frequencies the signals may carry, from one period
        per record up to the Nyquist frequency (half the sample rate). Default: from
        two periods per record to a twentieth of the sample rate (a record of more than
        40 samples).
    duration : float, optional
        Length of the proposed record (s); default the template experiment's. The
        record has 10 to 1,000,000 samples (``duration / sample_time``).
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
        if self.inputs is None:
            self.inputs = {}
        if not isinstance(self.inputs, Mapping):
            raise StudyError("[design] inputs must be a table: input = [min, max]")
        checked = {}
        for name, span in self.inputs.items():
            what = f"[design] inputs.{name}"
            pair = _sequence(span, what)
            if pair is None or len(pair) != 2:
                raise StudyError(f"{what} must be [min, max], got {span!r}")
            lo, hi = (check_number(v, what) for v in pair)
            if max(abs(lo), abs(hi)) >= LIMIT:
                raise StudyError(f"{what}: limits must lie within ±{LIMIT:g}, got [{lo:g}, {hi:g}]")
            if not lo < hi:
                raise StudyError(f"{what}: min {lo:.6g} is not below max {hi:.6g}")
            checked[str(name)] = [lo, hi]
        self.inputs = checked
        band = _sequence(self.band, "[design] band") if self.band is not None else []
        if band is None:
            raise StudyError(f"[design] band must be [f_min, f_max] in Hz, got {self.band!r}")
        if band:
            if len(band) != 2:
                raise StudyError(f"[design] band must be [f_min, f_max] in Hz, got {band}")
            lo, hi = (check_number(v, "[design] band") for v in band)
            if not 0 < lo < hi:
                raise StudyError(f"[design] band: need 0 < f_min < f_max, got [{lo:.6g}, {hi:.6g}]")
            self.band = [lo, hi]
        else:
            self.band = []
        for key in ("duration", "sample_time"):
            value = getattr(self, key)
            if value is not None:
                value = check_number(value, f"[design] {key}")
                if not 0 < value < math.inf:
                    raise StudyError(f"[design] {key} must be a positive number, got {value:.6g}")
                setattr(self, key, value)
        if self.duration is not None and self.sample_time is not None:
            check_samples(self.duration, self.sample_time)
        kinds = _sequence(self.kinds, "[design] kinds")
        if not kinds:
            raise StudyError(f"[design] kinds must be a non-empty list of {list(KINDS)}")
        self.kinds = list(kinds)
        self.kinds = [check_choice(k, "[design] kinds", KINDS) for k in self.kinds]
        self.criterion = check_choice(self.criterion, "[design] criterion", CRITERIA)
        self.bands = check_whole(self.bands, "[design] bands", 1, 12)
        self.seed = check_whole(self.seed, "[design] seed", 0)
        if not isinstance(self.experiment, str):
            raise StudyError("[design] experiment must be an experiment's name")


def _sequence(value: Any, what: str) -> list | None:
    """Return ``value``'s items as a list (a list, tuple or 1-d array); None for anything else.

    A mapping, a string or a set is no ``[a, b]``: iterating them gives keys or
    characters, or no order.
    """
    if isinstance(value, np.ndarray):
        if value.ndim != 1:
            raise StudyError(f"{what} must be a list, got an array of shape {value.shape}")
        return value.tolist()
    if isinstance(value, list | tuple):
        return list(value)
    return None


def check_samples(duration: float, sample_time: float) -> int:
    """Return the samples of a record of ``duration`` at ``sample_time`` (without the first).

    Raises
    ------
    StudyError
        Naming ``[design] duration`` and ``sample_time`` where there are fewer than 10 or
        more than :data:`SAMPLES` of them.
    """
    n = duration / sample_time  # both positive and finite: inf at worst, never an error
    if not 10 <= n <= SAMPLES:
        count = f"{n:.3g}" if math.isfinite(n) else "too many"
        raise StudyError(
            f"[design] duration {duration:.6g} s at sample_time {sample_time:.6g} s gives "
            f"{count} samples: a design needs 10 to {SAMPLES:,} (shorten duration or "
            "lengthen sample_time)"
        )
    return round(n)
