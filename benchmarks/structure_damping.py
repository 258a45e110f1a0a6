"""Structure identification on the SISO plant: spring damping on or off, from the data.

    python benchmarks/structure_damping.py [--seeds 10] [--first-seed 1] [--workers K]
                                           [--joint] [--no-naive] [--out FILE]

Data: ``examples/lsea_siso/friction_laws.py`` (the independent simulator, piecewise exact
for law 2) of the SISO rig (load cells 4 N each, encoder 1 um), friction law 2, with the
spring damping on (``B_s`` = 2.5 N.s/m, Table IV) or off (``B_s`` = 0), over noise seeds.
Model: ``fmus/LSEA_SISO_Friction.fmu`` (``parameter Integer damping``, 1 on, 0 off).

For each data set:

* **structure**: one study with ``damping = { choices = [0, 1] }`` beside law 2's Real
  parameters (``benchmarks/structure.py``'s first levels), friction fixed at law 2;
  with ``--joint`` also ``friction = { choices = [1, 2, 3] }`` and law 3's parameters
  (six candidate structures);
* **naive**: the same study with damping fixed (and only that structure's parameters),
  once per choice, the lowest BIC its choice;
* **reference**: SciPy ``least_squares`` at the chosen structure from the truth (where
  the true one is chosen) or from tsid's answer, in the same cost.

Printed: the confusion matrix (true damping against the chosen one), the worst relative
error of the true structure's parameters, the cost over the reference's, and the
simulations of the structure study and the naive route, with their ratio.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import structure as base

from tsid_fmu import Choice, Experiment, Parameter, Study, identify
from tsid_fmu.search.structure.selection import information

laws = base.laws
#: Law 2's Real parameters with damping on; off, B_s has no effect.
PARAMS = {1: base.LAW_PARAMS[2], 0: [n for n in base.LAW_PARAMS[2] if n != "B_s"]}


def truth(on: int) -> dict[str, float]:
    """The true parameters: Table IV, with B_s = 0 where the damping is off."""
    return {**laws.TRUTH[2], **({} if on else {"B_s": 0.0})}


def study(on: int, seed: int, fixed: int | None = None, joint: bool = False) -> Study:
    """The structure study on damping-``on`` data (``fixed``: the naive study of one)."""
    data = laws.make_data(2, seed, truth(on))
    names = PARAMS[fixed] if fixed is not None else (base.LAW_PARAMS[3] if joint else PARAMS[1])
    levels = base.LEVELS
    params: list = [Parameter(n, levels[n][0], min=levels[n][1], max=math.inf) for n in names]
    start: dict[str, float] = {"V_z": laws.base.V_Z}
    if fixed is not None:
        start.update(damping=fixed, friction=2)
    else:
        params.append(Choice("damping", [0, 1]))
        if joint:
            params.append(Choice("friction", [1, 2, 3]))
        else:
            start["friction"] = 2
    exp = Experiment(
        data,
        inputs={"F_m": "F_m"},
        outputs={"F_o": "F_o", "x_m": "x_m"},
        derived={"F_o": "F_of - F_or"},
        noise={"x_m": base.ENCODER_SIGMA},
        name="measured",
    )
    return Study(
        fmu=base.FMU, parameters=params, experiments=[exp], start_values=start,
        method=base.METHOD,
        name=f"damping{on}_seed{seed}" + ("" if fixed is None else f"_fixed{fixed}"),
    )  # fmt: skip


def reference(on: int, seed: int, chosen: int, start: dict[str, float]) -> float:
    """SciPy least_squares at damping ``chosen`` (law 2) from ``start``: its chi2."""
    lower = {n: base.LEVELS[n][1] for n in PARAMS[chosen]}
    return base.least_squares_at(study(on, seed, fixed=chosen), PARAMS[chosen], lower, start)[0]


def structure_route(on: int, seed: int, joint: bool) -> dict:
    """The structure study on one data set, with the reference at its choice."""
    t0 = time.perf_counter()
    out = identify(study(on, seed, joint=joint), workers=1, plots=False)
    s = out.structure
    chosen = int(s["values"]["damping"])
    law = int(s["values"].get("friction", 2))
    x = {k: float(v) for k, v in out.params.items() if k not in ("damping", "friction")}
    right = chosen == on and law == 2
    ratio, err = math.nan, math.nan
    if law == 2:  # the cost at the chosen damping, over least squares there
        fixed = study(on, seed, fixed=chosen)
        chi2, _ = base.chi2_at(fixed, {n: x[n] for n in PARAMS[chosen]})
        start = truth(on) if right else x
        ratio = chi2 / reference(on, seed, chosen, {**x, **start})
    if right:
        err = max(abs(x[k] / truth(on)[k] - 1) for k in PARAMS[on])
    return {
        "on": on, "seed": seed, "chosen": chosen, "law": law,
        "tied": bool(s.get("indistinguishable")), "why": s.get("why", ""),
        "error": err, "ratio": ratio, "nfev": out.nfev,
        "stages": {st.name: st.nfev for st in out.stages},
        "seconds": time.perf_counter() - t0,
    }  # fmt: skip


def naive_route(on: int, seed: int, cand: int) -> dict:
    """The naive study of damping ``cand`` on one data set: its simulations and BIC."""
    t0 = time.perf_counter()
    nst = study(on, seed, fixed=cand)
    nout = identify(nst, workers=1, plots=False)
    c2, n = base.chi2_at(nst, {k: float(nout.params[k]) for k in PARAMS[cand]})
    bic = information(c2, n, len(PARAMS[cand]))[1]
    return {"nfev": nout.nfev, "bic": bic, "seconds": time.perf_counter() - t0}


def _task(key: tuple[int, int, bool], cand: int | None) -> dict:
    """One task of a data set (in a worker process): its structure route, or a naive study."""
    on, seed, joint = key
    return structure_route(on, seed, joint) if cand is None else naive_route(on, seed, cand)


def line(r: dict) -> str:
    """One data set's result as a line."""
    return (
        f"damping {r['on']} seed {r['seed']}: chose damping {r['chosen']} law {r['law']}"
        f"{' (indist.)' if r['tied'] else ''}, naive {r.get('naive')}, error "
        f"{100 * r['error']:.3g} %, cost ratio {r['ratio']:.6f}, " + base.route_tail(r)
    )


