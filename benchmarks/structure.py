"""Structure identification on the SISO plant: the friction law chosen from the data.

    python benchmarks/structure.py [--seeds 10] [--quick] [--workers K] [--out FILE]

``--workers K`` runs the data sets in K processes (each task one route of one data
set: the structure study with its reference, or the naive study of one law; every
simulation in the task's own FMU process), so that the 10-seed run (30 data sets, 120
tasks) fits a many-core machine; ``--out FILE`` also writes the tables and one line per
data set there (Markdown). Only the repository and the venv's packages are needed.

Data: ``examples/lsea_siso/friction_laws.py``, an independent simulation (piecewise
exact for laws 1 and 2, SciPy hybrid ``solve_ivp`` for law 3) of the SISO rig (load
cells 4 N each, encoder 1 um) under each true friction law (1 Coulomb, 2 Coulomb +
viscous, 3 Stribeck + viscous), over noise seeds 1..N. Model:
``fmus/LSEA_SISO_Friction.fmu`` (``parameter Integer friction``).

For each data set:

* **structure**: one study with ``friction = { choices = [1, 2, 3] }`` beside the Real
  parameters (Table I's ranges at three levels, and levels for F_sm and V_s), the noise-
  weighted SSE and a least-squares refinement (the example's method);
* **naive**: the same study with the law fixed (``start_values``) and only that law's
  parameters, once per law; the law with the lowest BIC (``n ln(chi2/n) + (k+1) ln n``,
  the project's ``information``) is its choice;
* **reference**: SciPy ``least_squares`` at the structure's chosen law, from the truth
  (the chosen law is the true one) or from tsid's answer, in the same cost.

Printed: the confusion matrix (true law against the chosen one, "indist." where tsid
reports the candidates indistinguishable), and per true law the worst relative error of
the law's parameters (where the true law was chosen), tsid's cost over the reference's,
the simulations of the structure study and of the naive route, with their ratio.
"""

from __future__ import annotations

import argparse
import datetime
import math
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))  # this checkout's tsid_fmu
sys.path.insert(0, str(REPO / "examples" / "lsea_siso"))

import friction_laws as laws  # noqa: E402

from tsid_fmu import Choice, Experiment, Method, Parameter, Study, identify  # noqa: E402
from tsid_fmu.evaluate import make_evaluator  # noqa: E402
from tsid_fmu.search.structure.selection import information  # noqa: E402
from tsid_fmu.study import prepare  # noqa: E402

FMU = REPO / "fmus" / "LSEA_SISO_Friction.fmu"
ENCODER_SIGMA = laws.base.NOISE["x_m"]
#: First levels: Table I of the SISO paper's ranges at three levels (a 3-level choice
#: sits beside 3-level Real factors: L27), and a spread over a decade for law 3's two.
LEVELS = {
    "F_cm": ([10.0, 60.0, 110.0], 0.0),
    "F_vm": ([1.0, 10.0, 80.0], 0.0),
    "M_m": ([4.0, 8.0, 12.0], 0.01),
    "K_s": ([1000.0, 5500.0, 10000.0], 1.0),
    "B_s": ([0.1, 5.0, 20.0], 0.0),
    "F_sm": ([60.0, 120.0, 180.0], 0.0),
    "V_s": ([0.005, 0.02, 0.08], 1e-4),
}
#: The Real parameters each law has.
LAW_PARAMS = {
    1: ["F_cm", "M_m", "K_s", "B_s"],
    2: ["F_cm", "F_vm", "M_m", "K_s", "B_s"],
    3: ["F_cm", "F_vm", "M_m", "K_s", "B_s", "F_sm", "V_s"],
}
METHOD = Method(cost="sse", weighting="noise", replicates=1, start="centre", refine="least_squares")


def study(law: int, seed: int, fixed: int | None = None) -> Study:
    """The structure study on law ``law``'s data (``fixed``: the naive study of one law)."""
    data = laws.make_data(law, seed)
    names = LAW_PARAMS[fixed] if fixed else LAW_PARAMS[3]
    params: list = [Parameter(n, LEVELS[n][0], min=LEVELS[n][1], max=math.inf) for n in names]
    start = {"V_z": laws.base.V_Z}
    if fixed:
        start["friction"] = fixed
    else:
        params.append(Choice("friction", [1, 2, 3]))
    exp = Experiment(
        data,
        inputs={"F_m": "F_m"},
        outputs={"F_o": "F_o", "x_m": "x_m"},
        derived={"F_o": "F_of - F_or"},
        noise={"x_m": ENCODER_SIGMA},
        name="measured",
    )
    return Study(
        fmu=FMU, parameters=params, experiments=[exp], start_values=start, method=METHOD,
        name=f"law{law}_seed{seed}" + (f"_fixed{fixed}" if fixed else ""),
    )  # fmt: skip


