"""Law 3's optimum on the SISO friction-law data: does any peer reach it?

``benchmarks/structure.py`` measures tsid's cost within the chosen law against SciPy's
``least_squares`` **started from the truth** (the issue's reference). On law-3 data
(Stribeck friction) tsid stops 0.6-2.7 % above that reference, as the naive law-3 study
does. This script runs, on the same data and the same noise-weighted residuals of the
law-3 FMU (``benchmarks/structure.py``'s ``study(3, seed, fixed=3)``), what a user
without the truth could run instead, each polished by ``least_squares``:

- ``LS centre``: ``least_squares`` from the centre of the first levels;
- ``DE``: SciPy ``differential_evolution`` over the first levels' box (log scale, popsize
  15, 12 generations after the first: 1365 simulations), two seeds;
- ``CMA``: CMA-ES (``cma``) over the same box (``maxfevals`` 960), two seeds.

It prints each one's cost / the reference's and its simulations. Run::

    python benchmarks/structure_peers.py --seeds 2          # seeds 1 and 2, ~10 min each
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import structure as b


def run(seed: int) -> list[tuple[str, float, int]]:
    """Return (method, cost / reference, simulations) on law-3 data of ``seed``."""
    import cma
    from scipy.optimize import differential_evolution, least_squares

    names = b.LAW_PARAMS[3]
    res, ev = b.residuals_of(b.study(3, seed, fixed=3))
    lo = np.array([b.LEVELS[n][0][0] for n in names])
    hi = np.array([b.LEVELS[n][0][-1] for n in names])
    lb = np.array([b.LEVELS[n][1] for n in names])
    box_lo, box_hi = np.log(lo), np.log(hi)

    def chi2(x: np.ndarray) -> float:
        r = res(dict(zip(names, x, strict=True)))
        return float(r @ r)

    def ls(x0: np.ndarray) -> tuple[float, int]:
        x0 = np.maximum(np.asarray(x0, dtype=float), lb + 1e-9)
        scale, n0 = np.abs(x0) + 1e-6, ev.nfev
        out = least_squares(
            lambda s: res(dict(zip(names, s * scale, strict=True))),
            x0 / scale, bounds=(lb / scale, np.inf), method="trf", x_scale="jac",
        )  # fmt: skip
        return float(out.fun @ out.fun), ev.nfev - n0

    ref, n_ref = ls(np.array([b.laws.TRUTH[3][n] for n in names]))
    rows = [("LS from the truth (reference)", 1.0, n_ref)]
    cost, n = ls(0.5 * (lo + hi))
    rows.append(("LS centre", cost / ref, n))
    for k in (1, 2):
        n0 = ev.nfev
        out = differential_evolution(
            lambda z: chi2(np.exp(z)), list(zip(box_lo, box_hi, strict=True)),
            maxiter=12, popsize=15, polish=False, seed=k, tol=1e-8,
        )  # fmt: skip
        n_de = ev.nfev - n0
        cost, n = ls(np.exp(out.x))
        rows.append((f"DE seed {k} + LS", cost / ref, n_de + n))
    for k in (1, 2):
        n0 = ev.nfev
        opts = {"bounds": [0, 1], "seed": k, "maxfevals": 960, "verbose": -9}
        es = cma.CMAEvolutionStrategy(np.zeros(len(names)), 0.25, opts)

        def at(u: np.ndarray) -> np.ndarray:
            return np.exp(box_lo + np.asarray(u) * (box_hi - box_lo))

        while not es.stop():
            pop = es.ask()
            es.tell(pop, [chi2(at(u)) for u in pop])
        n_cma = ev.nfev - n0
        cost, n = ls(at(es.result.xbest))
        rows.append((f"CMA seed {k} + LS", cost / ref, n_cma + n))
    ev.close()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=1)
    args = ap.parse_args()
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        print(f"\nlaw-3 data, seed {seed}: cost / least squares from the truth, simulations")
        for name, ratio, n in run(seed):
            print(f"  {name:32} {ratio:10.5f}  {n:6d}", flush=True)


if __name__ == "__main__":
    main()
