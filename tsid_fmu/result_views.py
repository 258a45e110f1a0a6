"""Views of an :class:`~tsid_fmu.result.IdentificationResult`: its summary and tables.

The result's methods ``summary``, ``simulations_frame``, ``stages_frame`` and
``parameters_frame`` call these with the result; they read it and write nothing (and
do not import :mod:`tsid_fmu.result`, which imports them).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from tsid_fmu.search.stage import StageKind
from tsid_fmu.story import determination
from tsid_fmu.study.units import study_units
from tsid_fmu.trail.files import strict

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["parameters_frame", "simulations_frame", "stages_frame", "structures_table", "summary"]

STRUCTURE_COLUMNS = (
    "cost", "k", "AIC", "BIC", "LRT p", "LRT against", "validation cost", "simulations",
    "chosen", "why",
)  # fmt: skip
"""The structures table's columns as the reports show them (the row's ``values`` and
``x``, the choices' codes and each structure's optimum, stay in ``result.json``)."""


def structures_table(result: Any) -> pd.DataFrame:
    """Return the structures table for a reader: no dicts, "yes" for the chosen one.

    One row per structure, indexed by its label, with :data:`STRUCTURE_COLUMNS`; a
    validation cost that was not computed is left out as a column.
    """
    import pandas as pd

    rows = []
    for r in result.structures:
        row = {"structure": r.get("structure", "")}
        for c in STRUCTURE_COLUMNS:
            v = r.get(c)
            row[c] = ("yes" if v else "") if c == "chosen" else v
        rows.append(row)
    frame = pd.DataFrame(rows)
    if not len(frame):
        return frame
    frame = frame.set_index("structure")
    if frame["validation cost"].isna().all():
        frame = frame.drop(columns=["validation cost"])
    return frame


def summary(result: Any) -> dict[str, Any]:
    """Return :meth:`~tsid_fmu.result.IdentificationResult.summary`."""
    units = study_units(result.study)  # the study's, else the FMU's declared ones
    params = {
        name: {
            "value": value,
            "interval": list(result.intervals.get(name) or [None, None]),
            "unit": units.get(name, ""),
            "weak": result.weak.get(name),
            "determined": determination(result.intervals.get(name)),
            **({"sampled_interval": result.sampled.intervals[name]} if _has(result, name) else {}),
        }
        for name, value in result.params.items()
    }
    stages = [
        {
            "name": s.name,
            "kind": s.kind,
            "cost": s.cost,
            "nfev": s.nfev,
            "nit": len(s.records),
            "status": s.status,
            "message": s.message,
        }
        for s in result.stages
    ]
    return strict(
        {
            "format": 1,
            "parameters": params,
            "fun": result.fun,
            "nfev": result.nfev,
            "nit": result.nit,
            "status": result.status,
            "success": result.success,
            "message": result.message,
            "account": list(result.account),
            "stages": stages,
            "warnings": list(result.warnings),
            "out_dir": None if result.out_dir is None else str(result.out_dir),
            "fit": _fit_summary(result.fit, units),
            "validation": {
                name: (
                    {"cost": v["cost"], "outputs": _output_fit(v.get("fit", {}), units)}
                    if "cost" in v
                    else {"error": str(v.get("error", ""))}
                )
                for name, v in result.validation.items()
            },
            **_structure_summary(result),
            **({"conformance": result.conformance} if result.conformance is not None else {}),
        }
    )


_FIT_KEYS = ("rmse", "nrmse", "fit_percent")


def _output_fit(per_output: Any, units: dict[str, str]) -> dict[str, Any]:
    """RMSE (in the output's unit), NRMSE and fit % of each output of one experiment."""
    return {
        output: {**{k: m.get(k) for k in _FIT_KEYS}, "unit": units.get(output, "")}
        for output, m in per_output.items()
        if isinstance(m, dict)
    }


def _fit_summary(fit: Any, units: dict[str, str]) -> dict[str, Any]:
    """:func:`_output_fit` of each identification experiment (``result.fit``)."""
    return {exp: _output_fit(per_output, units) for exp, per_output in fit.items()}


def _has(result: Any, name: str) -> bool:
    return result.sampled is not None and name in result.sampled.intervals


def _structure_summary(result: Any) -> dict[str, Any]:
    """Return the ``structure`` entry of :meth:`summary` (structure identification only)."""
    found = result.structure
    if not found:
        return {}
    keys = ("chosen", "choices", "why", "indistinguishable")
    return {"structure": {**{k: found.get(k) for k in keys}, "table": result.structures}}


def simulations_frame(result: Any) -> pd.DataFrame:
    """Return :meth:`~tsid_fmu.result.IdentificationResult.simulations_frame`."""
    import pandas as pd

    rows = []
    for s in result.stages:
        arrays = sum(int(r.nfev) for r in s.records)
        rows.append(
            {
                "stage": s.name,
                "kind": s.kind,
                "array runs": sum(len(r.sets) for r in s.records),
                "confirmation runs": len(s.records),
                "array simulations": arrays,
                "other simulations": int(s.nfev) - arrays,
                "simulations": int(s.nfev),
            }
        )
    return pd.DataFrame(rows).set_index("stage") if rows else pd.DataFrame()


def stages_frame(result: Any) -> pd.DataFrame:
    """Return one row per stage: kind, cost, simulations, what it contributed."""
    import pandas as pd

    rows, before = [], math.inf
    for s in result.stages:
        partial = s.kind == StageKind.HORIZON  # its cost is over part of the data
        gain = (before - s.cost) / before if math.isfinite(before) and before else math.nan
        gain = math.nan if partial else gain
        rows.append(
            {
                "stage": s.name,
                "kind": s.kind,
                "cost": s.cost,
                "simulations": s.nfev,
                "cost fall [%]": 100 * gain,
                "message": s.message,
            }
        )
        before = s.cost if s.kind not in (StageKind.CONTRIBUTION, StageKind.HORIZON) else before
    return pd.DataFrame(rows).set_index("stage") if rows else pd.DataFrame()


def _sampled_columns(result: Any, name: str) -> dict[str, float]:
    """Return the sampled interval of ``name`` as the columns of :meth:`parameters_frame`."""
    if result.sampled is None:
        return {}
    low, high = result.sampled.intervals.get(name) or [None, None]
    kind = result.sampled.kind.replace("_", " ")
    return {
        f"{kind} low": math.nan if low is None else low,
        f"{kind} high": math.nan if high is None else high,
    }


def parameters_frame(result: Any) -> pd.DataFrame:
    """Return :meth:`~tsid_fmu.result.IdentificationResult.parameters_frame`."""
    import pandas as pd

    rows, units = [], study_units(result.study)  # the study's, else the FMU's units
    params = result.study.identified_parameters() if result.study else []
    for p in (p for p in params if p.name in result.params):  # those of the structure
        low, high = result.intervals.get(p.name, [None, None])
        se = result.uncertainty.relative.get(p.name, math.nan) if result.uncertainty else math.nan
        rows.append(
            {
                "parameter": p.name,
                "value": result.params[p.name],
                "unit": units.get(p.name, ""),
                "95% low": math.nan if low is None else low,
                "95% high": math.nan if high is None else high,
                "determined": determination(result.intervals.get(p.name)),
                "std error [%]": se,
                **_sampled_columns(result, p.name),
                "first levels": f"{min(p.levels):.6g} .. {max(p.levels):.6g}",
                "weakly determined": result.weak.get(p.name, ""),
            }
        )
    return pd.DataFrame(rows).set_index("parameter") if rows else pd.DataFrame()
