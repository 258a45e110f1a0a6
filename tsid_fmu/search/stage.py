"""A study is a sequence of named stages; each records its own answer."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from tsid_fmu.search.outcome import LocalStop, SolverNotes, Stationarity
from tsid_fmu.search.phases.contribution import Contribution
from tsid_fmu.search.record import (
    IterationRecord,
    Kept,
    json_float,
    kept_json,
    kept_values,
    spread,
    unjson_float,
)
from tsid_fmu.study.schema import Phase

__all__ = ["KINDS", "StageKind", "StageResult"]


class StageKind(StrEnum):
    """The kind of a stage; its value is what ``result.json`` and the trail write.

    A :class:`~enum.StrEnum`, so a kind equals its string (``StageKind.TAGUCHI ==
    "taguchi"``) and reads back from it; the search decides by the members, never by a
    string it spells itself.
    """

    TAGUCHI = "taguchi"
    """The papers' Taguchi procedure (orthogonal arrays, S/N ratios, re-leveling)."""
    REFINEMENT = "refinement"
    """A local least-squares refinement (a restart is one too)."""
    PHASE = "phase"
    """A phase of a phased (MISO) study: a Taguchi procedure on a parameter group."""
    CONTRIBUTION = "contribution"
    """The MISO paper's one-at-a-time contribution runs."""
    CHECK = "check"
    """The local probe test of an answer no refinement tested (:mod:`~tsid_fmu.search.verdict`)."""
    HORIZON = "horizon"
    """A refinement on the first share of the samples (a waypoint of a continuation)."""
    STRUCTURE = "structure"
    """Structure identification: the mixed arrays of Real and discrete factors."""
    CANDIDATE = "candidate"
    """Structure identification: a candidate structure not chosen, at its own optimum."""
    COMPARISON = "comparison"
    """Structure identification: the comparison of the candidates (:mod:`.structure.compare`)."""


KINDS = tuple(k.value for k in StageKind)
"""The kinds' values, in :class:`StageKind`'s order."""


