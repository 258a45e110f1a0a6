"""``screen(study)``: Morris or Sobol over the first ranges, beside eq. (7) from an L25.

The design is drawn in the search coordinates (:class:`~tsid_fmu.search.space.Space`:
``log10`` for parameters whose first levels span a decade or more, each first range one
unit wide), turned into parameter sets and scored by the same evaluator the search uses
(:func:`~tsid_fmu.evaluate.make_evaluator`: worker processes, time limit, memo), so every
simulation is counted and a point repeated by the design runs once. The noisy-input
replicates are left out: screening reads the measured inputs only.

Screened quantities: the study's cost, and per output its weighted sum of squared
residuals over the identification experiments (the residuals are scaled so that for the
``sse`` cost this is the output's share of the cost; for other costs it is the SSE in
units of each output's noise).
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.conformance import check_conformance
from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.factory import make_evaluator
from tsid_fmu.evaluate.protocol import Evaluator, Progress
from tsid_fmu.evaluators import StudyEvaluators
from tsid_fmu.screening.indices import (
    METHODS,
    MORRIS_THRESHOLD,
    SOBOL_THRESHOLD,
    array_contribution,
    array_design,
    default_n,
    design,
    indices,
    not_felt,
)
from tsid_fmu.screening.result import COST, ScreeningResult
from tsid_fmu.search.space import Space
from tsid_fmu.study.definition import Study

__all__ = ["screen"]

Layout = list[tuple[tuple[str, ...], int]]


def _layout(spec: Any) -> Layout:
    """Each experiment's output names and residual length (scored rows x outputs)."""
    if spec is None:
        return []
    return [(tuple(e.output_names), int(e.scored(e.measured).size)) for e in spec.experiments]


def _names(layout: Layout) -> list[str]:
    out: list[str] = []
    for names, _ in layout:
        out += [_quantity(n) for n in names if _quantity(n) not in out]
    return out


def _quantity(output: str) -> str:
    return f"{output} (output)" if output == COST else output


def _values(evaluation: Any, layout: Layout) -> tuple[dict[str, np.ndarray], int]:
    """Return each quantity per set, failures at the largest finite value; and the failures."""
    costs = np.asarray(evaluation.costs, dtype=float)[:, 0]
    out = {COST: costs}
    per = {q: np.zeros(costs.size) for q in _names(layout)}
    failed = ~np.isfinite(costs)
    for i, r in enumerate(evaluation.residuals or [None] * costs.size):
        if r is None or failed[i]:
            failed[i] = True
            continue
        k = 0
        for names, size in layout:
            block = np.asarray(r[k : k + size]).reshape(-1, len(names))
            for name, sse in zip(names, np.sum(block**2, axis=0), strict=True):
                per[_quantity(name)][i] += sse
            k += size
    out.update(per)
    for q, v in out.items():
        v = np.where(failed, np.nan, v)
        ok = v[np.isfinite(v)]
        out[q] = np.where(np.isfinite(v), v, ok.max() if ok.size else 0.0)
    return out, int(failed.sum())


def _console() -> Progress:
    def show(done: int, total: int) -> None:
        end = "\n" if done == total else ""
        print(f"\rscreening: {done}/{total} parameter sets", end=end, file=sys.stderr)

    return show


def study_evaluator(study: Study, runner: dict[str, Any]) -> Evaluator:
    """Return the search's evaluator of every parameter on the identification experiments."""
    exps = study.identify_names()
    evaluators = StudyEvaluators(study, runner, None)
    check_conformance(study, evaluators, None)  # a broken reset: a fresh instance per run
    spec = evaluators.spec(study.parameter_names, exps, {})
    plain = tuple(dataclasses.replace(e, noisy_inputs=()) for e in spec.experiments)
    return make_evaluator(dataclasses.replace(spec, experiments=plain), **runner)


def _score(
    ev: Evaluator, space: Space, s: np.ndarray, layout: Layout, progress: Progress | None
) -> tuple[dict[str, np.ndarray], int, int]:
    before = int(ev.nfev)
    sets = [space.to_x(row) for row in s]
    values, failed = _values(ev.evaluate(sets, progress), layout)
    return values, int(ev.nfev) - before, failed


def _check(study: Study, method: str, n: Any) -> tuple[str, int]:
    method = str(method).lower()
    if method not in METHODS:
        raise StudyError(f"screening method must be one of {', '.join(METHODS)}, got {method!r}")
    if study.choices:
        raise StudyError(
            f"screening covers real parameters; the study has discrete choices "
            f"({', '.join(c.name for c in study.choices)}): screen each structure's study"
        )
    if n is None:
        return method, default_n(method)
    if isinstance(n, bool) or not isinstance(n, int | np.integer):
        raise StudyError(f"screening n must be a whole number, got {n!r}")
    k = len(study.identified_parameters())
    runs = int(n) * (k + (1 if method == "morris" else 2))
    if runs > MAX_SCREEN_SETS:
        raise StudyError(
            f"screening n = {n} asks for {runs:,} parameter sets ({method}, {k} parameters), "
            f"more than {MAX_SCREEN_SETS:,}: give a smaller n"
        )
    return method, int(n)


