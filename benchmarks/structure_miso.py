"""Structure identification on the MISO plant: a one-mass or a two-mass load side.

    python benchmarks/structure_miso.py [--seeds 10] [--first-seed 1] [--workers K]
                                        [--masses 1 2] [--no-naive] [--out FILE]

Data: ``examples/lsea_miso/make_data.py``, the independent solution of the MISO rig
(held motor force, continuous stage motion logged as its position only, two
compression-only load cells of 1 N each), the example's three experiments (force only
and motion only to identify, both inputs to validate), over noise seeds, with a
two-mass load side (the example's truth: ``m2`` = 0.2 kg, ``C_2`` = 2 N.s/m) or a
one-mass one (``m2`` = ``C_2`` = 0: the load cells carry the spring force).
Model: a choice among two FMU files, ``model = { fmus = ["LSEA_MISO_OneMass.fmu",
"LSEA_MISO.fmu"] }`` (variant 0 one mass, 1 two masses).

For each data set:

* **structure**: one study with the FMU choice beside the example's first levels and
  bounds (``examples/lsea_miso/study.toml``, typed by hand, without its contribution
  analysis, which a structure study does not take yet);
* **naive**: the same study with each FMU alone (and only its parameters), the lowest
  BIC its choice;
* **reference**: SciPy ``least_squares`` at the chosen structure from the truth (where
  the true one is chosen) or from tsid's answer, in the same cost.

Printed: the confusion matrix (true load side against the chosen one), the worst
relative error of the true structure's parameters, the cost over the reference's, and
the simulations of the structure study and the naive route, with their ratio.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import structure as base  # noqa: E402

# the MISO example's make_data.py, under its own name (the SISO one is ``make_data``)
_spec = importlib.util.spec_from_file_location(
    "lsea_miso_make_data", HERE.parent / "examples" / "lsea_miso" / "make_data.py"
)
assert _spec is not None and _spec.loader is not None
rig = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = rig
_spec.loader.exec_module(rig)

from tsid_fmu import Experiment, Method, ModelChoice, Parameter, Study, identify  # noqa: E402
from tsid_fmu.search.structure.selection import information  # noqa: E402

FMUS = {
    1: HERE.parent / "fmus" / "LSEA_MISO_OneMass.fmu",
    2: HERE.parent / "fmus" / "LSEA_MISO.fmu",
}
#: The example study's first levels and lower bounds (examples/lsea_miso/study.toml).
LEVELS = {
    "m1": ([0.15, 0.4, 1.0], 0.01),
    "K_s": ([3000.0, 6000.0, 12000.0], 10.0),
    "C_d": ([0.5, 2.0, 10.0], 0.0),
    "C_1": ([8.0, 16.0, 32.0], 0.0),
    "m2": ([0.05, 0.1, 0.5], 0.001),
    "C_2": ([0.1, 1.0, 10.0], 0.0),
}
#: The Real parameters of each load side.
PARAMS = {1: ["m1", "K_s", "C_d", "C_1"], 2: list(LEVELS)}
#: The example's method, without its contribution analysis.
METHOD = Method(
    cost="sse", weighting="noise", replicates=1, start="centre", refine="least_squares",
    max_iterations=20,
)  # fmt: skip
ROLES = {"force_only": "identify", "motion_only": "identify", "combined": "validate"}


def truth(masses: int) -> dict[str, float]:
    """The true parameters: the example's, with ``m2 = C_2 = 0`` for one mass."""
    return {**rig.TRUTH, **({} if masses == 2 else {"m2": 0.0, "C_2": 0.0})}


def study(masses: int, seed: int, fixed: int | None = None) -> Study:
    """The structure study on ``masses``-mass data (``fixed``: the naive study of one)."""
    frames = rig.make_data(seed, truth(masses))
    exps = [
        Experiment(
            frames[name],
            name=name,
            role=role,
            inputs={"F_m": "F_m", "x_o": "x_o", "v_o": "v_o", "a_o": "a_o"},
            outputs={"F_o": "F_o"},
            derived={"F_o": "F_of - F_or", "v_o": "der(x_o)", "a_o": "der(x_o, 2)"},
            hold={"x_o": "linear", "v_o": "linear", "a_o": "linear"},
        )
        for name, role in ROLES.items()
    ]
    names = PARAMS[fixed] if fixed is not None else PARAMS[2]
    params: list = [Parameter(n, LEVELS[n][0], min=LEVELS[n][1], max=math.inf) for n in names]
    fmu = FMUS[fixed] if fixed is not None else FMUS[1]
    if fixed is None:
        params.append(ModelChoice("model", [FMUS[1], FMUS[2]]))
    return Study(
        fmu=fmu, parameters=params, experiments=exps, method=METHOD,
        name=f"masses{masses}_seed{seed}" + ("" if fixed is None else f"_fixed{fixed}"),
    )  # fmt: skip


def reference(masses: int, seed: int, chosen: int, start: dict[str, float]) -> float:
    """SciPy least_squares at load side ``chosen`` from ``start``: its chi2."""
    lower = {n: LEVELS[n][1] for n in PARAMS[chosen]}
    return base.least_squares_at(study(masses, seed, fixed=chosen), PARAMS[chosen], lower, start)[0]


