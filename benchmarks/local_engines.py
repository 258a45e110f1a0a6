"""Local engines: DFO-LS against SciPy ``least_squares`` on the generalisation problems.

Measures (issue 61, item 7) a model-based derivative-free least-squares engine, DFO-LS
(``dfols``, interpolation models of the residuals, no finite differences), against our
own finite-difference trust region, SciPy ``least_squares`` (trf, 2-point differences),
on the problems of ``benchmarks/generalise.py`` (same draws, same ``hand`` and ``init``
variants, same cost: the study's noise-weighted SSE through
``tsid_fmu.evaluate.make_evaluator``, with the same scaled search coordinates and
bounds, counting simulations through the evaluator).  From the centre of the first
ranges (``s = 0``) on each problem and variant:

- ``LS-c``: ``least_squares`` (``generalise.run_least_squares``, SciPy's default budget);
- ``DFO-c``: ``dfols.solve`` with the scaled bounds, ``maxfun = 100 (p + 1)`` (DFO-LS's
  own default below 1000; it counts every simulation, where SciPy's ``max_nfev`` of
  ``100 p`` leaves out those of the Jacobians), ``objfun_has_noise=False``;
- ``DFO-c noisy``: the same with ``objfun_has_noise=True`` (DFO-LS then restarts until
  the budget is spent);
- ``LS-t``: ``least_squares`` from the truth (a reference for the lowest cost only).

A method succeeds when its final cost is at most 1.001 times the lowest cost any of the
four found there; a method that raises is a failure (its message is kept).  The
summary gives per family and overall the successes and the median simulations of
``DFO-c``, ``DFO-c noisy`` and ``LS-c``, and the ratio of each DFO median to LS-c's.
Run::

    pip install dfo-ls                                       # the optional peer
    python benchmarks/local_engines.py --seeds dev --workers 1
    python benchmarks/local_engines.py --seeds dev --family siso_rig --workers 1
    python benchmarks/local_engines.py --quick --json /tmp/local.json

DFO-LS is licensed GPL-3.0-or-later, and tsid-fmu is BSD-3-Clause: DFO-LS is a
benchmark-only, optional peer, imported by this script alone and never a dependency of
the package (nor of any of its extras).  Without it the script says so and exits 2.
Keep ``--seeds eval`` for evaluation, as in ``generalise.py``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import numpy as np

# this checkout's tsid_fmu (not an installed one), and benchmarks/problems
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from generalise import (
    SEED_BASE,
    TOLERANCE,
    Scorer,
    draw,
    hand_study,
    init_toml,
    run_least_squares,
    tasks,
)
from problems.generalise_families import FAMILIES

from tsid_fmu import Study

#: The methods, in the table's order.
METHODS = ["LS-c", "DFO-c", "DFO-c noisy", "LS-t"]
#: Finite stand-in for an infinite bound (DFO-LS's own for "unconstrained").
BIG = 1e20


def _need_dfols() -> None:
    """Exit 2 with a clear message when DFO-LS is not installed."""
    try:
        import dfols  # noqa: F401
    except ImportError:
        print(
            "local_engines.py needs DFO-LS, an optional benchmark-only peer (GPL-3.0): "
            "pip install dfo-ls",
            file=sys.stderr,
        )
        sys.exit(2)


def solve_dfols(scorer: Scorer, start: np.ndarray, noisy: bool, seed: int) -> tuple[Any, list]:
    """``dfols.solve`` from ``start`` within the scorer's bounds: its solution, its warnings.

    ``maxfun = 100 (p + 1)``; ``seed`` seeds NumPy's global stream, from which DFO-LS
    draws its initial (and restart) directions. Also the peer of
    ``benchmarks/cascaded_tanks.py --dfols``.
    """
    import dfols

    p = len(start)
    lo = np.clip(scorer.lower, -BIG, BIG)
    hi = np.clip(scorer.upper, -BIG, BIG)
    # as run_least_squares: the start strictly inside the bounds
    s0 = np.clip(start, np.maximum(lo, -1e6) + 1e-9, np.minimum(hi, 1e6) - 1e-9)
    np.random.seed(seed)  # noqa: NPY002 (dfols uses the legacy global stream)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        soln = dfols.solve(
            scorer.residuals,
            s0,
            bounds=(lo, hi),
            maxfun=100 * (p + 1),
            objfun_has_noise=noisy,
            do_logging=False,
            print_progress=False,
        )
    return soln, caught


def run_dfols(scorer: Scorer, start: np.ndarray, noisy: bool, seed: int) -> dict:
    """``dfols.solve`` from ``start`` within the scorer's bounds: cost and simulations."""
    n0 = scorer.nfev
    soln, caught = solve_dfols(scorer, start, noisy, seed)
    out = {"flag": int(soln.flag), "msg": str(soln.msg)}
    if soln.x is None:
        raise RuntimeError(f"DFO-LS returned no point: {soln.msg}")
    out["cost"] = scorer.cost(np.asarray(soln.x))
    out["nfev"] = scorer.nfev - n0
    out["dfols_nf"] = int(soln.nf)
    if caught:
        out["warnings"] = sorted({str(w.message) for w in caught})
    return out


