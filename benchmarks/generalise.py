"""Generalisation benchmark: tsid and peers on randomly drawn problems of several families.

Problems are drawn at random (``benchmarks/problems/generalise_families.py``) from
families that differ from each other: the project's two plants (LSEA SISO and MISO), a
pythonfmu DC motor, a hand-written C Duffing oscillator, a Modelica pendulum with large
swings, a linear second-order system and a lightly damped oscillator whose cost has
local minima (36 problems per seed set, about 10 minutes on 2 cores).  Each draws
random true values, excitation, sensor noise (white or AR(1)), a model mismatch, first
ranges as users type them (truth inside, at an edge or outside by up to 2x; linear, log
or rounded levels) and FMU start values that are plausible but not the truth.  The
data always come from an independent solution, never from the FMU.

Each problem runs two ways: ``hand`` (the study a user writes, with the drawn levels)
and ``init`` (the study ``tsid init`` writes from the FMU and a CSV file, run unedited).
On each, on the same cost (the study's noise-weighted SSE, through
``tsid_fmu.evaluate.make_evaluator``, counting simulations as tsid does):

- ``tsid``: ``identify`` with the default method (only ``cost = "sse"``,
  ``weighting = "noise"``, ``replicates = 1`` given, as ``tsid init`` writes them);
- ``LS-c``: SciPy ``least_squares`` (trf, 2-point differences, bounds) from the centre
  of the first ranges, in log coordinates scaled by the ranges;
- ``LS-t``: the same from the truth (a reference for the lowest cost only);
- ``CMA``: CMA-ES (``cma``) within the first ranges, budget ``40 (p + 1)``;
- ``DE`` (``--de``): SciPy ``differential_evolution`` within the first ranges, budget
  ``150 (p + 1)``.

A method succeeds on a problem when its final cost is at most 1.001 times the lowest
cost any method found there.  Run::

    python benchmarks/generalise.py --seeds dev            # development seeds
    python benchmarks/generalise.py --seeds dev2 --family pendulum --count 12  # more dev
    python benchmarks/generalise.py --quick                # small subset (CI)
    python benchmarks/generalise.py --seeds dev --family duffing --workers 2 --markdown
    python benchmarks/generalise.py --seeds eval --check   # exit 1 below the bar

Keep ``--seeds eval`` for evaluation: whoever tunes the search must not look at it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
import zlib
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

# this checkout's tsid_fmu (not an installed one), and benchmarks/problems
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from problems.base import CACHE
from problems.generalise_draw import GenProblem
from problems.generalise_families import FAMILIES
from problems.generalise_report import render

from tsid_fmu import Experiment, Method, Parameter, Study, identify
from tsid_fmu.evaluate import make_evaluator
from tsid_fmu.scaffold import init_and_screen
from tsid_fmu.study import prepare

#: First seed of each seed set; a set's problems use ``base + k`` with its own stream.
SEED_BASE = {"dev": 0, "dev2": 20_000, "eval": 10_000}
#: SeedSequence spawn key of each seed set (each set is a separate stream).  ``dev2``
#: is a second development set: more problems to tune on, still apart from ``eval``.
STREAM = {"dev": 0, "dev2": 2, "eval": 1}
#: ``--quick``: (family, problem index) drawn from the dev seeds.
QUICK = [("duffing", 0), ("second_order", 0), ("local_minima", 0)]
#: Problems per seed set of a family outside the default mix, run with ``--family``.
ALONE = 6
#: Success: final cost within this factor of the lowest cost any method found.
TOLERANCE = 1.001
#: The method a user writing a study must give for the noise-weighted SSE (what
#: ``tsid init`` writes); everything else is tsid's default.
USER_METHOD = {"cost": "sse", "weighting": "noise", "replicates": 1}


def draw(family: str, index: int, seeds: str) -> GenProblem:
    """Problem ``index`` of ``family`` in the seed set ``seeds`` (``dev`` or ``eval``)."""
    seed = SEED_BASE[seeds] + index
    # keyed by the family's name, so adding a family leaves the others' draws alone
    family_key = zlib.crc32(family.encode())
    sequence = np.random.SeedSequence(seed, spawn_key=(STREAM[seeds], family_key))
    return FAMILIES[family][0](np.random.default_rng(sequence), seed)


def hand_study(gp: GenProblem) -> Study:
    """The study a user writes for ``gp``: the drawn levels, the default method."""
    prob = gp.problem
    params = [
        Parameter(n, d["levels"], min=d["min"], max=d["max"], unit=d["unit"])
        for n, d in prob.parameters.items()
    ]
    exps = [
        Experiment(
            e.data,
            inputs=e.inputs,
            outputs=e.outputs,
            derived=e.derived,
            name=e.name,
            hold={k: v for k, v in gp.hold.items() if k in e.inputs},
            noise={k: v for k, v in gp.noise.items() if k in e.outputs},
        )
        for e in prob.experiments
    ]
    return Study(
        fmu=prob.fmu,
        parameters=params,
        experiments=exps,
        start_values=dict(prob.start_values),
        method=Method(**{**USER_METHOD, **gp.method}),
        name=prob.name,
    )


def init_toml(gp: GenProblem, seeds: str) -> tuple[Path, int]:
    """Write the data CSV and run ``tsid init`` on it.

    Returns the study file's path and the simulations of init's screening, which count
    as tsid's.
    """
    folder = CACHE / "generalise" / f"{seeds}-{gp.problem.name}"
    folder.mkdir(parents=True, exist_ok=True)
    csv = folder / "measured.csv"
    gp.init.data.to_csv(csv, index=False, float_format="%.9g")
    toml = folder / "study.toml"
    _, found = init_and_screen(
        gp.problem.fmu, csv, toml, derived=gp.init.derived or None, workers=1
    )
    return toml, found.nfev if found else 0


class Scorer:
    """Cost and residuals of a study in scaled search coordinates, counting simulations.

    Coordinates: ``s = log(x / centre) / log(high / low)`` for a parameter whose first
    levels and lower bound are positive or zero (the first range is ``-0.5 .. 0.5``),
    else ``(x - centre) / (high - low)``.
    """

    def __init__(self, study: Study, interface: str | None) -> None:
        spec = prepare(study)
        if interface:
            spec = dataclasses.replace(spec, interface=interface)
        self.ev = make_evaluator(spec, workers=1)
        self.names = [p.name for p in study.parameters]
        self.params = {p.name: p for p in study.parameters}
        self.size = 1
        lows, highs = [], []
        for p in study.parameters:
            lows.append(self._to_s(p.name, p.min))
            highs.append(self._to_s(p.name, p.max))
        self.lower, self.upper = np.array(lows), np.array(highs)

    def _log(self, name: str) -> bool:
        p = self.params[name]
        return p.levels[0] > 0 and p.min >= 0

    def _to_s(self, name: str, x: float) -> float:
        p = self.params[name]
        low, high = p.levels[0], p.levels[-1]
        if self._log(name):
            if x <= 0:
                return -math.inf
            return math.log(x / math.sqrt(low * high)) / math.log(high / low)
        return (x - (low + high) / 2) / (high - low)

    def to_s(self, x: dict[str, float]) -> np.ndarray:
        """Coordinates of the parameter set ``x``."""
        return np.array([self._to_s(n, x[n]) for n in self.names])

    def to_x(self, s: np.ndarray) -> dict[str, float]:
        """The parameter set at coordinates ``s``."""
        out = {}
        for n, v in zip(self.names, s, strict=True):
            low, high = self.params[n].levels[0], self.params[n].levels[-1]
            if self._log(n):
                out[n] = math.sqrt(low * high) * (high / low) ** float(v)
            else:
                out[n] = (low + high) / 2 + float(v) * (high - low)
        return out

    @property
    def nfev(self) -> int:
        """Simulations so far (the evaluator's count)."""
        return int(self.ev.nfev)

    def residuals(self, s: np.ndarray) -> np.ndarray:
        """Weighted residuals at ``s`` (a large constant vector where a run fails, or
        where ``s`` lies so far out that the parameter set overflows)."""
        try:
            x = self.to_x(s)
        except OverflowError:
            return np.full(self.size, 1e10)
        ev = self.ev.evaluate([x])
        r = ev.residuals[0] if ev.residuals else None
        if r is None or not np.isfinite(ev.costs[0, 0]):
            return np.full(self.size, 1e10)
        self.size = r.size
        return r

    def cost_x(self, x: dict[str, float]) -> float:
        """The study's cost of the parameter set ``x`` (``inf`` where a run fails)."""
        c = float(self.ev.evaluate([x]).costs[0, 0])
        return c if math.isfinite(c) else math.inf

    def cost(self, s: np.ndarray) -> float:
        """The study's cost at ``s`` (1e300 where a run fails, for the optimisers)."""
        try:
            c = self.cost_x(self.to_x(s))
        except OverflowError:
            return 1e300
        return c if math.isfinite(c) else 1e300


def run_least_squares(scorer: Scorer, start: np.ndarray) -> dict:
    """``least_squares`` (trf, 2-point, bounds) from ``start``: cost and simulations."""
    from scipy.optimize import least_squares

    lo, hi = scorer.lower, scorer.upper
    s0 = np.clip(start, np.maximum(lo, -1e6) + 1e-9, np.minimum(hi, 1e6) - 1e-9)
    n0 = scorer.nfev
    out = least_squares(scorer.residuals, s0, bounds=(lo, hi), method="trf", x_scale="jac")
    # rounds of parallel simulation: each step's run, and each Jacobian's p columns at once
    p = len(start)
    rounds = {str(w): int(out.nfev) + int(out.njev or 0) * -(-p // w) for w in (1, 4, 16)}
    return {"cost": scorer.cost(out.x), "nfev": scorer.nfev - n0, "rounds": rounds}


def run_cma(scorer: Scorer, seed: int) -> dict:
    """CMA-ES within the first ranges from their centre, budget ``40 (p + 1)``."""
    import cma

    p = len(scorer.names)
    n0 = scorer.nfev
    opts = {"bounds": [-0.5, 0.5], "maxfevals": 40 * (p + 1), "seed": seed + 1, "verbose": -9}
    es = cma.CMAEvolutionStrategy(np.zeros(p), 0.25, opts)
    while not es.stop():
        xs = es.ask()
        es.tell(xs, [scorer.cost(np.asarray(x)) for x in xs])
    return {"cost": float(es.result.fbest), "nfev": scorer.nfev - n0}


def run_de(scorer: Scorer, seed: int) -> dict:
    """``differential_evolution`` within the first ranges, budget ``150 (p + 1)``."""
    from scipy.optimize import differential_evolution

    p = len(scorer.names)
    popsize = 10
    maxiter = max(1, 150 * (p + 1) // (popsize * p) - 1)
    n0 = scorer.nfev
    out = differential_evolution(
        scorer.cost,
        [(-0.5, 0.5)] * p,
        popsize=popsize,
        maxiter=maxiter,
        polish=False,
        seed=seed,
        tol=0,
    )
    return {"cost": float(out.fun), "nfev": scorer.nfev - n0}


def run_variant(gp: GenProblem, variant: str, seeds: str, de: bool) -> dict:
    """Run tsid and the peers on one variant (``hand`` or ``init``) of a problem."""
    screened = 0
    if variant == "hand":
        study = hand_study(gp)
        target: Study | str = study
    else:
        toml, screened = init_toml(gp, seeds)
        study = Study.from_toml(toml)
        target = str(toml)
    t0 = time.perf_counter()
    res = identify(target, workers=1, plots=False)
    tsid_time = time.perf_counter() - t0
    interface = (res.fidelity or {}).get("interface")
    scorer = Scorer(study, interface)
    truth = {**gp.problem.start_values, **gp.problem.truth}
    rows = {
        "tsid": {
            "cost": scorer.cost_x(res.params),
            "nfev": int(res.nfev) + screened,
            "screened": screened,
            "time": tsid_time,
            "status": int(res.status),
            "fun": float(res.fun),
            "coverage": coverage(res, gp.problem.truth),
            "where": where(res),
            # the path through the search: each stage's name, kind, simulations, cost and,
            # for a Taguchi stage that went on after the refinement, why
            "path": [
                [s.name, s.kind, int(s.nfev), float(s.cost), getattr(s, "resumed", "")]
                for s in res.stages
            ],
            "rounds": res.rounds,
        },
        "LS-c": run_least_squares(scorer, np.zeros(len(scorer.names))),
        "LS-t": run_least_squares(scorer, scorer.to_s(truth)),
        "CMA": run_cma(scorer, gp.seed),
    }
    if de:
        rows["DE"] = run_de(scorer, gp.seed)
    best = min(r["cost"] for r in rows.values())
    # the noise floor: residuals in noise units, one per sample and output
    floor = float(scorer.residuals(scorer.to_s(res.params)).size)
    for r in rows.values():
        r["ratio"] = r["cost"] / best if best > 0 else (1.0 if r["cost"] == best else math.inf)
        r["ok"] = r["cost"] <= TOLERANCE * best
    return {
        "family": gp.family,
        "seed": gp.seed,
        "variant": variant,
        "p": len(scorer.names),
        "best": best,
        "best_over_floor": best / floor if floor > 0 else math.nan,
        "methods": rows,
        "notes": gp.notes,
        "time": time.perf_counter() - t0,
    }


def where(res) -> dict[str, int]:
    """tsid's simulations by what spent them: the arrays, the first refinement, the
    horizons, the restarts, and the rest (combinations, checks, structure, the noise)."""
    out = {"arrays": 0, "refine": 0, "horizons": 0, "restarts": 0, "other": 0}
    for s in res.stages:
        if s.kind in ("taguchi", "contribution", "stable"):
            key = "arrays"
        elif s.kind == "horizon" or s.name.startswith("refinement after the horizons"):
            key = "horizons"
        elif s.name.startswith("restart"):
            key = "restarts"
        elif s.kind == "refinement":
            key = "refine"
        else:
            key = "other"
        out[key] += int(s.nfev)
    out["other"] += int(res.nfev) - sum(out.values())
    return out


def coverage(res, truth: dict[str, float]) -> dict:
    """Which true values lie inside tsid's 95 % intervals, and whether the result flags
    its intervals (its verdict on the fit: ``mismatch`` or ``coloured``)."""
    inside, reach = {}, {}
    for name, value in truth.items():
        if name not in res.params:
            continue
        low, high = res.intervals.get(name, [None, None])
        inside[name] = (low is None or low <= value) and (high is None or value <= high)
        # the error as a share of the interval's half-width on its side (1: on the end)
        end = high if value >= res.params[name] else low
        if end is not None and end != res.params[name]:
            reach[name] = abs(value - res.params[name]) / abs(end - res.params[name])
    u = res.uncertainty
    verdict = u.discrepancy.verdict if u is not None else "none"
    # exit status 1 says the answer is not shown to be an optimum, and warns that its
    # intervals may not hold: that flags them too
    flagged = verdict != "consistent" or int(res.status) != 0
    # for a look at calibration (``--json``): the error in standard errors, how much the
    # HAC standard error exceeds the Cramer-Rao one, and the degrees of freedom
    detail = {}
    if u is not None:
        for name in inside:
            se = u.std_error.get(name)
            crb = u.cramer_rao.get(name)
            rel = u.relative.get(name)
            detail[name] = {
                "z": (truth[name] - res.params[name]) / se if se else None,
                "hac_over_crb": rel / crb if rel and crb else None,
                "dof": u.dof.get(name),
                "profile": u.profile.get(name),
                # at the profile's resolution: the interval is a bound, not an estimate
                "bound": name in u.resolution,
            }
    return {
        "inside": inside,
        "reach": reach,
        "verdict": verdict,
        "flagged": flagged,
        "detail": detail,
    }


def run_problem(family: str, index: int, seeds: str, de: bool) -> list[dict]:
    """Draw one problem and run both variants; a crash becomes an ``error`` row."""
    t0 = time.perf_counter()
    try:
        gp = draw(family, index, seeds)
    except Exception as exc:
        return [
            {
                "family": family,
                "seed": SEED_BASE[seeds] + index,
                "variant": "-",
                "error": f"draw: {type(exc).__name__}: {exc}"[:200],
            }
        ]
    out = []
    for variant in ("hand", "init"):
        try:
            out.append(run_variant(gp, variant, seeds, de))
        except Exception as exc:
            out.append(
                {
                    "family": family,
                    "seed": gp.seed,
                    "variant": variant,
                    "error": f"{type(exc).__name__}: {exc}"[:200],
                }
            )
    print(f"  done {family} {gp.seed} in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return out


def _counts(family: str | None, count: int | None) -> dict[str, int]:
    """Problems per family: ``count`` or its own; one outside the mix only when named."""
    out = {}
    for f, (_, n) in FAMILIES.items():
        if n:
            out[f] = count or n
        elif f == family:
            out[f] = count or ALONE
    return out


def tasks(
    seeds: str, quick: bool, family: str | None, count: int | None = None
) -> list[tuple[str, int]]:
    """The (family, index) pairs to run (``count`` problems per family if given)."""
    if quick:
        chosen = list(QUICK)
    else:
        chosen = [(f, k) for f, n in _counts(family, count).items() for k in range(n)]
    return [t for t in chosen if family is None or t[0] == family]


def run_all(todo: list[tuple[str, int]], seeds: str, workers: int, de: bool) -> list[dict]:
    """Run every task (in ``workers`` processes); rows in task order."""
    results: dict[int, list[dict]] = {}
    if workers <= 1:
        for i, (family, index) in enumerate(todo):
            results[i] = run_problem(family, index, seeds, de)
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {
                pool.submit(run_problem, family, index, seeds, de): i
                for i, (family, index) in enumerate(todo)
            }
            for fut in as_completed(futures):
                results[futures[fut]] = fut.result()
    return [row for i in sorted(results) for row in results[i]]


def main(argv: list[str] | None = None) -> int:
    """Command line; returns the exit status (0 unless ``--check`` fails)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", choices=list(SEED_BASE), default="dev")
    parser.add_argument("--quick", action="store_true", help="a small subset (dev seeds)")
    parser.add_argument("--family", choices=list(FAMILIES), default=None)
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument(
        "--count", type=int, default=None, help="problems per family (default: its own)"
    )
    parser.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    parser.add_argument("--de", action="store_true", help="also run differential_evolution")
    parser.add_argument("--json", default=None, help="also write every row to this JSON file")
    parser.add_argument(
        "--check",
        action="store_true",
        help="exit 1 when tsid's success < 95 %% or its sims ratio > 2",
    )
    parser.add_argument(
        "--merge",
        nargs="+",
        default=None,
        metavar="JSON",
        help="run nothing: report the rows of earlier runs' --json files together",
    )
    args = parser.parse_args(argv)
    if args.merge:
        rows = [row for f in args.merge for row in json.loads(Path(f).read_text())]
        text, verdict = render(rows, 0.0, markdown=args.markdown, seeds=args.seeds, workers=0)
        print(text)
        return 1 if args.check and not verdict else 0
    seeds = "dev" if args.quick else args.seeds
    todo = tasks(seeds, args.quick, args.family, args.count)
    t0 = time.perf_counter()
    rows = run_all(todo, seeds, args.workers, args.de)
    wall = time.perf_counter() - t0
    text, verdict = render(rows, wall, markdown=args.markdown, seeds=seeds, workers=args.workers)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    print(text)
    return 1 if args.check and not verdict else 0


if __name__ == "__main__":
    sys.exit(main())