def structure_route(masses: int, seed: int, folder: Path | None = None) -> dict:
    """The structure study on one data set, with the reference at its choice.

    ``folder``: also write its output folder there (report, tables, ``model.ssp``).
    """
    t0 = time.perf_counter()
    out = identify(study(masses, seed), folder, workers=1, plots=False)
    s = out.structure
    chosen = int(s["values"]["model"]) + 1
    x = {k: float(v) for k, v in out.params.items() if k != "model"}
    right = chosen == masses
    fixed = study(masses, seed, fixed=chosen)
    chi2, _ = base.chi2_at(fixed, {n: x[n] for n in PARAMS[chosen]})
    start = truth(masses) if right else x
    ratio = chi2 / reference(masses, seed, chosen, {**x, **start})
    err = max(abs(x[k] / truth(masses)[k] - 1) for k in PARAMS[masses]) if right else math.nan
    held = [n for n in PARAMS[masses] if right and _holds(out.intervals.get(n), truth(masses)[n])]
    open_ = [n for n in PARAMS[masses] if None in (out.intervals.get(n) or [None])]
    return {
        "masses": masses, "seed": seed, "chosen": chosen,
        "tied": bool(s.get("indistinguishable")), "why": s.get("why", ""),
        "error": err, "held": held, "open": open_, "ratio": ratio, "nfev": out.nfev,
        "params": sorted(out.params),
        "stages": {st.name: st.nfev for st in out.stages},
        "seconds": time.perf_counter() - t0,
    }  # fmt: skip


def _holds(interval: list | None, value: float) -> bool:
    """Whether a 95 % interval (``None`` for an open end) holds ``value``."""
    low, high = interval or [None, None]
    return (low is None or low <= value) and (high is None or value <= high)


def naive_route(masses: int, seed: int, cand: int) -> dict:
    """The naive study of load side ``cand`` on one data set: its simulations and BIC."""
    t0 = time.perf_counter()
    nst = study(masses, seed, fixed=cand)
    nout = identify(nst, workers=1, plots=False)
    c2, n = base.chi2_at(nst, {k: float(nout.params[k]) for k in PARAMS[cand]})
    bic = information(c2, n, len(PARAMS[cand]))[1]
    return {"nfev": nout.nfev, "bic": bic, "seconds": time.perf_counter() - t0}


def _task(key: tuple[int, int], cand: int | None) -> dict:
    """One task of a data set (in a worker process): its structure route, or a naive study."""
    masses, seed = key
    return structure_route(masses, seed) if cand is None else naive_route(masses, seed, cand)


def line(r: dict) -> str:
    """One data set's result as a line."""
    return (
        f"{r['masses']} mass(es) seed {r['seed']}: chose {r['chosen']}"
        f"{' (indist.)' if r['tied'] else ''}, naive {r.get('naive')}, error "
        f"{100 * r['error']:.3g} %, truth in {len(r['held'])} intervals (open: "
        f"{', '.join(r['open']) or 'none'}), cost ratio {r['ratio']:.6f}, " + base.route_tail(r)
    )


def table(rows: list[dict]) -> list[str]:
    """The printed (Markdown) tables."""
    picks = [
        "| true load side | chosen one mass | chosen two masses | indist. "
        "| naive (BIC) one / two |",
        "|---|---|---|---|---|",
    ]
    cells = [
        "| true load side | seeds | worst error | truth in its 95 % interval (open ones) "
        "| cost / least_squares (median, max) | <= 1.001 x "
        "| simulations: structure | naive (2 studies) | structure / naive (seeds with fewer) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for m in (1, 2):
        rs = [r for r in rows if r["masses"] == m]
        if not rs:
            continue
        pick = [sum(1 for r in rs if not r["tied"] and r["chosen"] == c) for c in (1, 2)]
        naive = "/".join(str(sum(1 for r in rs if r.get("naive") == c)) for c in (1, 2))
        tied = sum(1 for r in rs if r["tied"])
        name = "one mass (m2 = C_2 = 0)" if m == 1 else "two masses (m2 0.2, C_2 2)"
        picks.append(f"| {name} | {pick[0]} | {pick[1]} | {tied} | {naive} |")
        right = [r for r in rs if r["chosen"] == m]
        held = sum(len(r["held"]) for r in right)
        opens = sum(len(r["open"]) for r in right)
        error, *rest = base.variant_cells(rs)
        row = [str(m), str(len(rs)), error, f"{held}/{len(PARAMS[m]) * len(right)} ({opens})"]
        cells.append("| " + " | ".join([*row, *rest]) + " |")
    lines = [*picks, "", *cells]
    return lines


def main(argv: list[str] | None = None) -> list[dict]:
    """Run the benchmark and print its tables; return the rows."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=10, help="noise seeds per true variant")
    ap.add_argument("--first-seed", type=int, default=1, help="tune on 101 and up")
    ap.add_argument("--masses", type=int, nargs="*", default=[1, 2], help="true load sides")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--no-naive", action="store_true", help="skip the naive route")
    ap.add_argument("--out", type=Path, help="also write the tables to this file")
    args = ap.parse_args(argv)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    cands = () if args.no_naive else (1, 2)
    keys = [(m, s) for s in seeds for m in args.masses]
    t0 = time.perf_counter()
    rows = base.run_data_sets(keys, cands, args.workers, _task, base.join_naive, line)
    rows.sort(key=lambda r: (r["masses"], r["seed"]))
    wall = time.perf_counter() - t0
    base.report("structure_miso.py", f"{wall:.0f} s wall", table(rows),
                [line(r) for r in rows], args.out)  # fmt: skip
    return rows


if __name__ == "__main__":
    main()
