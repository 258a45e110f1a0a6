"""The recursive Taguchi identification loop (SISO paper, Section III, Steps II-V).

Each iteration builds the orthogonal array of the current levels (Step III), simulates
every row against the measured data with noise replicates, computes the
smaller-the-better S/N ratio of each row, the response table and the ANOVA, re-levels
(Step IV, :mod:`tsid_fmu.leveling`), confirms the predicted optimum with one more
simulation, and keeps the best parameter set seen so far, so the answer is never
worse than the best row evaluated. The loop stops in Case 3 (Step V) or after
``max_iterations``.

Every finished iteration is written to the output folder before the next starts
(:mod:`tsid_fmu.trail`), so an interrupted study resumes, and a person can edit the
proposed levels of the next iteration and continue.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.analysis import AnovaTable, ResponseTable, anova, response_table
from tsid_fmu.analysis import sn_smaller_the_better as sn_stb
from tsid_fmu.arrays import select_array
from tsid_fmu.canonical import CanonicalRecord, canonical_iteration
from tsid_fmu.errors import StudyError
from tsid_fmu.identifiability import standard_errors
from tsid_fmu.leveling import (
    LevelingDecision,
    ParameterDecision,
    relative_span,
    relevel,
    use_log_scale,
)
from tsid_fmu.runner import Evaluator
from tsid_fmu.scoring import metrics
from tsid_fmu.study import Study, load_study
from tsid_fmu.surrogate import quadratic_optimum

__all__ = ["IdentificationResult", "IterationRecord", "identify", "run_iteration"]

RERUN_AFTER = 2
"""Iterations without a lower cost after which the next-best run is re-conducted (the
MISO paper continued two iterations from its run 7 before going back to run 4)."""

SENSITIVITY_STEP = 0.05
"""Relative move of each parameter in :func:`local_sensitivity`."""

WEAK_STD_ERROR = 5.0
"""Relative standard error (percent, Cramer-Rao bound at the answer) above which a
parameter is reported as weakly constrained by the data."""

WEAK_CONTRIBUTION = 1.0
"""Percent ANOVA contribution below which a parameter is reported as weakly constrained."""


@dataclass
class IterationRecord:
    """Everything one iteration did, enough to re-create its tables and to resume.

    Attributes
    ----------
    index : int
        1-based iteration number.
    array : str
        Orthogonal array used (e.g. ``"L25"``).
    columns : list of int
        0-based array column of each parameter.
    names : list of str
        Parameters, in column order.
    levels : dict
        Levels of each parameter in this iteration.
    level_index : numpy.ndarray
        0-based level of each parameter in each run, shape ``(runs, parameters)``.
    costs : numpy.ndarray
        Cost of each run and replicate, shape ``(runs, replicates)`` (``inf``: failed).
    errors : list of str or None
        Failure reason of each run.
    decision : LevelingDecision
        Re-leveling outcome (case, proposed next levels, predicted optimum).
    optimum_cost : float
        Mean cost of the confirmation run at the predicted optimum.
    best_x, best_cost, best_source : dict, float, str
        Best parameter set seen so far, its mean cost and where it was found.
    nfev : int
        Simulations run so far, including this iteration.
    """

    index: int
    array: str
    columns: list[int]
    names: list[str]
    levels: dict[str, list[float]]
    level_index: np.ndarray
    costs: np.ndarray
    errors: list[str | None]
    decision: LevelingDecision
    optimum_cost: float
    optimum_error: str | None
    best_x: dict[str, float]
    best_cost: float
    best_source: str
    nfev: int
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def values(self) -> np.ndarray:
        """Parameter value of each run, shape ``(runs, parameters)``."""
        cols = [
            np.asarray(self.levels[n])[self.level_index[:, j]] for j, n in enumerate(self.names)
        ]
        return np.column_stack(cols)

    @property
    def mean_costs(self) -> np.ndarray:
        """Mean cost over replicates of each run."""
        return self.costs.mean(axis=1)

    @property
    def sn(self) -> np.ndarray:
        """Smaller-the-better S/N ratio of each run (dB)."""
        return sn_stb(self.costs)

    @property
    def response(self) -> ResponseTable:
        """Mean S/N per level of each parameter (the response table)."""
        return response_table(
            self.level_index,
            self.sn,
            self.names,
            n_levels=[len(self.levels[n]) for n in self.names],
        )

    @property
    def anova(self) -> AnovaTable:
        """ANOVA of the S/N ratios, with pooling when the array is saturated."""
        return anova(
            self.level_index,
            self.sn,
            self.names,
            n_levels=[len(self.levels[n]) for n in self.names],
        )

    @property
    def optimum(self) -> dict[str, float]:
        """Main-effects optimum of this iteration (the confirmation run's parameters)."""
        return dict(self.extra.get("optimum", self.decision.optimum()))

    def sn_means(self) -> dict[str, list[float]]:
        """Mean S/N per level by parameter."""
        rt = self.response
        return {n: [float(v) for v in rt.means[n]] for n in self.names}

    def runs_frame(self):
        """Return the runs of this iteration as a :class:`pandas.DataFrame`."""
        import pandas as pd

        values = self.values
        data: dict[str, Any] = {"iteration": self.index, "run": np.arange(1, len(values) + 1)}
        for j, n in enumerate(self.names):
            data[f"{n} level"] = self.level_index[:, j] + 1
        for j, n in enumerate(self.names):
            data[n] = values[:, j]
        for r in range(self.costs.shape[1]):
            data[f"cost r{r + 1}"] = self.costs[:, r]
        data["mean cost"] = self.mean_costs
        data["S/N [dB]"] = self.sn
        data["error"] = [e or "" for e in self.errors]
        return pd.DataFrame(data)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy (``inf`` written as ``None``)."""
        return {
            "index": self.index,
            "array": self.array,
            "columns": list(self.columns),
            "names": list(self.names),
            "levels": self.levels,
            "level_index": self.level_index.tolist(),
            "costs": [[_json_float(c) for c in row] for row in self.costs],
            "errors": self.errors,
            "decision": self.decision.to_dict(),
            "optimum_cost": _json_float(self.optimum_cost),
            "optimum_error": self.optimum_error,
            "best_x": self.best_x,
            "best_cost": _json_float(self.best_cost),
            "best_source": self.best_source,
            "nfev": self.nfev,
            "extra": self.extra,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> IterationRecord:
        """Re-create a record written by :meth:`to_dict`."""
        dec = d["decision"]
        decision = LevelingDecision(
            parameters=[ParameterDecision(**p) for p in dec["parameters"]],
            converged=bool(dec["converged"]),
            message=dec["message"],
        )
        return cls(
            index=int(d["index"]),
            array=d["array"],
            columns=list(d["columns"]),
            names=list(d["names"]),
            levels={k: [float(v) for v in vs] for k, vs in d["levels"].items()},
            level_index=np.asarray(d["level_index"], dtype=int),
            costs=np.array([[_from_json_float(c) for c in row] for row in d["costs"]]),
            errors=list(d["errors"]),
            decision=decision,
            optimum_cost=_from_json_float(d["optimum_cost"]),
            optimum_error=d.get("optimum_error"),
            best_x={k: float(v) for k, v in d["best_x"].items()},
            best_cost=_from_json_float(d["best_cost"]),
            best_source=d["best_source"],
            nfev=int(d["nfev"]),
            extra=dict(d.get("extra", {})),
        )


def _json_float(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _from_json_float(x: float | None) -> float:
    return math.inf if x is None else float(x)


class IdentificationResult(dict):
    """Outcome of an identification, in the style of :class:`scipy.optimize.OptimizeResult`.

    Attributes
    ----------
    x : dict
        Identified value of each parameter (the best parameter set seen).
    fun : float
        Its mean cost over the replicates; after iterations on canonical factors, its
        cost on the measured inputs (no added noise), by which those compare sets.
    success : bool
        True if the study converged (Case 3, or the canonical factors converged) within
        its iteration limits.
    status : int
        0 converged, 1 iteration limit reached, 2 paused by request.
    message : str
        Why the loop stopped.
    nfev : int
        Simulations run.
    nit : int
        Iterations run.
    iterations : list of IterationRecord
        The audit trail, one record per iteration.
    canonical : list of CanonicalRecord
        Iterations on canonical factors after the Taguchi iterations (study option
        ``canonical``); ``x`` and ``fun`` include them.
    weak : dict
        Parameters the data constrain weakly, with the reason.
    contribution : dict
        ANOVA percent contribution of each parameter per iteration.
    fit : dict
        Cost kinds and fit percentage per experiment and output at ``x``, noise-free.
    noise : dict
        Noise level of each experiment's measured outputs, estimated from the data
        (:func:`tsid_fmu.scoring.noise_level`; the study's ``weighting = "noise"``
        divides by it). A fit at the noise level has an RMSE close to it.
    out_dir : Path or None
        Where the audit trail and report were written.
    """

    def __getattr__(self, name: str) -> Any:
        try:
            return self[name]
        except KeyError as exc:
            raise AttributeError(name) from exc

    def __setattr__(self, name: str, value: Any) -> None:
        self[name] = value

    def __dir__(self) -> list[str]:
        return list(self.keys())

    def __repr__(self) -> str:
        order = ["message", "success", "status", "fun", "x", "nfev", "nit", "weak"]
        width = max(len(k) for k in order)
        lines = [f"{k.rjust(width)}: {self[k]!r}" for k in order if k in self]
        return "\n".join(lines)

    def to_pandas(self):
        """Return every run of every iteration as one :class:`pandas.DataFrame`.

        The column ``stage`` tells the Taguchi iterations over the parameters
        (``"parameters"``) from those on canonical factors (``"canonical"``).
        """
        import pandas as pd

        frames = [rec.runs_frame().assign(stage="parameters") for rec in self["iterations"]]
        frames += [rec.runs_frame().assign(stage="canonical") for rec in self.get("canonical", [])]
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    def parameters_frame(self):
        """Return the identified parameters with units, ranges and flags."""
        import pandas as pd

        study: Study = self["study"]
        rows = []
        for p in study.parameters:
            mine = [r for r in self["iterations"] if p.name in r.levels]
            first = mine[0] if mine else None
            last = mine[-1] if mine else None
            rows.append(
                {
                    "parameter": p.name,
                    "value": self["x"][p.name],
                    "unit": p.unit,
                    "first levels": f"{min(first.levels[p.name]):.6g} .. "
                    f"{max(first.levels[p.name]):.6g}"
                    if first
                    else "",
                    "last levels": f"{min(last.levels[p.name]):.6g} .. "
                    f"{max(last.levels[p.name]):.6g}"
                    if last
                    else "",
                    "contribution first [%]": self["contribution"].get(p.name, [math.nan])[0],
                    "contribution last [%]": self["contribution"].get(p.name, [math.nan])[-1],
                    "cost rise at +/-5 % [%]": self.get("sensitivity", {}).get(p.name, math.nan),
                    "std error [%]": (
                        self["identifiability"].relative.get(p.name, math.nan)
                        if self.get("identifiability") is not None
                        else math.nan
                    ),
                    "weakly constrained": self["weak"].get(p.name, ""),
                }
            )
        return pd.DataFrame(rows).set_index("parameter")


ProgressCallback = Callable[[str, dict[str, Any]], None]


def run_iteration(
    index: int,
    levels: Mapping[str, list[float]],
    study: Study,
    evaluator: Evaluator,
    best: tuple[dict[str, float], float, str] | None,
    nfev_before: int,
    progress: ProgressCallback | None = None,
) -> IterationRecord:
    """Run one iteration: array, simulations, S/N analysis, re-leveling, confirmation.

    Parameters
    ----------
    index : int
        1-based iteration number.
    levels : mapping
        Levels of each parameter for this iteration.
    study : Study
        The study.
    evaluator : Evaluator
        Runs and scores parameter sets.
    best : tuple or None
        Best ``(x, cost, source)`` seen before this iteration.
    nfev_before : int
        Simulations run before this iteration.
    progress : callable, optional
        Receives ``("row", {...})`` events while rows run.

    Returns
    -------
    IterationRecord
        The finished iteration.
    """
    names = study.parameter_names
    n_levels = [len(levels[n]) for n in names]
    array, columns = select_array(n_levels, name=study.array)
    level_index = np.asarray(array.table[:, columns], dtype=int)
    sets = [
        {n: float(levels[n][level_index[i, j]]) for j, n in enumerate(names)}
        for i in range(array.n_runs)
    ]

    def row_progress(done: int, total: int) -> None:
        if progress is not None:
            progress("row", {"iteration": index, "done": done, "total": total})

    ev = evaluator.evaluate(sets, progress=row_progress)
    if all(e is not None for e in ev.errors):
        raise StudyError(
            f"iteration {index}: every run of {array.name} failed; first reason: {ev.errors[0]}"
        )
    sn = sn_stb(ev.costs)
    rt = response_table(level_index, sn, names, n_levels=n_levels)
    means = {n: [float(v) for v in rt.means[n]] for n in names}
    current = {n: list(levels[n]) for n in names}
    contribution = anova(level_index, sn, names, n_levels=n_levels).contribution
    decision = relevel(
        current, means, study.leveling, bounds=study.bounds(), contribution=contribution
    )
    optimum = decision.optimum()
    # Confirmation runs. Besides the main-effects optimum (t = 1), "auto" also tries the
    # point halfway to it from the centre of the current ranges: when two parameters
    # interact along a valley (cost ~ f(u - v), as K_s and M_m do through the natural
    # frequency), main effects average over the other factor and the optimum they
    # predict overshoots to the mirror side of the valley, while the halfway point lands
    # in it.
    steps = (1.0, 0.5) if study.selection == "auto" else (1.0,)
    trial_sets = [_towards(current, optimum, t, study) for t in steps]
    labels = ["predicted optimum", "halfway to the predicted optimum"][: len(steps)]
    if study.selection == "auto":
        surface = _surface_optimum(current, level_index, sn, names, study)
        if surface is not None:
            trial_sets.append(surface)
            labels.append("optimum of the quadratic response surface")
    conf = evaluator.evaluate(trial_sets)
    optimum_cost = float(conf.mean_costs[0])

    candidates: list[tuple[dict[str, float], float, str]] = []
    if best is not None:
        candidates.append(best)
    row_means = ev.mean_costs
    i_best = int(np.argmin(row_means))
    candidates.append(
        (sets[i_best], float(row_means[i_best]), f"iteration {index}, run {i_best + 1}")
    )
    for label, x, c in zip(labels, trial_sets, conf.mean_costs, strict=True):
        candidates.append((x, float(c), f"iteration {index}, {label}"))
    best_x, best_cost, best_source = min(candidates, key=lambda c: c[1])

    selection = "main effects"
    if study.selection == "best_run" or (
        study.selection == "auto" and not decision.converged and best_cost < optimum_cost
    ):
        # The additive main-effects model did not predict the best set (interactions):
        # continue from the best set seen, as the MISO paper continues from its best run.
        decision = relevel(
            current,
            means,
            study.leveling,
            bounds=study.bounds(),
            centre=best_x,
            contribution=contribution,
        )
        selection = (
            "best run"
            if study.selection == "best_run"
            else f"{best_source} (predicted optimum cost {optimum_cost:.6g} > {best_cost:.6g})"
        )
    return IterationRecord(
        index=index,
        array=array.name,
        columns=list(columns),
        names=names,
        levels={n: [float(v) for v in levels[n]] for n in names},
        level_index=level_index,
        costs=ev.costs,
        errors=ev.errors,
        decision=decision,
        optimum_cost=optimum_cost,
        optimum_error=conf.errors[0],
        best_x=dict(best_x),
        best_cost=best_cost,
        best_source=best_source,
        nfev=nfev_before + ev.nfev + conf.nfev,
        extra={"selection": selection, "optimum": optimum},
    )


def _canonical_stage(
    study: Study,
    evaluator: Any,
    best: tuple[dict[str, float], float, str],
    audit: Any,
    callback: ProgressCallback | None,
    prior: list[CanonicalRecord] | None = None,
) -> tuple[dict[str, float], float, str, list[CanonicalRecord], str]:
    """Run up to ``study.canonical`` iterations on canonical factors from ``best``.

    ``prior`` holds the canonical iterations of an interrupted study (same Taguchi
    result); the stage continues after them instead of starting again.
    """
    names = study.parameter_names
    # a parameter at zero (on its bound) steps by 1 % of its largest first level
    scales = {p.name: 0.01 * max(abs(v) for v in p.levels) for p in study.parameters}
    records: list[CanonicalRecord] = list(prior or [])
    centre_nfev = 0
    if records:
        last = records[-1]
        best = (last.best_x, last.best_cost, last.best_source)
        radius = float(last.extra.get("radius", math.inf))
        evaluator.nfev += sum(r.nfev for r in records)
    else:
        radius = math.inf
        # from here on a set's cost is its cost on the measured inputs (see canonical.py)
        nfev0 = evaluator.nfev
        centre = evaluator.evaluate([best[0]], clean=True).mean_costs[0]
        best = (best[0], float(centre), best[2])
        centre_nfev = evaluator.nfev - nfev0
    for i in range(len(records) + 1, study.canonical + 1):
        if records and records[-1].converged:
            break
        if callback:
            callback("canonical", {"iteration": i, "limit": study.canonical})
        rows = None
        if callback:

            def rows(done: int, total: int) -> None:
                callback("row", {"done": done, "total": total})

        rec = canonical_iteration(
            i,
            evaluator,
            names,
            best,
            study.bounds(),
            study.leveling.significance_db,
            radius,
            rows,
            scales,
        )
        if i == 1:
            rec.nfev += centre_nfev  # the centre's cost on the measured inputs
        radius = rec.extra["radius"]
        records.append(rec)
        best = (rec.best_x, rec.best_cost, rec.best_source)
        if audit is not None:
            audit.write_canonical(rec)
        if callback:
            callback("canonical done", {"record": rec})
    if records and records[-1].converged:
        note = f"canonical factors converged after {len(records)} iteration(s)"
    else:
        note = f"{len(records)} iteration(s) on canonical factors"
    return best[0], best[1], best[2], records, note


def _levels_from_run(rec: IterationRecord, run: int, study: Study) -> dict[str, list[float]]:
    """Levels of the iteration after ``rec`` centred on its run ``run`` (0-based)."""
    centre = {n: float(v) for n, v in zip(rec.names, rec.values[run], strict=True)}
    decision = relevel(
        rec.levels,
        rec.sn_means(),
        study.leveling,
        bounds=study.bounds(),
        centre=centre,
        contribution=rec.anova.contribution,
    )
    return decision.next_levels()


def _next_best(
    records: list[IterationRecord], tried: set[tuple[int, int]], study: Study
) -> tuple[IterationRecord, int] | None:
    """Return the run to re-conduct from when the last iteration did not lower the cost.

    Returns the next-best (untried) run of the iteration whose choice was followed by
    ``RERUN_AFTER`` iterations that did not lower the cost, or None if the cost went
    down, the ranges are already small, or nothing is left to try.
    """
    if len(records) < RERUN_AFTER + 1:
        return None
    last, src = records[-1], records[-1 - RERUN_AFTER]
    if last.best_cost < src.best_cost or last.decision.converged:
        return None
    if any("rerun" in r.extra for r in records[-RERUN_AFTER:]):
        return None  # give a re-run its own iterations before judging it
    wide = 10 * study.leveling.tolerance
    if all(relative_span(v) <= wide for v in last.levels.values()):
        return None  # near convergence a flat iteration is expected, not a wrong turn
    order = [int(i) for i in np.argsort(src.mean_costs, kind="stable")]
    for run in order[1:]:
        if np.isfinite(src.mean_costs[run]) and (src.index, run) not in tried:
            return src, run
    return None


def _towards(
    levels: Mapping[str, list[float]], optimum: Mapping[str, float], t: float, study: Study
) -> dict[str, float]:
    """Return the point a fraction ``t`` of the way from the range centres to ``optimum``.

    The centre and the interpolation are geometric for log-spaced levels.
    """
    out = {}
    bounds = study.bounds()
    for name, lv in levels.items():
        lo, hi = min(lv), max(lv)
        target = optimum[name]
        if use_log_scale(lv, study.leveling) and target > 0:
            centre = math.sqrt(lo * hi)
            value = centre * (target / centre) ** t
        else:
            centre = 0.5 * (lo + hi)
            value = centre + t * (target - centre)
        bmin, bmax = bounds[name]
        out[name] = float(min(max(value, bmin), bmax))
    return out


def _surface_optimum(
    levels: Mapping[str, list[float]],
    level_index: np.ndarray,
    sn: np.ndarray,
    names: list[str],
    study: Study,
) -> dict[str, float] | None:
    """Maximiser of a quadratic S/N model over the runs, within the current ranges."""
    z = np.empty(level_index.shape)
    spans = []
    for j, name in enumerate(names):
        lv = np.asarray(levels[name], dtype=float)
        log = use_log_scale(lv, study.leveling)
        u = np.log10(lv) if log else lv
        lo, hi = u.min(), u.max()
        z[:, j] = (2 * u[level_index[:, j]] - lo - hi) / (hi - lo)
        spans.append((lo, hi, log))
    best = quadratic_optimum(z, sn)
    if best is None:
        return None
    bounds = study.bounds()
    out = {}
    for j, name in enumerate(names):
        lo, hi, log = spans[j]
        u = 0.5 * (lo + hi) + 0.5 * best[j] * (hi - lo)
        value = 10.0**u if log else u
        bmin, bmax = bounds[name]
        out[name] = float(min(max(value, bmin), bmax))
    return out


def weak_parameters(
    records: list[IterationRecord], study: Study, threshold: float = WEAK_CONTRIBUTION
) -> tuple[dict[str, str], dict[str, list[float]]]:
    """Find the parameters the data constrain weakly.

    A parameter is flagged if its S/N was flat while its levels were still far apart
    (Case 2 narrowing with a range wider than ten times the tolerance), or if its ANOVA
    percent contribution in the first iteration - over the user's rough ranges - is
    below ``threshold``. (Later iterations are not used: once every range is small one
    parameter dominates the ANOVA and the others' shares say nothing about the data.)
    :func:`local_sensitivity` adds a check at the answer itself.

    Returns
    -------
    weak : dict
        Parameter name -> reason.
    contribution : dict
        Parameter name -> percent contribution in each iteration.
    """
    contribution: dict[str, list[float]] = {n: [] for n in study.parameter_names}
    weak: dict[str, str] = {}
    wide = 10 * study.leveling.tolerance
    for rec in records:
        table = rec.anova
        for n in rec.names:
            contribution[n].append(float(table.contribution[n]))
        for d in rec.decision.parameters:
            flat = d.delta_db < study.leveling.significance_db
            if flat and d.case in ("narrow", "keep") and relative_span(rec.levels[d.name]) > wide:
                weak.setdefault(
                    d.name,
                    f"flat S/N ({d.delta_db:.3g} dB) over a wide range in iteration {rec.index}",
                )
    if records:
        for n in study.parameter_names:
            first = contribution[n][0]
            if first < threshold and n not in weak:
                weak[n] = f"ANOVA contribution {first:.2g} % over the first-iteration ranges"
    return weak, contribution


def local_sensitivity(
    evaluator: Any, x: Mapping[str, float], step: float = SENSITIVITY_STEP
) -> dict[str, float]:
    """Percent rise of the cost when each parameter moves by ``+/- step`` from ``x``.

    The mean over both directions is returned; a parameter whose value barely changes
    the cost is weakly constrained by the data, whatever the ANOVA said.
    """
    names = list(x)
    sets = [dict(x)]
    for n in names:
        for sign in (-1.0, 1.0):
            trial = dict(x)
            trial[n] = x[n] * (1 + sign * step) if x[n] != 0 else sign * step
            sets.append(trial)
    costs = evaluator.evaluate(sets).mean_costs
    base = float(costs[0])
    out = {}
    for i, n in enumerate(names):
        pair = costs[1 + 2 * i : 3 + 2 * i]
        rise = float(np.mean(pair)) - base
        out[n] = 100.0 * rise / base if base > 0 and np.isfinite(rise) else float("inf")
    return out


def identify(
    study: Study | str | Path,
    out: str | Path | None = None,
    *,
    resume: bool = False,
    max_iterations: int | None = None,
    pause_after: int | None = None,
    progress: bool | ProgressCallback = False,
    plots: bool = True,
    continue_from_run: int | None = None,
    evaluator: Any = None,
    workers: int | None = None,
    timeout: float | None = None,
    scheduler: Any = None,
) -> IdentificationResult:
    """Identify the parameters of a study's FMU from its measured data.

    Parameters
    ----------
    study : Study or path
        The study, or the path of its TOML file.
    out : path, optional
        Folder for the audit trail, plots and report; written as each iteration ends.
    resume : bool
        Continue the study already in ``out`` (after an interruption, or after a person
        edited ``next_levels.toml`` of the last iteration).
    max_iterations : int, optional
        Override the study's iteration limit.
    pause_after : int, optional
        Stop after this many iterations in this call (to review and edit the proposed
        levels, then continue with ``resume=True``).
    progress : bool or callable
        True prints progress to stderr; a callable receives ``(event, info)``.
    plots : bool
        Write the per-iteration plots (main effects, fit) into ``out``.
    continue_from_run : int, optional
        With ``resume``: centre the next levels on this (1-based) run of the last
        iteration instead of the proposed levels - a person picking the run to continue
        from, as the MISO paper does with its runs 7 and 4.
    evaluator : object, optional
        Something with the interface of :class:`~tsid_fmu.runner.Evaluator` to score
        parameter sets (e.g. a parallel one); default a serial Evaluator of the study.
        It is not closed here.
    workers : int, optional
        Worker processes that run the rows in parallel (default: all available cores;
        1 runs serially in this process). Results are identical either way.
    timeout : float, optional
        Time limit in seconds per simulation; a row past it is stopped and fails, and
        the study goes on (needs worker processes).
    scheduler : str or distributed.Client, optional
        Address of a ``dask.distributed`` scheduler to send the rows to (needs
        ``tsid-fmu[dask]``).

    Returns
    -------
    IdentificationResult
        ``x``, ``fun``, ``success``, ``message``, ``nfev``, ``nit``, the per-iteration
        records and ``to_pandas()``.
    """
    from tsid_fmu import trail
    from tsid_fmu.progress import ConsoleProgress

    if not isinstance(study, Study):
        study = load_study(study)
    if study.phases or study.contribution.enabled:
        from tsid_fmu.phases import identify_phased

        if continue_from_run is not None or evaluator is not None or pause_after is not None:
            raise StudyError(
                "continue_from_run, pause_after and evaluator apply to single-phase studies; "
                "a phased study resumes phase by phase"
            )
        callback_p = ConsoleProgress() if progress is True else (progress or None)
        return identify_phased(
            study, out, resume=resume, progress=callback_p, plots=plots,
            max_iterations=max_iterations,
            runner={"workers": workers, "timeout": timeout, "scheduler": scheduler},
        )  # fmt: skip
    limit = max_iterations or study.max_iterations
    callback: ProgressCallback | None
    if progress is True:
        callback = ConsoleProgress()
    elif callable(progress):
        callback = progress
    else:
        callback = None

    audit = trail.Trail(out, study) if out is not None else None
    records: list[IterationRecord] = []
    levels = study.first_levels()
    if audit is not None:
        records = audit.open(resume=resume)
        if records:
            levels = audit.next_levels(records[-1])
    elif resume:
        raise StudyError("resume needs the output folder of the study (out=...)")
    pending_note: str | None = None
    pending_from: tuple[int, int] | None = None
    if continue_from_run is not None:
        if not records:
            raise StudyError("continue_from_run needs a study to resume (no iteration found)")
        last = records[-1]
        if not 1 <= continue_from_run <= len(last.errors):
            raise StudyError(
                f"continue_from_run {continue_from_run}: iteration {last.index} has runs "
                f"1..{len(last.errors)}"
            )
        levels = _levels_from_run(last, continue_from_run - 1, study)
        pending_note = f"continued from iteration {last.index}, run {continue_from_run} (chosen)"
    elif records and "next" in records[-1].extra:
        # the interrupted study had decided to re-conduct from a next-best run
        pending_note = records[-1].extra["next"]["note"]
        pending_from = tuple(records[-1].extra["next"]["from"])

    best = (records[-1].best_x, records[-1].best_cost, records[-1].best_source) if records else None
    nfev = records[-1].nfev if records else 0
    status, message = 1, f"iteration limit ({limit}) reached before the levels converged"
    owned = evaluator is None
    if owned:
        from tsid_fmu.parallel import make_evaluator

        evaluator = make_evaluator(study, workers=workers, timeout=timeout, scheduler=scheduler)
    try:
        evaluator.nfev = nfev
        converged_before = bool(records) and records[-1].decision.converged
        ran = 0
        if converged_before and levels == records[-1].levels and pending_note is None:
            status, message = 0, records[-1].decision.message
        else:
            tried: set[tuple[int, int]] = {
                tuple(r.extra["rerun_from"]) for r in records if "rerun_from" in r.extra
            }
            reruns = len(tried)
            for index in range(len(records) + 1, limit + 1):
                if callback:
                    callback("iteration", {"iteration": index, "limit": limit, "levels": levels})
                rec = run_iteration(index, levels, study, evaluator, best, nfev, callback)
                if pending_note is not None:
                    rec.extra["rerun"] = pending_note
                    if pending_from is not None:
                        rec.extra["rerun_from"] = list(pending_from)
                    pending_note, pending_from = None, None
                records.append(rec)
                best = (rec.best_x, rec.best_cost, rec.best_source)
                nfev = rec.nfev
                # Decide the next levels before the iteration is written, so that a study
                # interrupted here resumes exactly as it would have continued.
                levels = rec.decision.next_levels()
                alt = None
                if not rec.decision.converged and reruns < study.max_reruns:
                    alt = _next_best(records, tried, study)
                if alt is not None:
                    # Continuing from the best choice did not lower the cost (the MISO
                    # paper's "results did not meet expectations"): re-conduct from the
                    # next-best run of the iteration that chose it.
                    src, run = alt
                    tried.add((src.index, run))
                    reruns += 1
                    levels = _levels_from_run(src, run, study)
                    note = (
                        f"iteration {index} did not lower the cost ({rec.best_cost:.6g}); "
                        f"re-conducted from iteration {src.index}, run {run + 1} (next best)"
                    )
                    rec.extra["next"] = {"levels": levels, "note": note, "from": [src.index, run]}
                    pending_note, pending_from = note, (src.index, run)
                    if callback:
                        callback("rerun", {"message": note})
                if audit is not None:
                    audit.write_iteration(rec, evaluator if plots else None)
                if callback:
                    callback("iteration done", {"record": rec})
                ran += 1
                if rec.decision.converged:
                    status, message = 0, rec.decision.message
                    break
                if pause_after is not None and ran >= pause_after and index < limit:
                    status = 2
                    message = (
                        f"paused after iteration {index}: review the proposed levels and "
                        "continue with resume"
                    )
                    break
        if not records:
            raise StudyError("no iteration was run (max_iterations is 0?)")
        best_x, best_cost, best_source = (
            records[-1].best_x,
            records[-1].best_cost,
            records[-1].best_source,
        )
        canon: list[CanonicalRecord] = []
        prior: list[CanonicalRecord] = []
        if audit is not None:
            # a resumed study whose Taguchi iterations are unchanged continues its
            # canonical iterations; any others are stale
            if resume and ran == 0 and study.canonical:
                prior = audit.canonical_records()[: study.canonical]
            audit.clear_canonical(keep=len(prior))
        if study.canonical and status != 2:
            best_x, best_cost, best_source, canon, note = _canonical_stage(
                study, evaluator, (best_x, best_cost, best_source), audit, callback, prior
            )
            message = f"{message}; {note}"
            if canon and canon[-1].converged:
                status = 0
        noise = {
            p.experiment.name: dict(zip(p.output_names, map(float, p.noise), strict=True))
            for p in evaluator.prepared
        }
        sensitivity = local_sensitivity(evaluator, best_x)
        precision = standard_errors(evaluator, best_x)
        fit: dict[str, Any] = {}
        simulated = evaluator.simulate_clean(best_x)
        for prep, y, err in simulated:
            if y is None:
                fit[prep.experiment.name] = {"error": err}
            else:
                fit[prep.experiment.name] = metrics(prep.time, prep.measured, y, prep.output_names)
        nfev = evaluator.nfev
    finally:
        if owned:
            evaluator.close()

    weak, contribution = weak_parameters(records, study)
    if precision is not None:
        for n, rel in precision.relative.items():
            if n in weak and rel <= WEAK_STD_ERROR:
                # the Taguchi iterations' evidence is about their levels; say what the
                # data determine at the answer too
                weak[n] += f" (yet its standard error at the answer is +/-{rel:.2g} %)"
            if rel > WEAK_STD_ERROR:
                spread = (
                    f"+/-{rel:.2g} %"
                    if math.isfinite(rel)
                    else f"+/-{precision.std_error[n]:.3g} (about a value of 0)"
                )
                weak[n] = (
                    f"the data determine it only to {spread} (standard error, "
                    "Cramer-Rao bound)" + (f"; {weak[n]}" if n in weak else "")
                )
    result = IdentificationResult(
        x=dict(best_x),
        fun=best_cost,
        success=status == 0,
        status=status,
        message=message,
        nfev=nfev,
        nit=len(records) + len(canon),
        iterations=records,
        canonical=canon,
        weak=weak,
        contribution=contribution,
        fit=fit,
        noise=noise,
        best_source=best_source,
        sensitivity=sensitivity,
        identifiability=precision,
        study=study,
        out_dir=Path(out) if out is not None else None,
    )
    if audit is not None:
        audit.write_result(result, simulated if plots else None)
    if callback:
        callback("done", {"result": result})
    return result