def residuals_of(st: Study):
    """Noise-weighted residuals of a study at ``x`` (and the evaluator, to close)."""
    ev = make_evaluator(prepare(st), workers=1)

    def res(x: dict[str, float]) -> np.ndarray:
        out = ev.evaluate([x])
        r = out.residuals[0] if out.residuals else None
        return np.asarray(r) if r is not None else np.full(1, 1e10)

    return res, ev


def least_squares_at(
    st: Study, names: list[str], lower: dict[str, float], start: dict[str, float]
) -> tuple[float, int]:
    """SciPy least_squares of ``st``'s ``names`` from ``start``: its chi2 and simulations.

    Each parameter scaled by its start (``x_scale="jac"``), bounded below by ``lower``.
    """
    from scipy.optimize import least_squares

    res, ev = residuals_of(st)
    lo = np.array([lower[n] for n in names])
    x0 = np.maximum(np.array([start[n] for n in names], dtype=float), lo + 1e-9)
    scale = np.abs(x0) + 1e-6

    def f(s: np.ndarray) -> np.ndarray:
        return res(dict(zip(names, s * scale, strict=True)))

    out = least_squares(f, x0 / scale, bounds=(lo / scale, np.inf), method="trf", x_scale="jac")
    n = ev.nfev
    ev.close()
    return float(out.fun @ out.fun), n


def reference(law: int, seed: int, chosen: int, start: dict[str, float]) -> tuple[float, int]:
    """SciPy least_squares at law ``chosen`` from ``start``: its chi2 and simulations."""
    lower = {n: LEVELS[n][1] for n in LAW_PARAMS[chosen]}
    return least_squares_at(study(law, seed, fixed=chosen), LAW_PARAMS[chosen], lower, start)


def chi2_at(st: Study, x: dict[str, float]) -> tuple[float, int]:
    """chi2 and n of the noise-weighted residuals of ``st`` at ``x``."""
    res, ev = residuals_of(st)
    r = res(x)
    ev.close()
    return float(r @ r), r.size


def structure_route(law: int, seed: int, workers: int = 1) -> dict:
    """The structure study on one data set, with the reference at its chosen law."""
    t0 = time.perf_counter()
    st = study(law, seed)
    out = identify(st, workers=workers, plots=False)
    s = out.structure
    chosen = int(s["values"]["friction"])
    tied = bool(s.get("indistinguishable"))
    x = {k: float(v) for k, v in out.params.items() if k != "friction"}
    fixed_st = study(law, seed, fixed=chosen)
    chi2, _ = chi2_at(fixed_st, {n: x[n] for n in LAW_PARAMS[chosen]})
    truth = laws.TRUTH[law]
    start = truth if chosen == law else x
    ref_chi2, ref_nfev = reference(law, seed, chosen, {**x, **start})
    err = max(abs(x[k] / truth[k] - 1) for k in LAW_PARAMS[law]) if chosen == law else math.nan
    return {
        "law": law, "seed": seed, "chosen": chosen, "tied": tied, "why": s.get("why", ""),
        "error": err, "ratio": chi2 / ref_chi2, "ref_chi2": ref_chi2, "nfev": out.nfev,
        "ref_nfev": ref_nfev,
        "stages": {st_.name: st_.nfev for st_ in out.stages},
        "seconds": time.perf_counter() - t0,
    }  # fmt: skip


def naive_route(law: int, seed: int, cand: int, workers: int = 1) -> dict:
    """The naive study of law ``cand`` on one data set: its simulations and BIC."""
    t0 = time.perf_counter()
    nst = study(law, seed, fixed=cand)
    nout = identify(nst, workers=workers, plots=False)
    c2, n = chi2_at(nst, {k: float(nout.params[k]) for k in LAW_PARAMS[cand]})
    bic = information(c2, n, len(LAW_PARAMS[cand]))[1]
    return {"nfev": nout.nfev, "bic": bic, "chi2": c2, "seconds": time.perf_counter() - t0}


def merge(row: dict, naive: dict[int, dict]) -> dict:
    """Join a data set's structure row and its three naive studies."""
    bics = {c: naive[c]["bic"] for c in sorted(naive)}
    own = naive.get(row["law"])
    return {
        **row,
        # the naive study of the true law against the same reference (where tsid chose it)
        "naive_ratio": own["chi2"] / row["ref_chi2"]
        if own and "chi2" in own and "ref_chi2" in row and row["chosen"] == row["law"]
        else math.nan,
        "naive_nfev": sum(naive[c]["nfev"] for c in naive),
        "naive": min(bics, key=lambda k: (bics[k], k)) if bics else None,
        "bics": bics,
        "seconds": row["seconds"] + sum(naive[c]["seconds"] for c in naive),
    }


