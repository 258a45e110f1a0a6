"""A whole example study end to end: wall time and simulations, serial vs parallel.

    python benchmarks/bench_study.py [siso|miso] [--workers N] [--python-loop]

Runs the example's ``study.toml`` through :func:`tsid_fmu.identify` (FMU loading and
worker start-up included, no plots, no output folder) once with ``workers=1,
timeout=0`` (in this process) and once with ``--workers`` processes, and checks
that both give the same answer with the same number of simulations, cost for cost (the
result does not depend on the worker count). The speed-up is quoted against the serial
run of the same process.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from _common import REPO, cores

from tsid_fmu import identify
from tsid_fmu.fmu import compiled
from tsid_fmu.study import load_study

STUDIES = {
    "siso": REPO / "examples" / "lsea_siso" / "study.toml",
    "miso": REPO / "examples" / "lsea_miso" / "study.toml",
}


def run(label: str, example: str, workers: int) -> tuple[float, object]:
    """Identify ``example`` with ``workers`` and print one row; return (wall, result).

    ``workers=1`` runs in this process (``timeout=0``), not in one worker process.
    """
    t0 = time.perf_counter()
    timeout = 0 if workers == 1 else None
    result = identify(load_study(STUDIES[example]), workers=workers, timeout=timeout, plots=False)
    wall = time.perf_counter() - t0
    print(f"  {label:<28}{wall:>9.2f} s{result.nfev:>8d}{result.nit:>6d}   {result.fun:.9g}")
    return wall, result


def same_runs(a: object, b: object) -> bool:
    """Whether two results ran the same parameter sets with bit-identical costs."""
    if a.params != b.params or a.nfev != b.nfev or len(a.iterations) != len(b.iterations):
        return False
    return all(
        np.array_equal(ra.runs_frame().to_numpy(), rb.runs_frame().to_numpy())
        for ra, rb in zip(a.iterations, b.iterations, strict=True)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("example", nargs="?", default="siso", choices=sorted(STUDIES))
    parser.add_argument("--workers", type=int, default=max(2, cores()))
    parser.add_argument("--python-loop", action="store_true", help="also time the Python loop")
    args = parser.parse_args()
    compiled.warm_up()
    print(f"{args.example} example study, {cores()} cores, loop backend {compiled.backend()}")
    print(f"  {'evaluator':<28}{'wall':>11}{'nfev':>8}{'nit':>6}   best cost")
    if args.python_loop:
        os.environ[compiled.LOOP_ENV] = "python"
        run("serial, Python loop", args.example, 1)
        os.environ.pop(compiled.LOOP_ENV)
    ws, rs = run("serial", args.example, 1)
    wp, rp = run(f"parallel, {args.workers} workers", args.example, args.workers)
    print(f"\nspeed-up parallel/serial: {ws / wp:.2f}x; same runs and costs: {same_runs(rs, rp)}")


if __name__ == "__main__":
    main()
