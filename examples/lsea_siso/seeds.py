"""How much the SISO example's answer depends on its replicate-noise seed.

The study adds white noise to the input for its replicates (the SISO paper's S/N over
replicates); the seed fixes that noise. This script runs the example's study with
seeds 1 to 6 and prints each answer's error against the truth, then the exact minima of
the IAE (the study's cost, Nelder-Mead) and of the squared error (scipy's least
squares) on the same data, searched from the truth and from the best answer, so the
spread of B_s can be compared with what the data determine at all.

Run:  python examples/lsea_siso/seeds.py [--seeds 1 2 3] [--workers 2]   (about 2 min)
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares, minimize

from tsid_fmu.engine import identify
from tsid_fmu.parallel import make_evaluator
from tsid_fmu.study import load_study

HERE = Path(__file__).resolve().parent
TRUTH = {"F_cm": 88.5, "F_vm": 51.5, "M_m": 4.3, "K_s": 8600.0, "B_s": 2.5}


def errors(x: dict[str, float]) -> str:
    """Format the relative errors of ``x`` against the truth, in percent."""
    return "  ".join(f"{100 * (x[n] / v - 1):+7.2f}" for n, v in TRUTH.items())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args()
    study = load_study(HERE / "study.toml")
    names = list(TRUTH)
    print(f"{'':26s}" + "  ".join(f"{n:>7s}" for n in names) + "   [% error]")
    answers = []
    for seed in args.seeds:
        res = identify(dataclasses.replace(study, seed=seed), plots=False, workers=args.workers)
        state = "converged" if res.success else "limit"
        label = f"seed {seed} ({res.nit} it, {state})"
        print(f"{label:26s}{errors(res.x)}   cost {res.fun:.4f}")
        answers.append((res.fun, res.x))

    def to_x(z: np.ndarray) -> dict[str, float]:
        return {n: TRUTH[n] * float(np.exp(v)) for n, v in zip(names, z, strict=True)}

    with make_evaluator(study, workers=1) as ev:

        def iae(z: np.ndarray) -> float:
            return float(ev.evaluate([to_x(z)], clean=True).mean_costs[0])

        ((p, y, _),) = ev.simulate_clean(TRUTH)
        sigma = np.sqrt(np.mean((y - p.measured) ** 2, axis=0))

        def residuals(z: np.ndarray) -> np.ndarray:
            ((p, y, _),) = ev.simulate_clean(to_x(z))
            return ((y - p.measured) / sigma).ravel()

        best = min(answers, key=lambda a: a[0])[1]
        starts = {"truth": np.zeros(len(names))}
        starts["best answer"] = np.log([best[n] / TRUTH[n] for n in names])
        print(f"{'truth':26s}{errors(TRUTH)}   cost {iae(starts['truth']):.4f}")
        # dry friction makes both surfaces slightly rough: local searches from two starts
        for label, z0 in starts.items():
            opt = minimize(iae, z0, method="Nelder-Mead",
                           options={"xatol": 1e-5, "fatol": 1e-6, "maxiter": 4000})  # fmt: skip
            print(f"IAE min. from {label:12s}{errors(to_x(opt.x))}   cost {opt.fun:.4f}")
            ls = least_squares(residuals, z0, diff_step=1e-4)
            print(f"SSE min. from {label:12s}{errors(to_x(ls.x))}   cost {iae(ls.x):.4f}")


if __name__ == "__main__":
    main()
