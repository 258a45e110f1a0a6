"""What one Taguchi iteration did: enough to re-create its tables and to resume."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from tsid_fmu.doe.anova import AnovaTable, anova
from tsid_fmu.doe.leveling import LevelingDecision
from tsid_fmu.doe.response import ResponseTable, response_table
from tsid_fmu.doe.sn import sn_smaller_the_better
from tsid_fmu.search.taguchi.frame import Frame

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "IterationRecord",
    "Kept",
    "Rerun",
    "json_float",
    "kept_json",
    "kept_values",
    "spread",
    "unjson_float",
]


def json_float(x: float) -> float | None:
    """``x`` for strict JSON: non-finite values become ``None``."""
    return float(x) if math.isfinite(x) else None


def unjson_float(x: float | None) -> float:
    """Inverse of :func:`json_float` (``None`` reads back as ``inf``)."""
    return math.inf if x is None else float(x)


def _same(v: Any) -> Any:
    return v


@dataclass(frozen=True)
class Kept:
    """How a typed attribute of a record or stage is kept in its JSON ``extra``.

    The search reads the attribute; only :func:`kept_json` and :func:`kept_values` (the
    trail's boundary) read or write the key. With ``spread`` (the keys), the attribute's
    JSON form is a dict whose items are kept as keys of ``extra`` of their own, and
    ``decode`` reads those of them present (:func:`spread`).
    """

    attr: str
    key: str
    encode: Callable[[Any], Any] = _same
    decode: Callable[[Any], Any] = _same
    spread: tuple[str, ...] = ()

    @property
    def keys(self) -> tuple[str, ...]:
        """The keys of ``extra`` it is kept under."""
        return self.spread or (self.key,)


def spread(attr: str, cls: type) -> Kept:
    """Keep a dataclass attribute's fields as keys of ``extra`` (those that are None left out)."""

    def encode(v: Any) -> dict[str, Any]:
        return {k: x for k, x in dataclasses.asdict(v).items() if x is not None}

    names = tuple(f.name for f in dataclasses.fields(cls))
    return Kept(attr, "", encode, lambda d: cls(**d), spread=names)


@functools.cache
def _defaults(cls: type) -> dict[str, Any]:
    """Each field's default of a dataclass (a default factory called once)."""
    return {
        f.name: f.default if f.default is not dataclasses.MISSING else f.default_factory()
        for f in dataclasses.fields(cls)
        if f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
    }


def _unset(obj: Any, attr: str) -> bool:
    """Whether a kept attribute holds its default (it is then not written).

    An empty list where the default is None is kept: it says "none", not "not made".
    """
    default, v = _defaults(type(obj))[attr], getattr(obj, attr)
    return v is None if default is None else bool(v == default)


def kept_json(obj: Any, kept: Sequence[Kept], extra: Mapping[str, Any]) -> dict[str, Any]:
    """Return ``extra`` with each set attribute of ``kept`` in its JSON form."""
    out = dict(extra)
    for k in kept:
        if _unset(obj, k.attr):
            continue
        v = k.encode(getattr(obj, k.attr))
        out.update(v if k.spread else {k.key: v})
    return out


def kept_values(extra: dict[str, Any], kept: Sequence[Kept]) -> dict[str, Any]:
    """Pop the keys of ``kept`` from ``extra``; return the attributes they hold."""
    out = {}
    for k in kept:
        held = {key: extra.pop(key) for key in k.keys if key in extra}
        if k.spread and held:
            out[k.attr] = k.decode(held)
        elif not k.spread and held.get(k.key) is not None:
            out[k.attr] = k.decode(held[k.key])
    return out


@dataclass
class Rerun:
    """The re-run an iteration sends its stage to: from a next-best run (MISO paper).

    Attributes
    ----------
    frame : Frame
        The levels of the re-run, centred on that run.
    note : str
        Why, in words (the next iteration's ``rerun``).
    origin : list of int
        ``[iteration, run]`` of the run it starts from.
    """

    frame: Frame
    note: str
    origin: list[int]

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (``extra["next"]`` in the trail)."""
        return {"frame": self.frame.to_dict(), "note": self.note, "from": list(self.origin)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Rerun:
        """Inverse of :meth:`to_dict`."""
        return cls(Frame.from_dict(d["frame"]), str(d["note"]), [int(i) for i in d["from"]])


def _starts(starts: list[Mapping[str, Any]]) -> list[dict[str, Any]]:
    return [dict(s) for s in starts]


_KEPT = (
    Kept("handover", "handover", str, str),
    Kept("handback", "handback", str, str),
    Kept("rerun", "rerun", str, str),
    Kept("rerun_from", "rerun_from", list, lambda v: [int(i) for i in v]),
    Kept("starts", "starts", _starts, _starts),
    Kept("next_rerun", "next", Rerun.to_dict, Rerun.from_dict),
    Kept("describe", "describe", dict, dict),
    Kept("discrete", "discrete", dict, dict),
    Kept("structure", "structure", list, list),
)
"""The record's typed attributes kept in its JSON ``extra``."""


@dataclass
class IterationRecord:
    """Everything one iteration did.

    Attributes
    ----------
    index : int
        1-based iteration number within its stage.
    stage : str
        Name of the stage (or phase) the iteration belongs to.
    array : str
        Orthogonal array used (e.g. ``"L25"``).
    columns : list of int
        0-based array column of each factor.
    frame : Frame
        The factors and their levels.
    parameters : list of str
        Parameter names, in the order of ``sets`` columns.
    level_index : numpy.ndarray
        0-based level of each factor in each run, ``(runs, factors)``.
    sets : numpy.ndarray
        Parameter values of each run, ``(runs, parameters)``.
    costs : numpy.ndarray
        Cost of each run and replicate, ``(runs, replicates)``; column 0 on the measured
        inputs; ``inf`` where the run failed.
    errors : list of str or None
        Failure reason of each run.
    decision : LevelingDecision
        Re-leveling outcome, one decision per factor.
    prediction : dict
        The confirmation run at the main-effects optimum: ``{"x", "cost", "error",
        "offsets"}``.
    best_x, best_cost, best_source : dict, float, str
        Best parameter set seen so far in the stage, its cost on the measured inputs,
        and where it was found.
    centre_source : str
        What the next levels are centred on.
    nfev : int
        Simulations run by this iteration (replicates and the confirmation run included).
    nfev_total : int
        Simulations of the whole study so far.
    next_frame : Frame
        The factors and levels proposed for the next iteration.
    extra : dict
        Notes a caller adds for the report and the trail; nothing of tsid-fmu's own
        (its notes are the typed attributes below).
    handover : str
        Why the stage handed over to the refinement after this iteration ("" where it
        did not).
    handback : str
        Why a continued stage handed back to the refinement ("" where it did not).
    rerun : str
        Why this iteration re-runs from elsewhere ("" where it goes on from the last).
    rerun_from : list of int or None
        ``[iteration, run]`` of the next-best run it re-runs from (None where it does
        not: an edit by a person, or no re-run).
    starts : list of dict
        The start points the stage scored before its first iteration: ``{"x", "cost",
        "source"}`` each (empty after the first iteration).
    next_rerun : Rerun or None
        The re-run it sends the stage to next (None where the stage goes on from its
        ``next_frame``).
    describe : dict or None
        What each rotated factor moves, in words (``+0.71 lg F_vm -0.70 lg B_s``), for
        the report's plots; None where no factor is rotated.
    discrete : dict or None
        In structure identification, each open discrete factor's response table and
        labels (the report's table).
    structure : list of dict or None
        In structure identification, the discrete factors as they stood after it.

    The typed attributes are kept in ``extra`` in the trail under their own names
    (``next_rerun`` as ``"next"``), by :meth:`to_dict` and :meth:`from_dict` alone.
    """

    index: int
    stage: str
    array: str
    columns: list[int]
    frame: Frame
    parameters: list[str]
    level_index: np.ndarray
    sets: np.ndarray
    costs: np.ndarray
    errors: list[str | None]
    decision: LevelingDecision
    prediction: dict[str, Any]
    best_x: dict[str, float]
    best_cost: float
    best_source: str
    centre_source: str
    nfev: int
    nfev_total: int
    next_frame: Frame
    extra: dict[str, Any] = field(default_factory=dict)
    handover: str = ""
    handback: str = ""
    rerun: str = ""
    rerun_from: list[int] | None = None
    starts: list[dict[str, Any]] = field(default_factory=list)
    next_rerun: Rerun | None = None
    describe: dict[str, str] | None = None
    discrete: dict[str, Any] | None = None
    structure: list[dict[str, Any]] | None = None

    @property
    def names(self) -> list[str]:
        """Factor names, in column order."""
        return self.frame.names

    @property
    def levels(self) -> dict[str, list[float]]:
        """Levels of each factor: parameter values, or offsets of rotated factors."""
        return {
            f.name: list(f.values) if f.values is not None else [float(o) for o in f.offsets]
            for f in self.frame.factors
        }

    @property
    def n_levels(self) -> list[int]:
        """Number of levels of each factor."""
        return [f.n_levels for f in self.frame.factors]

    @property
    def values(self) -> np.ndarray:
        """Parameter values of each run, ``(runs, parameters)``."""
        return self.sets

    @property
    def measured_costs(self) -> np.ndarray:
        """Cost of each run on the measured inputs (the study's objective)."""
        return self.costs[:, 0]

    @property
    def mean_costs(self) -> np.ndarray:
        """Mean cost over the replicates of each run."""
        return self.costs.mean(axis=1)

    @property
    def sn(self) -> np.ndarray:
        """Smaller-the-better S/N ratio of each run over its replicates (dB)."""
        return sn_smaller_the_better(self.costs)

    @property
    def response(self) -> ResponseTable:
        """Mean S/N per level of each factor (the response table)."""
        return response_table(self.level_index, self.sn, self.names, n_levels=self.n_levels)

    @property
    def response_means(self) -> ResponseTable:
        """Mean cost per level of each factor (the response table for means).

        Failed runs count as the worst finite cost.
        """
        c = self.mean_costs
        finite = c[np.isfinite(c)]
        worst = float(finite.max()) if finite.size else 1.0
        return response_table(
            self.level_index,
            np.where(np.isfinite(c), c, worst),
            self.names,
            n_levels=self.n_levels,
        )

    @property
    def anova(self) -> AnovaTable:
        """ANOVA of the S/N ratios, with pooling when the array is saturated."""
        return anova(self.level_index, self.sn, self.names, n_levels=self.n_levels)

    def sn_means(self) -> dict[str, list[float]]:
        """Mean S/N per level by factor."""
        rt = self.response
        return {n: [float(v) for v in rt.means[n]] for n in self.names}

    def runs_frame(self) -> pd.DataFrame:
        """Return the runs of this iteration as a :class:`pandas.DataFrame`."""
        import pandas as pd

        data: dict[str, Any] = {
            "stage": self.stage,
            "iteration": self.index,
            "run": np.arange(1, len(self.sets) + 1),
        }
        for j, n in enumerate(self.names):
            data[f"{n} level"] = self.level_index[:, j] + 1
        for j, n in enumerate(self.parameters):
            data[n] = self.sets[:, j]
        for r in range(self.costs.shape[1]):
            data["cost" if r == 0 else f"cost r{r + 1}"] = self.costs[:, r]
        data["mean cost"] = self.mean_costs
        data["S/N [dB]"] = self.sn
        data["error"] = [e or "" for e in self.errors]
        return pd.DataFrame(data)

    def to_dict(self) -> dict[str, Any]:
        """Return a strict-JSON-serialisable copy."""
        pred = dict(self.prediction)
        pred["cost"] = json_float(float(pred.get("cost", math.inf)))
        return {
            "index": self.index,
            "stage": self.stage,
            "array": self.array,
            "columns": list(self.columns),
            "frame": self.frame.to_dict(),
            "parameters": list(self.parameters),
            "level_index": self.level_index.tolist(),
            "sets": self.sets.tolist(),
            "costs": [[json_float(c) for c in row] for row in self.costs],
            "errors": self.errors,
            "decision": self.decision.to_dict(),
            "prediction": pred,
            "best_x": self.best_x,
            "best_cost": json_float(self.best_cost),
            "best_source": self.best_source,
            "centre_source": self.centre_source,
            "nfev": self.nfev,
            "nfev_total": self.nfev_total,
            "next_frame": self.next_frame.to_dict(),
            "extra": kept_json(self, _KEPT, self.extra),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> IterationRecord:
        """Re-create a record written by :meth:`to_dict`."""
        pred = dict(d["prediction"])
        pred["cost"] = unjson_float(pred.get("cost"))
        extra = dict(d.get("extra", {}))
        return cls(
            index=int(d["index"]),
            stage=str(d["stage"]),
            array=str(d["array"]),
            columns=[int(c) for c in d["columns"]],
            frame=Frame.from_dict(d["frame"]),
            parameters=[str(p) for p in d["parameters"]],
            level_index=np.asarray(d["level_index"], dtype=int),
            sets=np.asarray(d["sets"], dtype=float),
            costs=np.array([[unjson_float(c) for c in row] for row in d["costs"]], dtype=float),
            errors=list(d["errors"]),
            decision=LevelingDecision.from_dict(d["decision"]),
            prediction=pred,
            best_x={k: float(v) for k, v in d["best_x"].items()},
            best_cost=unjson_float(d["best_cost"]),
            best_source=str(d["best_source"]),
            centre_source=str(d["centre_source"]),
            nfev=int(d["nfev"]),
            nfev_total=int(d["nfev_total"]),
            next_frame=Frame.from_dict(d["next_frame"]),
            **kept_values(extra, _KEPT),
            extra=extra,
        )
