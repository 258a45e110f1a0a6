"""Accuracy benchmark: tsid against SciPy peers on data from independent simulators.

Every problem's measured data come from an independent solution of the plant's
equations written in ``benchmarks/problems/`` (never from the FMU being identified),
with a rig's conventions: commands held per sample, continuous outputs sampled, one
noise level per sensor. On the same FMU, data and cost (noise-weighted SSE, so that
``least_squares`` minimises exactly the study's cost), each method runs and is scored:

- **tsid**: the Taguchi stage alone, and the whole study (the default ``refine =
  "auto"``), and the whole study with ``refine = "least_squares"`` (the Taguchi stage to
  its own end, then the refinement: the procedure of the round before);
- **least_squares**: SciPy's trust-region least squares from the centre of the first
  ranges, and from the two range corners (every parameter at its first level, every
  parameter at its last level), in the same search coordinates;
- **differential_evolution**: SciPy's DE over the first ranges with a budget of
  simulations (no polish).

Printed per problem: simulations, wall time, cost relative to the best cost any method
found, worst parameter error against the truth, and (tsid) how far the Taguchi stage
alone got. Run::

    python benchmarks/accuracy.py                 # every problem
    python benchmarks/accuracy.py --de-budget 1000 --markdown   # and its table (docs/benchmarks)
    python benchmarks/accuracy.py siso_encoder dc_motor --workers 1
    python benchmarks/accuracy.py --tsid-only     # tsid's rows only (a search change)
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's tsid_fmu

from problems import dc_motor as dc_mod
from problems import local_minima as lm_mod
from problems import miso as miso_mod
from problems import siso as siso_mod

from tsid_fmu import Experiment, Method, Parameter, Study, identify
from tsid_fmu.evaluate import make_evaluator
from tsid_fmu.search.space import Space
from tsid_fmu.study import prepare

ENCODER_SIGMA = 1e-6 / math.sqrt(12)


def study_of(prob, method: Method) -> Study:
    """The study a user would write for a benchmark problem."""
    params = [
        Parameter(
            n,
            d["levels"],
            min=d.get("min", -math.inf),
            max=d.get("max", math.inf),
            unit=d.get("unit", ""),
        )
        for n, d in prob.parameters.items()
    ]
    exps = [
        Experiment(
            e.data,
            inputs=e.inputs,
            outputs=e.outputs,
            derived=e.derived,
            name=e.name,
            noise={"x_m": ENCODER_SIGMA} if "x_m" in e.outputs else {},
            hold={k: "linear" for k in ("x_o", "v_o", "a_o") if k in e.inputs},
        )
        for e in prob.experiments
    ]
    return Study(
        fmu=prob.fmu,
        parameters=params,
        experiments=exps,
        start_values=dict(prob.start_values),
        method=method,
        name=prob.name,
    )


PROBLEMS = {
    "siso_encoder": lambda: siso_mod.siso(encoder=True),
    "siso_loadcells": lambda: siso_mod.siso(encoder=False),
    "miso": miso_mod.miso,
    "dc_motor": dc_mod.dc_motor,
    "local_minima": lm_mod.local_minima,
}

METHOD = Method(cost="sse", weighting="noise", replicates=1, start="centre")
"""What a user writes for these data: the noise-weighted SSE; everything else default,
but for the start point: the project's FMUs carry the truth as their start values, which
tsid would score first, so it starts from the centre of the first levels, as the peers
do (a vendor's FMU rarely carries the values of the unit on the bench)."""


class Scorer:
    """Costs and residuals of one problem in the search coordinates, counting simulations."""

    def __init__(self, study: Study, workers: int | None) -> None:
        self.study = study
        self.spec = prepare(study)
        self.ev = make_evaluator(self.spec, workers=workers)
        self.space = Space(study.first_levels(), study.bounds(), study.method.leveling)
        self.size = 0

    def x(self, s: np.ndarray) -> dict[str, float]:
        return self.space.to_x(s)

    def residuals(self, s: np.ndarray) -> np.ndarray:
        ev = self.ev.evaluate([self.x(s)])
        r = ev.residuals[0] if ev.residuals else None
        if r is None or not np.isfinite(ev.costs[0, 0]):
            return np.full(self.size or 1, 1e10)
        self.size = r.size
        return r

    def cost(self, s: np.ndarray) -> float:
        c = float(self.ev.evaluate([self.x(s)]).costs[0, 0])
        return c if math.isfinite(c) else 1e300

    def close(self) -> None:
        self.ev.close()


def _row(name, x, cost, nfev, seconds, truth, note=""):
    return {
        "method": name,
        "x": x,
        "cost": cost,
        "nfev": nfev,
        "time": seconds,
        "note": note,
        "error": max(abs(x[k] / truth[k] - 1) for k in truth) * 100,
    }


def run_least_squares(scorer: Scorer, start: np.ndarray, name: str, truth):
    from scipy.optimize import least_squares

    lo, hi = scorer.space.s_lower, scorer.space.s_upper
    width = np.minimum(hi - lo, 1.0)
    s0 = np.clip(start, lo + 1e-9 * width, hi - 1e-9 * width)
    n0, t0 = scorer.ev.nfev, time.perf_counter()
    out = least_squares(scorer.residuals, s0, bounds=(lo, hi), method="trf", x_scale="jac")
    x = scorer.x(out.x)
    return _row(
        name,
        x,
        scorer.cost(out.x),
        scorer.ev.nfev - n0,
        time.perf_counter() - t0,
        truth,
        out.message[:40],
    )


def run_de(scorer: Scorer, budget: int, truth, seed: int = 1):
    from scipy.optimize import differential_evolution

    p = scorer.space.dim
    popsize = 15
    maxiter = max(1, budget // (popsize * p) - 1)
    bounds = [(-0.5, 0.5)] * p  # the first levels' range of every parameter
    n0, t0 = scorer.ev.nfev, time.perf_counter()
    out = differential_evolution(
        scorer.cost, bounds, popsize=popsize, maxiter=maxiter, polish=False, seed=seed, tol=0
    )
    x = scorer.x(out.x)
    return _row(
        f"differential_evolution ({budget} budget)",
        x,
        float(out.fun),
        scorer.ev.nfev - n0,
        time.perf_counter() - t0,
        truth,
    )


def run_tsid(study: Study, truth, workers: int | None):
    t0 = time.perf_counter()
    res = identify(study, workers=workers, plots=False)
    seconds = time.perf_counter() - t0
    tag = res.stages[0] if res.stages[0].kind != "contribution" else res.stages[1]
    last_taguchi = [s for s in res.stages if s.kind in ("taguchi", "phase")][-1]
    taguchi_nfev = sum(s.nfev for s in res.stages if s.kind != "refinement")
    rows = [
        _row(
            "tsid: Taguchi stage(s) alone",
            last_taguchi.x,
            last_taguchi.cost,
            taguchi_nfev,
            math.nan,
            truth,
            tag.message[:40],
        ),
        _row(
            "tsid: whole study",
            res.params,
            res.fun,
            res.nfev,
            seconds,
            truth,
            "; ".join(f"{s.name} {s.nfev}" for s in res.stages)[:60],
        ),
    ]
    return rows, res


#: The label of each problem in docs/benchmarks/accuracy.md (``--markdown``).
LABELS = {
    "siso_encoder": "SISO, load cells + encoder, Table I",
    "siso_loadcells": "SISO, load cells only",
    "miso": "MISO, one experiment, rough ranges",
    "dc_motor": "DC motor (pythonfmu FMU), one decade per parameter",
    "local_minima": "lightly damped resonance (local minima)",
}


def _ratio(c: float) -> str:
    return f"{c:.6f}" if c < 10 else f"{c:.3g}"


def _error(e: float) -> str:
    return f"{e:.3g} %"


def markdown_rows(name: str, rows: list[dict], best: float) -> list[str]:
    """The table rows of one problem in docs/benchmarks/accuracy.md (``--markdown``)."""
    by = {r["method"]: r for r in rows}

    def cells(*methods: str) -> str:
        rs = [by[m] for m in methods]
        sims = " / ".join(str(r["nfev"]) for r in rs)
        ratios = " / ".join(_ratio(r["cost"] / best) for r in rs)
        errors = " / ".join(_error(r["error"]) for r in rs)
        return f"{sims} | {ratios} | {errors} |"

    de = next(r["method"] for r in rows if r["method"].startswith("differential"))
    return [
        f"| {LABELS.get(name, name)} | tsid: Taguchi stage alone | "
        + cells("tsid: Taguchi stage(s) alone"),
        "| | tsid: whole study | " + cells("tsid: whole study"),
        '| | tsid: refine = "least_squares" (the arrays to their end) | '
        + cells('tsid: refine = "least_squares" (arrays to their end)'),
        "| | least_squares from the centre | " + cells("least_squares from the centre"),
        "| | least_squares from level 1 / level 5 | "
        + cells("least_squares from level 1", "least_squares from level 5"),
        "| | differential_evolution | " + cells(de),
    ]


MARKDOWN_HEADER = [
    "| problem | method | simulations | cost / best | worst error |",
    "|---|---|---:|---:|---:|",
]


def tsid_rows(prob: Any, workers: int | None) -> tuple[list[dict], Any]:
    """tsid's rows of one problem: the Taguchi stage alone, the whole study, and the
    whole study with ``refine = "least_squares"``; and the whole study's result."""
    rows, res = run_tsid(study_of(prob, METHOD), prob.truth, workers)
    # the procedure of the round before, in the same run: the Taguchi stage to its own end
    whole = study_of(prob, dataclasses.replace(METHOD, refine="least_squares"))
    row = run_tsid(whole, prob.truth, workers)[0][1]
    row["method"] = 'tsid: refine = "least_squares" (arrays to their end)'
    rows.append(row)
    return rows, res


def tsid_only(name: str, workers: int | None) -> None:
    """Print tsid's rows of one problem with their costs (``--tsid-only``: the peers' rows
    do not depend on tsid's code, so a change to the search needs only these again)."""
    prob = PROBLEMS[name]()
    rows, res = tsid_rows(prob, workers)
    print(f"\n## {name} (tsid only)")
    for r in rows:
        print(f"{r['method']:<54} {r['nfev']:>6d} {r['cost']:>16.10g} {r['error']:>11.3g}%")
    print(intervals_line(res, prob.truth))


def benchmark(name: str, workers: int | None, de_budget: int) -> tuple[list[dict], float]:
    prob = PROBLEMS[name]()
    study = study_of(prob, METHOD)
    rows, res = tsid_rows(prob, workers)
    scorer = Scorer(dataclasses.replace(study, method=dataclasses.replace(METHOD)), workers)
    try:
        truth_cost = scorer.cost(scorer.space.to_s(prob.truth))
        centre = np.zeros(scorer.space.dim)
        rows.append(run_least_squares(scorer, centre, "least_squares from the centre", prob.truth))
        first = scorer.space.to_s({n: min(d["levels"]) for n, d in prob.parameters.items()})
        last = scorer.space.to_s({n: max(d["levels"]) for n, d in prob.parameters.items()})
        rows.append(run_least_squares(scorer, first, "least_squares from level 1", prob.truth))
        rows.append(run_least_squares(scorer, last, "least_squares from level 5", prob.truth))
        rows.append(run_de(scorer, de_budget, prob.truth))
    finally:
        scorer.close()
    best = min(min(r["cost"] for r in rows), truth_cost)
    print(f"\n## {name}: cost at the truth {truth_cost:.6g}, best found {best:.6g}")
    print(
        f"{'method':<44} {'sims':>6} {'time [s]':>9} {'cost / best':>12} {'worst error':>12}  note"
    )
    for r in rows:
        print(
            f"{r['method']:<44} {r['nfev']:>6d} {r['time']:>9.1f} {r['cost'] / best:>12.6f} "
            f"{r['error']:>11.3g}%  {r['note']}"
        )
    print(intervals_line(res, prob.truth))
    print(peer_line(res, rows))
    return rows, best


def peer_line(res, rows: list[dict]) -> str:
    """tsid's answer against the lowest-cost least_squares answer, parameter by parameter."""
    ls = min((r for r in rows if r["method"].startswith("least_squares")), key=lambda r: r["cost"])
    diffs = "; ".join(f"{n} {100 * (res.params[n] / v - 1):+.3f} %" for n, v in ls["x"].items())
    return (
        f"tsid (whole study) against {ls['method']} (its lowest-cost start): cost "
        f"{100 * (res.fun / ls['cost'] - 1):+.4f} %; {diffs}"
    )


def intervals_line(res, truth: dict[str, float]) -> str:
    """tsid's error and 95 % interval per parameter, and how many intervals hold the truth."""
    parts, inside = [], 0
    for n, v in truth.items():
        low, high = res.intervals.get(n, [None, None])
        ok = (low is None or low <= v) and (high is None or v <= high)
        inside += ok
        show = "..".join("open" if b is None else f"{b:.4g}" for b in (low, high))
        err = 100 * (res.params[n] / v - 1)
        parts.append(f"{n} {err:+.2f} % [{show}]{'' if ok else ' MISSES'}")
    return f"tsid errors and 95 % intervals ({inside}/{len(truth)} hold the truth): " + "; ".join(
        parts
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("problems", nargs="*", help=f"any of {', '.join(PROBLEMS)} (default all)")
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--de-budget", type=int, default=1500)
    parser.add_argument(
        "--markdown",
        action="store_true",
        help="end with the table of these problems (docs/benchmarks/accuracy.md)",
    )
    parser.add_argument(
        "--tsid-only", action="store_true", help="tsid's rows only, with their costs (no peers)"
    )
    args = parser.parse_args()
    unknown = sorted(set(args.problems) - set(PROBLEMS))
    if unknown:
        parser.error(f"unknown problem(s) {unknown}; choose from {', '.join(PROBLEMS)}")
    if args.tsid_only:
        for name in args.problems or list(PROBLEMS):
            tsid_only(name, args.workers)
        return
    table = list(MARKDOWN_HEADER)
    for name in args.problems or list(PROBLEMS):
        rows, best = benchmark(name, args.workers, args.de_budget)
        table += markdown_rows(name, rows, best)
    if args.markdown:
        command = " ".join(["python benchmarks/accuracy.py", *sys.argv[1:]])
        print(f"\n<!-- {command}, {time.strftime('%Y-%m-%d')} -->")
        print("\n".join(table))


if __name__ == "__main__":
    main()