def one(law: int, seed: int, workers: int, naive: bool = True) -> dict:
    """Structure study, naive route and reference on one data set (in this process)."""
    return merge(
        structure_route(law, seed, workers),
        {c: naive_route(law, seed, c, workers) for c in ((1, 2, 3) if naive else ())},
    )


def _task(key: tuple[int, int], cand: int | None) -> dict:
    """Run one task of :func:`run_all` (in a worker process)."""
    law, seed = key
    return structure_route(law, seed) if cand is None else naive_route(law, seed, cand)


def run_data_sets(
    keys: Sequence[tuple],
    cands: Sequence[int],
    workers: int,
    task: Callable[[tuple, int | None], dict],
    join: Callable[[dict, dict[int, dict]], dict],
    show: Callable[[dict], str],
) -> list[dict]:
    """Each data set's structure route and naive studies, in ``workers`` processes.

    ``keys`` name the data sets, in order: their tasks are submitted together, so a run
    cut short still gives whole data sets for the first ones. ``task(key, cand)`` runs
    the structure route (``cand`` None) or the naive study of ``cand`` (a module-level
    function, to run in a worker); ``join(row, naive)`` makes a data set's row once its
    tasks are in, and ``show(row)`` the line then printed.
    """
    from concurrent.futures import ProcessPoolExecutor, as_completed

    parts = (None, *cands)
    done: dict[tuple, dict] = {}
    rows = []
    with ProcessPoolExecutor(max_workers=max(1, workers)) as pool:
        futures = {pool.submit(task, k, c): (k, c) for k in keys for c in parts}
        for fut in as_completed(futures):
            key, cand = futures[fut]
            done[(key, cand)] = fut.result()
            if all((key, c) in done for c in parts):
                rows.append(join(done[(key, None)], {c: done[(key, c)] for c in cands}))
                print(show(rows[-1]), flush=True)
    return rows


def variant_cells(rs: list[dict]) -> list[str]:
    """A true variant's summary cells over its seeds: worst error, cost over the reference
    (median, max), within 1.001 x, mean simulations of both routes, and their ratio."""
    errs = [r["error"] for r in rs if not math.isnan(r["error"])]
    ratios = [r["ratio"] for r in rs if not math.isnan(r["ratio"])]
    s_n = statistics.mean(r["nfev"] for r in rs)
    n_n = statistics.mean(r.get("naive_nfev", 0) for r in rs)
    fewer = sum(1 for r in rs if r["nfev"] < r.get("naive_nfev", 0))
    return [
        f"{100 * max(errs):.3g} %" if errs else "n/a",
        f"{statistics.median(ratios):.6f}, {max(ratios):.6g}" if ratios else "n/a",
        f"{sum(1 for x in ratios if x <= 1.001)}/{len(rs)}",
        f"{s_n:.0f}",
        f"{n_n:.0f}" if n_n else "not run",
        f"{s_n / n_n:.2f} ({fewer}/{len(rs)})" if n_n else "-",
    ]


def route_tail(r: dict) -> str:
    """The end of a data set's line: its runs against the naive route's, why, and by stage."""
    return (
        f"sims {r['nfev']} vs naive {r.get('naive_nfev', 0)} ({r['seconds']:.0f} s): "
        f"{r['why']}\n    simulations by stage: "
        + ", ".join(f"{k} {v}" for k, v in r["stages"].items())
    )


def join_naive(row: dict, naive: dict[int, dict]) -> dict:
    """A data set's structure row with its naive studies: the BIC's choice, their runs."""
    row = dict(row)
    if naive:
        bics = {c: naive[c]["bic"] for c in naive}
        row["naive"] = min(bics, key=lambda k: (bics[k], k))
        row["naive_nfev"] = sum(n["nfev"] for n in naive.values())
        row["seconds"] += sum(n["seconds"] for n in naive.values())
    return row


def line(r: dict) -> str:
    """One data set's result as a line."""
    return (
        f"law {r['law']} seed {r['seed']}: chose {r['chosen']}"
        f"{' (indist.)' if r['tied'] else ''}, naive {r['naive']}, error "
        f"{100 * r['error']:.3g} %, cost ratio {r['ratio']:.6f} (naive "
        f"{r.get('naive_ratio', math.nan):.6f}), sims {r['nfev']} vs naive "
        f"{r['naive_nfev']} ({r['seconds']:.0f} s): {r['why']}"
        + "\n    simulations by stage: "
        + ", ".join(f"{k} {v}" for k, v in r.get("stages", {}).items())
    )