@dataclass
class StageResult:
    """What one stage did.

    Attributes
    ----------
    name : str
        ``"taguchi"``, ``"refinement"``, ``"phase 1: m1, K_s"``, ...
    kind : StageKind
        What the stage is (given as a member or its string).
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
        The stationarity test made at the answer (None where none was made).
    stop : LocalStop
        Why a refinement stopped (``LocalStop.NONE`` for other stages).
    parallel : list or None
        A refinement's last Jacobian's parallel pairs, ``[name_i, name_j, ratio]`` each,
        kept where the refinement in combinations reads them
        (:mod:`~tsid_fmu.search.local.combined`); None where none were kept.
    pairs : list or None
        The combinations this stage refined in, in the same form; None for a stage that
        did not.
    agrees : str
        The stage whose answer this one (the refinement after the horizons) reached
        again ("" where none).
    start : dict or None
        Where a local stage started (a finished one from the same start is read back
        on ``--resume``); None where not recorded.
    start_cost : float or None
        The cost there.
    start_from : str
        Where that start came from, in words ("" where not said).
    resumed : str
        Why a handed-over Taguchi stage was continued ("" where it was not).
    crawled : dict or None
        A refinement that stopped in a valley and was continued in the combinations: the
        first part's stop, test, cost, simulations and answer (JSON form).
    poor_fit : dict or None
        An answer still far above the noise floor after the search: ``{"floor",
        "ratio", "restarts", "horizons_agree"}`` (the warning of
        :func:`tsid_fmu.weak.poor_fit`).
    phases : list of Phase or None
        The phases a ``contribution`` stage planned (MISO paper), in order.
    held : list of str
        The parameters a refinement held to its end: the outputs do not depend on them.
    contribution : Contribution or None
        A ``contribution`` stage's tables (kept as ``extra``'s ``input``, ``percent``,
        ``runs`` and ``groups``).
    solver : SolverNotes or None
        What a refinement's solver reported (kept as ``extra``'s ``method``, ``nfev``,
        ``njev``, ``first_pass`` and ``off_the_floor``).
    fraction : float or None
        The share of each experiment's samples a ``horizon`` stage fitted.

    The typed attributes are kept in ``extra`` under their own names in ``result.json``
    and the trail, by :meth:`to_dict` and :meth:`from_dict` alone.
    """

    name: str
    kind: StageKind
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
    start: dict[str, float] | None = None
    start_cost: float | None = None
    start_from: str = ""
    resumed: str = ""
    crawled: dict[str, Any] | None = None
    poor_fit: dict[str, Any] | None = None
    phases: list[Phase] | None = None
    held: list[str] = field(default_factory=list)
    contribution: Contribution | None = None
    solver: SolverNotes | None = None
    fraction: float | None = None

    def __post_init__(self) -> None:
        self.kind = StageKind(self.kind)  # a string reads as its member; another is an error

    @property
    def converged(self) -> bool:
        """True if the stage stopped because it converged."""
        return self.status == 0

    def to_dict(self) -> dict[str, Any]:
        """Return the summary written into ``result.json`` (records are kept apart)."""
        return {
            "name": self.name,
            "kind": str(self.kind),
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
        out = kept_json(self, _KEPT, self.extra)
        if self.kind == StageKind.REFINEMENT:
            out["stop"] = self.stop.value  # a refinement always says why it stopped
        return out

    @classmethod
    def from_dict(
        cls, d: Mapping[str, Any], records: list[IterationRecord] | None = None
    ) -> StageResult:
        """Re-create a stage written by :meth:`to_dict`, with its records.

        An unknown ``stop`` (a trail written by another version) reads as ``NONE``.
        """
        extra = dict(d.get("extra", {}))
        return cls(
            name=str(d["name"]),
            kind=StageKind(d["kind"]),
            x={k: float(v) for k, v in d["x"].items()},
            cost=unjson_float(d["cost"]),
            nfev=int(d["nfev"]),
            message=str(d["message"]),
            status=int(d.get("status", 0)),
            records=list(records or []),
            experiments=list(d.get("experiments", [])),
            **kept_values(extra, _KEPT),
            extra=extra,
        )


_STOPS = frozenset(LocalStop)


def _stop(v: Any) -> LocalStop:
    """Read a ``stop`` back; one another version wrote reads as ``NONE``."""
    return LocalStop(v) if v in _STOPS else LocalStop.NONE


def _pairs(v: list) -> list[list]:
    return [list(p) for p in v]


def _point(v: Mapping[str, float]) -> dict[str, float]:
    return {str(k): float(x) for k, x in v.items()}


def _cost(v: float | None) -> float | None:
    return json_float(v) if v is not None else None


def _phases_json(v: list[Phase]) -> list[dict[str, Any]]:
    return [dataclasses.asdict(p) for p in v]


def _phases(v: list[Mapping[str, Any]]) -> list[Phase]:
    return [Phase(**p) for p in v]


_KEPT = (
    Kept("stationarity", "stationarity", Stationarity.to_dict, Stationarity.from_dict),
    Kept("stop", "stop", lambda s: s.value, _stop),
    Kept("parallel", "parallel", _pairs, _pairs),
    Kept("pairs", "pairs", _pairs, _pairs),
    Kept("agrees", "agrees", str, str),
    Kept("start", "start", _point, _point),
    Kept("start_cost", "start_cost", _cost, float),
    Kept("start_from", "start_from", str, str),
    Kept("resumed", "resumed", str, str),
    Kept("crawled", "crawled", dict, dict),
    Kept("poor_fit", "poor_fit", dict, dict),
    Kept("phases", "phases", _phases_json, _phases),
    Kept("held", "held", list, list),
    spread("contribution", Contribution),
    spread("solver", SolverNotes),
    Kept("fraction", "fraction", float, float),
)
"""The stage's typed attributes kept in its JSON ``extra``."""