def _guarded(scorer: Scorer, fn) -> dict:
    """Run one method; an exception becomes a failed row with its message."""
    n0 = scorer.nfev
    t0 = time.perf_counter()
    try:
        row = fn()
    except Exception as exc:
        row = {
            "cost": math.inf,
            "nfev": scorer.nfev - n0,
            "error": f"{type(exc).__name__}: {exc}"[:200],
        }
    row["time"] = time.perf_counter() - t0
    return row


def run_variant(gp, variant: str, seeds: str) -> dict:
    """The four local runs on one variant (``hand`` or ``init``) of a problem."""
    if variant == "hand":
        study = hand_study(gp)
    else:
        study = Study.from_toml(init_toml(gp, seeds)[0])
    t0 = time.perf_counter()
    scorer = Scorer(study, None)
    p = len(scorer.names)
    zeros = np.zeros(p)
    truth = {**gp.problem.start_values, **gp.problem.truth}
    rows = {
        "LS-c": _guarded(scorer, lambda: run_least_squares(scorer, zeros)),
        "DFO-c": _guarded(scorer, lambda: run_dfols(scorer, zeros, False, gp.seed)),
        "DFO-c noisy": _guarded(scorer, lambda: run_dfols(scorer, zeros, True, gp.seed)),
        "LS-t": _guarded(scorer, lambda: run_least_squares(scorer, scorer.to_s(truth))),
    }
    best = min(r["cost"] for r in rows.values())
    for r in rows.values():
        if best > 0 and math.isfinite(best):
            r["ratio"] = r["cost"] / best
        else:
            r["ratio"] = 1.0 if r["cost"] == best and math.isfinite(best) else math.inf
        r["ok"] = math.isfinite(r["cost"]) and r["cost"] <= TOLERANCE * best
    return {
        "family": gp.family,
        "seed": gp.seed,
        "variant": variant,
        "p": p,
        "best": best,
        "methods": rows,
        "time": time.perf_counter() - t0,
    }


def run_problem(family: str, index: int, seeds: str) -> list[dict]:
    """Draw one problem and run both variants; a crash becomes an ``error`` row."""
    t0 = time.perf_counter()
    try:
        gp = draw(family, index, seeds)
    except Exception as exc:
        seed = SEED_BASE[seeds] + index
        error = f"draw: {type(exc).__name__}: {exc}"[:200]
        return [{"family": family, "seed": seed, "variant": "-", "error": error}]
    out = []
    for variant in ("hand", "init"):
        try:
            out.append(run_variant(gp, variant, seeds))
        except Exception as exc:
            error = f"{type(exc).__name__}: {exc}"[:200]
            out.append({"family": family, "seed": gp.seed, "variant": variant, "error": error})
    print(f"  done {family} {gp.seed} in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return out


def run_all(todo: list[tuple[str, int]], seeds: str, workers: int) -> list[dict]:
    """Run every task (in ``workers`` processes); rows in task order."""
    results: dict[int, list[dict]] = {}
    if workers <= 1:
        for i, (family, index) in enumerate(todo):
            results[i] = run_problem(family, index, seeds)
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {
                pool.submit(run_problem, family, index, seeds): i
                for i, (family, index) in enumerate(todo)
            }
            for fut in as_completed(futures):
                results[futures[fut]] = fut.result()
    return [row for i in sorted(results) for row in results[i]]


def _cell(r: dict) -> list[str]:
    """Sims and ratio of one method (`` x`` marks a failure, ``E`` an exception)."""
    if "error" in r:
        return [str(r["nfev"]), "E"]
    mark = "" if r["ok"] else " x"
    return [str(r["nfev"]), f"{r['ratio']:.4g}{mark}"]


def table(rows: list[dict]) -> list[str]:
    """One line per run: family, seed, variant, p, then sims and ratio per method."""
    head = ["family", "seed", "var", "p"]
    for m in METHODS:
        head += [f"{m} sims", f"{m} ratio"]
    body = []
    for row in rows:
        if "error" in row:
            body.append([row["family"], str(row["seed"]), row["variant"], "-", row["error"]])
            continue
        cells = [row["family"], str(row["seed"]), row["variant"], str(row["p"])]
        for m in METHODS:
            cells += _cell(row["methods"][m])
        body.append(cells)
    widths = [max(len(h), *(len(b[i]) for b in body if i < len(b))) for i, h in enumerate(head)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(head, widths, strict=True))]
    for b in body:
        lines.append("  ".join(c.rjust(w) for c, w in zip(b, widths, strict=False)))
    lines.append("ratio: final cost / lowest of the four; x: not within 1.001; E: raised")
    return lines