def run_all(laws_: list[int], seeds: list[int], processes: int, naive: bool = True) -> list[dict]:
    """Every data set's structure and naive routes, in ``processes`` processes."""
    keys = [(law, s) for s in seeds for law in laws_]
    rows = run_data_sets(keys, (1, 2, 3) if naive else (), processes, _task, merge, line)
    return sorted(rows, key=lambda r: (r["law"], r["seed"]))


def table(rows: list[dict]) -> list[str]:
    """The printed (Markdown) tables."""
    lines = [
        "| true law | chosen 1 | chosen 2 | chosen 3 | indist. | naive (BIC) chosen 1/2/3 |",
        "|---|---|---|---|---|---|",
    ]
    for law in (1, 2, 3):
        rs = [r for r in rows if r["law"] == law]
        if not rs:
            continue
        picked = [sum(1 for r in rs if not r["tied"] and r["chosen"] == c) for c in (1, 2, 3)]
        naive = "/".join(str(sum(1 for r in rs if r["naive"] == c)) for c in (1, 2, 3))
        tied = sum(1 for r in rs if r["tied"])
        name = f"{law} {laws.LAWS[law]}"
        lines.append(f"| {name} | {' | '.join(map(str, picked))} | {tied} | {naive} |")
    lines += [
        "",
        "| true law | seeds | worst error (max over seeds) | cost / least_squares (median, max) "
        "| <= 1.001 x: structure, naive | simulations: structure (of which mixed arrays) "
        "| naive (3 laws) | structure / naive |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for law in (1, 2, 3):
        rs = [r for r in rows if r["law"] == law]
        if not rs:
            continue
        errs = [r["error"] for r in rs if not math.isnan(r["error"])]
        err = f"{100 * max(errs):.3g} %" if errs else "n/a"
        s_n = statistics.mean(r["nfev"] for r in rs)
        a_n = statistics.mean(r.get("stages", {}).get("structure", 0) for r in rs)
        n_n = statistics.mean(r["naive_nfev"] for r in rs)
        ratio = f"{s_n / n_n:.2f}" if n_n else "not run"
        ratios = [r["ratio"] for r in rs]
        at = sum(1 for x in ratios if x <= 1.001)
        naive_at = [r.get("naive_ratio", math.nan) for r in rs]
        naive_at = [x for x in naive_at if not math.isnan(x)]
        n_at = f"{sum(1 for x in naive_at if x <= 1.001)}/{len(naive_at)}" if naive_at else "-"
        lines.append(
            f"| {law} | {len(rs)} | {err} | {statistics.median(ratios):.6f}, {max(ratios):.6g} "
            f"| {at}/{len(rs)}, {n_at} | {s_n:.0f} ({a_n:.0f}) | {n_n:.0f} | {ratio} |"
        )
    return lines


def main(argv: list[str] | None = None) -> list[dict]:
    """Run the benchmark and print its tables; return the rows."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=10, help="noise seeds per true law")
    ap.add_argument("--quick", action="store_true", help="one seed per law")
    ap.add_argument(
        "--first-seed", type=int, default=1,
        help="first noise seed (tune on seeds outside the reported 1..N, e.g. 101)",
    )  # fmt: skip
    ap.add_argument("--laws", type=int, nargs="*", default=[1, 2, 3])
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", type=Path, help="also write the tables to this file")
    ap.add_argument("--no-naive", action="store_true", help="skip the naive route")
    args = ap.parse_args(argv)
    first = args.first_seed
    seeds = list(range(first, first + (1 if args.quick else args.seeds)))
    t0 = time.perf_counter()
    if args.workers > 1:
        rows = run_all(args.laws, seeds, args.workers, not args.no_naive)
    else:
        rows = []
        for law in args.laws:
            for seed in seeds:
                rows.append(one(law, seed, 1, not args.no_naive))
                print(line(rows[-1]), flush=True)
    wall = time.perf_counter() - t0
    tasks = f", {sum(r['seconds'] for r in rows):.0f} s in the tasks"
    report(
        "structure.py", f"{wall:.0f} s wall{tasks}", table(rows), [line(r) for r in rows], args.out
    )
    return rows


def report(script: str, timing: str, tables: list[str], lines: list[str], out: Path | None) -> None:
    """Print a run's head, tables and lines; also write them to ``out`` where given."""
    head = (
        f"{datetime.date.today()}: python benchmarks/{script} {' '.join(sys.argv[1:])} ({timing})"
    )
    text = "\n".join([head, "", *tables, "", *lines])
    print("\n" + text)
    if out is not None:
        out.write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
