"""A study is a sequence of named stages; each records its own answer."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from tsid_fmu.search.outcome import LocalStop, Stationarity
from tsid_fmu.search.record import IterationRecord, json_float, unjson_float

__all__ = ["KINDS", "StageResult"]

KINDS = (
    "taguchi",
    "refinement",
    "phase",
    "contribution",
    "check",
    "horizon",
    "structure",
    "candidate",
    "comparison",
)
"""Kinds of stage: the papers' Taguchi procedure; an optional local least-squares polish;
a phase of a phased (MISO) study, itself a Taguchi procedure on a parameter group; the
MISO paper's one-at-a-time contribution runs; the local probe test of an answer that no
refinement tested (:mod:`tsid_fmu.search.verdict`); in structure identification, the mixed
arrays of Real and discrete factors, one stage per candidate structure not chosen, and
the comparison of the structures (:mod:`tsid_fmu.search.structure.compare`)."""


@dataclass
class StageResult:
    """What one stage did.

    Attributes
    ----------
    name : str
        ``"taguchi"``, ``"refinement"``, ``"phase 1: m1, K_s"``, ...
    kind : str
        One of :data:`KINDS`.
    x : dict
        The stage's answer (the best parameter set it saw, including the parameters it
        did not vary).
    cost : float
        The study's cost of ``x`` on the measured inputs of the stage's experiments.
    nfev : int
        Simulations the stage ran.
    message : str
        Why it stopped.
    status : int
        0 converged, 1 stopped at a limit, 2 paused for review.
    records : list of IterationRecord
        Its Taguchi iterations (empty for a refinement).
    experiments : list of str
        The experiments the stage fitted.
    extra : dict
        Stage-specific details for the report and the trail (a refinement's counts, a
        phase's parameters); no decision of the search reads them.
    stationarity : Stationarity or None
        The stationarity test made at the answer (None where none was made); written
        into ``extra["stationarity"]`` by :meth:`to_dict`.
    stop : LocalStop
        Why a refinement stopped (``LocalStop.NONE`` for other stages); written into
        ``extra["stop"]``.
    parallel : list or None
        A refinement's last Jacobian's parallel pairs, ``[name_i, name_j, ratio]`` each,
        kept where the refinement in combinations reads them
        (:mod:`~tsid_fmu.search.local.combined`); None where none were kept.
        ``extra["parallel"]``.
    pairs : list or None
        The combinations this stage refined in, in the same form; None for a stage that
        did not. ``extra["pairs"]``.
    agrees : str
        The stage whose answer this one (the refinement after the horizons) reached
        again ("" where none). ``extra["agrees"]``.
    """

    name: str
    kind: str
    x: dict[str, float]
    cost: float
    nfev: int
    message: str
    status: int = 0
    records: list[IterationRecord] = field(default_factory=list)
    experiments: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    stationarity: Stationarity | None = None
    stop: LocalStop = LocalStop.NONE
    parallel: list[list] | None = None
    pairs: list[list] | None = None
    agrees: str = ""

    @property
    def converged(self) -> bool:
        """True if the stage stopped because it converged."""
        return self.status == 0

    def to_dict(self) -> dict[str, Any]:
        """Return the summary written into ``result.json`` (records are kept apart)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "x": dict(self.x),
            "cost": json_float(self.cost),
            "nfev": self.nfev,
            "message": self.message,
            "status": self.status,
            "iterations": len(self.records),
            "experiments": list(self.experiments),
            "extra": self._extra_json(),
        }

    def _extra_json(self) -> dict[str, Any]:
        """Return ``extra`` with the typed outcomes in their JSON form."""
        out = dict(self.extra)
        if self.stationarity is not None:
            out["stationarity"] = self.stationarity.to_dict()
        if self.stop is not LocalStop.NONE or self.kind == "refinement":
            out["stop"] = self.stop.value
        for key in ("parallel", "pairs"):
            if getattr(self, key) is not None:
                out[key] = [list(p) for p in getattr(self, key)]
        if self.agrees:
            out["agrees"] = self.agrees
        return out

    @classmethod
    def from_dict(
        cls, d: Mapping[str, Any], records: list[IterationRecord] | None = None
    ) -> StageResult:
        """Re-create a stage written by :meth:`to_dict`, with its records.

        An unknown ``stop`` (a trail written by another version) reads as ``NONE``.
        """
        extra = dict(d.get("extra", {}))
        test = Stationarity.from_dict(extra.pop("stationarity", None))
        stop = str(extra.pop("stop", "") or "")
        parallel, pairs = extra.pop("parallel", None), extra.pop("pairs", None)
        return cls(
            name=str(d["name"]),
            kind=str(d["kind"]),
            x={k: float(v) for k, v in d["x"].items()},
            cost=unjson_float(d["cost"]),
            nfev=int(d["nfev"]),
            message=str(d["message"]),
            status=int(d.get("status", 0)),
            records=list(records or []),
            experiments=list(d.get("experiments", [])),
            extra=extra,
            stationarity=test,
            stop=LocalStop(stop) if stop in set(LocalStop) else LocalStop.NONE,
            parallel=[list(p) for p in parallel] if parallel is not None else None,
            pairs=[list(p) for p in pairs] if pairs is not None else None,
            agrees=str(extra.pop("agrees", "") or ""),
        )
