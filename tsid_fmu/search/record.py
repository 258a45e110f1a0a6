"""What one Taguchi iteration did: enough to re-create its tables and to resume."""

from __future__ import annotations

import math
from collections.abc import Mapping
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

__all__ = ["IterationRecord", "json_float", "unjson_float"]


def json_float(x: float) -> float | None:
    """``x`` for strict JSON: non-finite values become ``None``."""
    return float(x) if math.isfinite(x) else None


def unjson_float(x: float | None) -> float:
    """Inverse of :func:`json_float` (``None`` reads back as ``inf``)."""
    return math.inf if x is None else float(x)


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
        Notes for the report and the trail: re-runs from the next-best run, a person's
        choices.
    handover : str
        Why the stage handed over to the refinement after this iteration ("" where it
        did not); kept in the trail as ``extra["handover"]``.
    handback : str
        Why a continued stage handed back to the refinement ("" where it did not);
        ``extra["handback"]`` in the trail.
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
            "extra": {
                **self.extra,
                **({"handover": self.handover} if self.handover else {}),
                **({"handback": self.handback} if self.handback else {}),
            },
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
            extra=extra,
            handover=str(extra.pop("handover", "") or ""),
            handback=str(extra.pop("handback", "") or ""),
        )
