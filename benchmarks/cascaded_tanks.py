"""Real data: tsid and a multistart least-squares peer on the Cascaded Tanks benchmark.

One run, side by side, on the same FMU (``fmus/CascadedTanks.fmu``), the same study
(``examples/cascaded_tanks/study.toml``) and the same cost (its noise-weighted SSE on the
Est record, through ``tsid_fmu.evaluate.make_evaluator``, counting simulations as tsid
does):

- ``tsid``: ``identify`` of the example as committed;
- ``LS-multistart``: SciPy ``least_squares`` (trf, 2-point differences, bounds; the
  coordinates of ``benchmarks/generalise.py``: log or linear, scaled by the first
  ranges) from ``--starts`` (default 25) points drawn uniformly inside the first levels
  (``numpy.random.default_rng(--seed)``); the answer is the start with the lowest Est
  cost (chosen on Est, never on Val), and its simulations are those of every start.

- ``DFO-LS-multistart`` (with ``--dfols``; the optional peer ``pip install dfo-ls``,
  GPL-3.0, never a dependency): ``dfols.solve`` from the same starts, the same scaled
  bounds, ``maxfun = 100 (p + 1)`` (as ``benchmarks/local_engines.py``); the best by
  Est cost.

For each: simulations, Est RMSE and Val RMSE in V (Val simulated in free run from the
identified initial levels ``x1_0``, ``x2_0``: the protocol's stricter reading, all 1024
samples scored). Run::

    python benchmarks/cascaded_tanks.py                  # the table, as markdown
    python benchmarks/cascaded_tanks.py --starts 10      # fewer starts
    python benchmarks/cascaded_tanks.py --json out.json  # the figures, per start too
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from generalise import Scorer

from tsid_fmu import Study, identify
from tsid_fmu.evaluate import make_evaluator
from tsid_fmu.study import prepare
from tsid_fmu.uncertainty.assess import validate

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "examples" / "cascaded_tanks" / "study.toml"

#: Published Val RMSE (V) on the same records, with their sources.
PUBLISHED = [
    (
        "NLSS2 (nonlinear state space)",
        0.34,
        "Relan et al., via Table 2 of Math. Probl. Eng. 2021, 6613425",
    ),
    ("PNLSS (polynomial nonlinear state space)", 0.45, "Relan et al., ibid."),
    ("kernel-based Volterra", 0.48, "Dalla Libera et al., Automatica 2021"),
    ("Volterra, third degree", 0.54, "Math. Probl. Eng. 2021, 6613425, Table 2"),
    ("BLA (best linear approximation)", 0.76, "Relan et al., ibid."),
]


def rmse(study: Study, interface: str | None, x: dict[str, float], role: str) -> float:
    """RMSE (V) of ``y`` on the first experiment of ``role`` at the parameter set ``x``."""
    import dataclasses

    spec = prepare(study, role=role)
    if interface:
        spec = dataclasses.replace(spec, interface=interface)
    ev = make_evaluator(spec, workers=1)
    try:
        out = validate(ev, spec, x)
    finally:
        close = getattr(ev, "close", None)
        if close is not None:
            close()
    first = next(iter(out.values()))
    return float(first["fit"]["y"]["rmse"]) if "fit" in first else math.nan


def _least_squares(scorer: Scorer, s0: np.ndarray, k: int) -> np.ndarray:
    from scipy.optimize import least_squares

    lo, hi = scorer.lower, scorer.upper
    return least_squares(scorer.residuals, s0, bounds=(lo, hi), method="trf", x_scale="jac").x


def _dfols(scorer: Scorer, s0: np.ndarray, k: int) -> np.ndarray:
    from local_engines import solve_dfols

    soln, _ = solve_dfols(scorer, s0, noisy=False, seed=k)
    if soln.x is None:
        raise RuntimeError(f"DFO-LS returned no point: {soln.msg}")
    return np.asarray(soln.x)


def multistart(
    scorer: Scorer, starts: int, seed: int, solve=_least_squares
) -> tuple[dict[str, float], list[dict]]:
    """``solve`` from ``starts`` uniform points in the first levels; the best by cost."""
    rng = np.random.default_rng(seed)
    lo, hi = scorer.lower, scorer.upper
    runs, best, best_x = [], math.inf, None
    for k in range(starts):
        s0 = np.clip(rng.uniform(-0.5, 0.5, len(scorer.names)), lo + 1e-9, hi - 1e-9)
        n0, t0 = scorer.nfev, time.perf_counter()
        x = solve(scorer, s0, k)
        cost = scorer.cost(x)
        runs.append({"start": k, "cost": cost, "nfev": scorer.nfev - n0,
                     "time": time.perf_counter() - t0})  # fmt: skip
        print(f"  start {k + 1}/{starts}: cost {cost:.6g}, {runs[-1]['nfev']} simulations",
              file=sys.stderr)  # fmt: skip
        if cost < best:
            best, best_x = cost, scorer.to_x(x)
    assert best_x is not None
    return best_x, runs


def main(argv: list[str] | None = None) -> int:
    """Run tsid and the peer; print the table (markdown) and optionally write JSON."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--starts", type=int, default=25, help="least-squares starts (25)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the starts (0)")
    ap.add_argument("--json", type=Path, help="write the figures here")
    ap.add_argument("--dfols", action="store_true", help="DFO-LS from the same starts too")
    args = ap.parse_args(argv)
    if args.dfols:
        try:
            import dfols  # noqa: F401
        except ImportError:
            print("--dfols needs DFO-LS, an optional benchmark-only peer (GPL-3.0): "
                  "pip install dfo-ls", file=sys.stderr)  # fmt: skip
            return 2
    study = Study.from_toml(STUDY)
    t0 = time.perf_counter()
    res = identify(STUDY, plots=False)
    tsid_time = time.perf_counter() - t0
    interface = (res.fidelity or {}).get("interface")
    rows = {
        "tsid": {
            "nfev": int(res.nfev),
            "est": float(res.fit["est"]["y"]["rmse"]),
            "val": float(res.validation["val"]["fit"]["y"]["rmse"]),
            "cost": float(res.fun),
            "status": int(res.status),
            "time": tsid_time,
        }
    }
    peers = {
        "LS-multistart": _least_squares,
        **({"DFO-LS-multistart": _dfols} if args.dfols else {}),
    }
    for name, solve in peers.items():
        scorer = Scorer(study, interface)
        t0 = time.perf_counter()
        x, runs = multistart(scorer, args.starts, args.seed, solve)
        rows[name] = {
            "nfev": sum(r["nfev"] for r in runs),
            "est": rmse(study, interface, x, "identify"),
            "val": rmse(study, interface, x, "validate"),
            "cost": min(r["cost"] for r in runs),
            "starts": args.starts,
            "runs": runs,
            "time": time.perf_counter() - t0,
            "params": x,
        }
    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()  # fmt: skip
    print(f"commit {commit}, {time.strftime('%Y-%m-%d', time.gmtime())}, interface {interface}\n")
    print("| method | simulations | Est cost (SSE / noise²) | Est RMSE [V] | Val RMSE [V] |")
    print("|---|---|---|---|---|")
    for name, r in rows.items():
        label = f"{name} ({args.starts} starts)" if name != "tsid" else name
        print(f"| {label} | {r['nfev']} | {r['cost']:.6g} | {r['est']:.3f} | {r['val']:.3f} |")
    if args.json:
        args.json.write_text(json.dumps({"commit": commit, "interface": interface,
                                         "rows": rows}, indent=1))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