def _size_warnings(method: str, n: int) -> list[str]:
    """Return what makes a screening of this size untrustworthy."""
    if method == "sobol" and n < SOBOL_MIN_N:
        return [
            f"Sobol with n = {n} base samples: the indices are noise at this size (ST "
            f"can exceed 1); use n >= {SOBOL_MIN_N}, or Morris for a cheap screening"
        ]
    return []


MAX_SCREEN_SETS = 100_000
"""Most parameter sets one screening runs (``n (k + 1)`` Morris, ``n (k + 2)`` Sobol)."""
SOBOL_MIN_N = 64
"""Below this many Sobol base samples the indices are noise (an ``ST`` of 1.38 at n = 2):
the result says so."""


def _threshold(method: str, threshold: float | None) -> float:
    if threshold is None:
        return MORRIS_THRESHOLD if method == "morris" else SOBOL_THRESHOLD
    if not 0 <= float(threshold) < 1:
        raise StudyError(f"screening threshold must be between 0 and 1, got {threshold!r}")
    return float(threshold)


def screen(
    study: Study | str | Path,
    method: str = "morris",
    n: int | None = None,
    *,
    workers: int | None = None,
    timeout: float | None = None,
    scheduler: Any = None,
    progress: bool | Callable[[int, int], None] = False,
    threshold: float | None = None,
    contribution: bool = True,
    seed: int = 0,
    evaluator: Evaluator | None = None,
) -> ScreeningResult:
    """Screen which parameters the outputs feel over a study's first ranges.

    Parameters
    ----------
    study : Study or path
        The study, or the path of its TOML file.
    method : {"morris", "sobol"}
        Morris elementary effects (cheap: ``n (k + 1)`` simulations) or Sobol indices
        (thorough: ``n (k + 2)``), both through SALib.
    n : int, optional
        Morris trajectories (default 20) or Sobol base samples (a power of two,
        default 64).
    workers, timeout, scheduler
        As for :func:`tsid_fmu.identify`.
    progress : bool or callable
        True prints the parameter sets done to stderr; a callable gets ``(done, total)``.
    threshold : float, optional
        Below it a parameter is not felt: a fraction of the largest ``mu*`` (Morris,
        default 0.05) or a total index ``ST`` (Sobol, default 0.01).
    contribution : bool
        Also run the MISO paper's eq. (7) from an L25 over the same ranges.
    seed : int
        Seed of the design and of the bootstrap intervals.
    evaluator : Evaluator, optional
        Score parameter sets with this instead (not closed here).

    Returns
    -------
    ScreeningResult
        Indices per quantity, the parameters set apart, eq. (7) and the simulations.
    """
    if not isinstance(study, Study):
        study = Study.from_toml(study)
    method, n = _check(study, method, n)
    params = study.identified_parameters()  # a per-experiment parameter: each copy
    space = Space({p.name: p.levels for p in params}, study.bounds(), study.method.leveling)
    x = design(method, names := list(space.names), n, seed)
    show = _console() if progress is True else (progress or None)
    runner = {"workers": workers, "timeout": timeout, "scheduler": scheduler}
    ev = evaluator if evaluator is not None else study_evaluator(study, runner)
    try:
        layout = _layout(getattr(ev, "spec", None))
        values, nfev, failed = _score(ev, space, x, layout, show)
        out = ScreeningResult(
            method=method,
            n=n,
            parameters=names,
            log={m: bool(lg) for m, lg in zip(names, space.log, strict=True)},
            quantities=list(values),
            indices={q: indices(method, names, x, v, seed) for q, v in values.items()},
            not_felt={},
            set_apart=[],
            threshold=_threshold(method, threshold),
            min_percent=study.contribution.min_percent,
            nfev=nfev,
            nfev_screen=nfev,
            failed=failed,
            warnings=_size_warnings(method, n),
        )
        if contribution:
            _contribution(out, ev, space, layout, show)
    finally:
        if evaluator is None:
            ev.close()
    _set_apart(out)
    return out


def _contribution(out: ScreeningResult, ev: Evaluator, space: Space, layout, show) -> None:
    """Add the MISO paper's eq. (7) from an L25 over the same ranges to ``out``."""
    names = out.parameters
    array, s = array_design(len(names))
    got, extra, bad = _score(ev, space, s, layout, show)
    out.contribution = {q: array_contribution(s, names, v) for q, v in got.items()}
    out.array, out.nfev_contribution = array.name, extra
    out.nfev += extra
    out.failed += bad


def _set_apart(out: ScreeningResult) -> None:
    """Name what each quantity does not feel, and what none of them feels, in ``out``."""
    names = out.parameters
    out.not_felt = {q: not_felt(out.method, out.indices[q], out.threshold) for q in out.quantities}
    out.set_apart = [m for m in names if all(m in v for v in out.not_felt.values())]
    if out.contribution:
        low = [{m for m, p in c.items() if p < out.min_percent} for c in out.contribution.values()]
        out.contribution_set_apart = [m for m in names if all(m in v for v in low)]