def table(rows: list[dict]) -> list[str]:
    """The printed (Markdown) tables."""
    lines = [
        "| true damping | chosen off | chosen on | other law | indist. | naive (BIC) off / on |",
        "|---|---|---|---|---|---|",
    ]
    for on in (0, 1):
        rs = [r for r in rows if r["on"] == on]
        if not rs:
            continue
        pick = [sum(1 for r in rs if not r["tied"] and r["law"] == 2 and r["chosen"] == c)
                for c in (0, 1)]  # fmt: skip
        other = sum(1 for r in rs if r["law"] != 2)
        naive = "/".join(str(sum(1 for r in rs if r.get("naive") == c)) for c in (0, 1))
        tied = sum(1 for r in rs if r["tied"])
        name = "on (B_s 2.5)" if on else "off (B_s 0)"
        lines.append(f"| {name} | {pick[0]} | {pick[1]} | {other} | {tied} | {naive} |")
    lines += [
        "",
        "| true damping | seeds | worst error | cost / least_squares (median, max) | <= 1.001 x "
        "| simulations: structure | naive (2 studies) | structure / naive (seeds with fewer) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for on in (0, 1):
        rs = [r for r in rows if r["on"] == on]
        if not rs:
            continue
        lines.append("| " + " | ".join([str(on), str(len(rs)), *base.variant_cells(rs)]) + " |")
    return lines


def main(argv: list[str] | None = None) -> list[dict]:
    """Run the benchmark and print its tables; return the rows."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=10, help="noise seeds per true variant")
    ap.add_argument("--first-seed", type=int, default=1, help="tune on 101 and up")
    ap.add_argument("--damping", type=int, nargs="*", default=[0, 1], help="true variants")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--joint", action="store_true", help="friction law chosen too")
    ap.add_argument("--no-naive", action="store_true", help="skip the naive route")
    ap.add_argument("--out", type=Path, help="also write the tables to this file")
    args = ap.parse_args(argv)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    cands = () if args.no_naive else (0, 1)
    keys = [(on, s, args.joint) for s in seeds for on in args.damping]
    t0 = time.perf_counter()
    rows = base.run_data_sets(keys, cands, args.workers, _task, base.join_naive, line)
    rows.sort(key=lambda r: (r["on"], r["seed"]))
    wall = time.perf_counter() - t0
    base.report("structure_damping.py", f"{wall:.0f} s wall", table(rows),
                [line(r) for r in rows], args.out)  # fmt: skip
    return rows


if __name__ == "__main__":
    main()