def _median(values: list[int]) -> float:
    return float(statistics.median(values)) if values else float("nan")


def _group(name: str, rows: list[dict]) -> list[str]:
    """Two summary lines for a group of runs: successes, then median simulations."""
    n = len(rows)
    ok = {m: sum(r["methods"][m]["ok"] for r in rows) for m in METHODS}
    rates = ", ".join(f"{m} {ok[m]}/{n}" for m in METHODS)
    sims = {m: _median([r["methods"][m]["nfev"] for r in rows]) for m in METHODS}
    ls = sims["LS-c"]
    parts = [f"LS-c {ls:g}"]
    for m in ("DFO-c", "DFO-c noisy"):
        ratio = sims[m] / ls if ls else math.inf
        parts.append(f"{m} {sims[m]:g} ({ratio:.2f} x LS-c)")
    rescue = sum(r["methods"]["DFO-c"]["ok"] and not r["methods"]["LS-c"]["ok"] for r in rows)
    lost = sum(r["methods"]["LS-c"]["ok"] and not r["methods"]["DFO-c"]["ok"] for r in rows)
    return [
        f"{name:<13} runs {n:>2}; success: {rates}",
        f"{'':<13} median sims: {'; '.join(parts)}; DFO-c ok & LS-c not {rescue}, "
        f"LS-c ok & DFO-c not {lost}",
    ]


def summary(rows: list[dict], wall: float, seeds: str, workers: int) -> list[str]:
    """Successes and median simulations per family and overall."""
    done = [r for r in rows if "error" not in r]
    errors = len(rows) - len(done)
    raised = sum("error" in r["methods"][m] for r in done for m in METHODS)
    lines = [
        "",
        f"Summary ({seeds} seeds, {len(done)} runs, {errors} errors, {raised} methods raised; "
        f"success: cost <= {TOLERANCE:g} x the lowest of the four)",
    ]
    if done:
        lines += _group("all", done)
    for family in FAMILIES:
        group = [r for r in done if r["family"] == family]
        if group:
            lines += _group(family, group)
    lines.append(f"wall {wall:.0f} s on {workers} worker(s)")
    return lines


def main(argv: list[str] | None = None) -> int:
    """Command line; returns the exit status (2 when DFO-LS is missing)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", choices=list(SEED_BASE), default="dev")
    parser.add_argument("--quick", action="store_true", help="a small subset (dev seeds)")
    parser.add_argument("--family", choices=list(FAMILIES), default=None)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument(
        "--count", type=int, default=None, help="problems per family (default: its own)"
    )
    parser.add_argument("--json", default=None, help="also write every row to this JSON file")
    args = parser.parse_args(argv)
    _need_dfols()
    seeds = "dev" if args.quick else args.seeds
    todo = tasks(seeds, args.quick, args.family, args.count)
    t0 = time.perf_counter()
    rows = run_all(todo, seeds, args.workers)
    wall = time.perf_counter() - t0
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    print("\n".join(table(rows) + summary(rows, wall, seeds, args.workers)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
