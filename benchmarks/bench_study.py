"""The whole SISO example study: wall time and simulations, serial vs parallel.

    python benchmarks/bench_study.py [--workers N] [--python-loop]

Runs ``examples/lsea_siso/study.toml`` end to end (FMU loading included, no plots) with
the serial evaluator and with the parallel one, and checks that both find bit-identical
costs. Target (issue 5): under 20 s wall time on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import tsid_fmu.engine as engine
from _common import REPO, cores
from tsid_fmu.parallel import ParallelEvaluator
from tsid_fmu.runner import Evaluator

from tsid_fmu.fmu import compiled as fastloop
from tsid_fmu.study import load_study

STUDY = REPO / "examples" / "lsea_siso" / "study.toml"


def run(label: str, factory) -> tuple[float, object]:
    t0 = time.perf_counter()
    study = load_study(STUDY)
    with factory(study) as evaluator:  # FMU loading (and worker start-up) is timed
        result = engine.identify(study, plots=False, evaluator=evaluator)
    wall = time.perf_counter() - t0
    print(f"  {label:<28}{wall:>9.2f} s{result.nfev:>8d}{result.nit:>6d}   {result.fun:.9g}")
    return wall, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=cores())
    parser.add_argument("--python-loop", action="store_true", help="also time the Python loop")
    args = parser.parse_args()
    fastloop.warm_up()
    print(f"SISO example study, {cores()} cores available, loop backend {fastloop.backend()}")
    print(f"  {'evaluator':<28}{'wall':>11}{'nfev':>8}{'nit':>6}   best cost")
    rows = {}
    if args.python_loop:
        os.environ[fastloop.LOOP_ENV] = "python"
        rows["serial, Python loop"] = run("serial, Python loop", Evaluator)
        os.environ.pop(fastloop.LOOP_ENV)
    rows["serial"] = run("serial", Evaluator)
    rows["parallel"] = run(
        f"parallel, {args.workers} workers",
        lambda study: ParallelEvaluator(study, workers=args.workers),
    )
    (ws, rs), (wp, rp) = rows["serial"], rows["parallel"]
    same = rs.x == rp.x and all(
        np.array_equal(a.costs, b.costs) for a, b in zip(rs.iterations, rp.iterations, strict=True)
    )
    print(f"\nspeed-up parallel/serial: {ws / wp:.2f}x; costs bit-identical: {same}")
    print(f"target: whole study < 20 s on 2 cores: {'PASS' if wp < 20 else 'FAIL'} ({wp:.1f} s)")


if __name__ == "__main__":
    main()
