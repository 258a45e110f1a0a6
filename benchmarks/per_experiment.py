"""Per-experiment parameters (issue 29, item 2): cost, simulations and array size.

N lag records (``der(x) = (u - x) / tau``), each from its own initial state, made by
SciPy's ``solve_ivp`` (not by the FMU). ``tau`` is shared, ``x0`` per experiment. For
N = 2, 4, 8 it prints:

- tsid's answer with ``x0`` per experiment: its simulations, its cost over the
  least-squares optimum (SciPy's ``least_squares`` on the same stacked residuals, from
  the truth: the baseline of this run), and how many copies' 95 % intervals hold their
  truth;
- SciPy's ``least_squares`` alone from the centre of the first levels (a local method
  with no arrays), its simulations and cost ratio;
- one shared ``x0`` instead (the model without the feature): its cost ratio;
- the rows of one array iteration with the copies held (the shared parameter only) and
  with every copy a factor of its own, as the arrays would need without the scheme.

    python benchmarks/per_experiment.py [--sizes 2 4 8]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from _common import REPO  # noqa: F401  (puts tests/ on sys.path for fmu_factory)
from fmu_factory import build_c_fmu
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from tsid_fmu import Experiment, Parameter, Study, identify
from tsid_fmu.doe.arrays import select_array
from tsid_fmu.study.prepare import serial_evaluator

TAU, SIGMA = 0.37, 0.002


def lag_ivp(t: np.ndarray, u: np.ndarray, x0: float) -> np.ndarray:
    """The lag's state at ``t`` by ``solve_ivp``, ``u[k]`` held over each interval."""
    x = np.empty(t.size)
    x[0] = x0
    for k in range(t.size - 1):
        sol = solve_ivp(lambda _t, s, uk=u[k]: (uk - s) / TAU, (t[k], t[k + 1]), [x[k]], rtol=1e-10)
        x[k + 1] = sol.y[0, -1]
    return x


def records(folder: Path, n: int) -> dict[str, tuple[Path, float]]:
    out = {}
    rng = np.random.default_rng(n)
    for k in range(n):
        x0 = float(rng.uniform(-0.9, 0.9))
        t = np.arange(0, 3.0 + 1e-9, 0.01)
        u = np.where((t % 2.0) < 1.0, 1.0, -0.5) + 0.3 * np.sin(3 * t + k)
        y = lag_ivp(t, u, x0) + rng.normal(0, SIGMA, t.size)
        path = folder / f"e{k + 1}.csv"
        pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(path, index=False)
        out[f"e{k + 1}"] = (path, x0)
    return out


def study(fmu: Path, recs: dict[str, tuple[Path, float]], own: bool) -> Study:
    params = [
        Parameter("tau", [0.1, 0.4, 1.6], min=0.01),
        Parameter("x0", [-1.0, 0.0, 1.0], per_experiment=own),
    ]
    exps = [
        Experiment(data=p, name=n, inputs={"u": "u"}, outputs={"y": "y"})
        for n, (p, _) in recs.items()
    ]
    return Study(fmu, params, exps, cost="sse", weighting="noise", replicates=1)


def scipy_fit(s: Study, start: dict[str, float]) -> tuple[float, int]:
    """Least squares on the study's stacked residuals: (cost, simulations)."""
    names = s.parameter_names
    with serial_evaluator(s) as ev:

        def residuals(v: np.ndarray) -> np.ndarray:
            return np.asarray(ev.evaluate([dict(zip(names, v, strict=True))]).residuals[0])

        fit = least_squares(residuals, [start[n] for n in names], x_scale="jac", xtol=1e-12)
        return float(np.sum(fit.fun**2)), int(ev.nfev)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[2, 4, 8])
    args = parser.parse_args()
    head = (
        f"{'N':>3} {'tsid sims':>9} {'tsid/opt':>9} {'x0 in CI':>8} {'scipy sims':>10} "
        f"{'scipy/opt':>9} {'shared/opt':>10} {'rows held':>9} {'rows copies':>11} {'s':>6}"
    )
    print(head)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        fmu = build_c_fmu(folder, interfaces=("cs",))
        for n in args.sizes:
            t0 = time.perf_counter()
            sub = folder / f"n{n}"
            sub.mkdir()
            recs = records(sub, n)
            own = study(fmu, recs, own=True)
            truth = {"tau": TAU, **{f"x0[{e}]": x0 for e, (_, x0) in recs.items()}}
            best, _ = scipy_fit(own, truth)  # the baseline: the optimum, from the truth
            res = identify(own, plots=False, workers=1)
            inside = sum(
                res.intervals[f"x0[{e}]"][0] <= x0 <= res.intervals[f"x0[{e}]"][1]
                for e, (_, x0) in recs.items()
            )
            centre = {"tau": 0.4, **{f"x0[{e}]": 0.0 for e in recs}}
            alone, alone_nfev = scipy_fit(own, centre)
            shared = identify(study(fmu, recs, own=False), plots=False, workers=1)
            held = select_array([3])[0].n_runs
            copies = select_array([3] * (1 + n))[0].n_runs
            print(
                f"{n:>3} {res.nfev:>9} {res.fun / best:>9.5f} {inside:>5}/{n:<2} "
                f"{alone_nfev:>10} {alone / best:>9.5f} {shared.fun / best:>10.1f} "
                f"{held:>9} {copies:>11} {time.perf_counter() - t0:>6.1f}"
            )


if __name__ == "__main__":
    main()
