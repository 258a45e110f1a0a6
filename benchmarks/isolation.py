"""The cost of isolating the simulations in one worker process, against this process.

    python benchmarks/isolation.py [--sets N] [--rounds R] [--study]

With one worker (``--workers 1``, or one usable core) a study runs its simulations in
one worker process (:class:`~tsid_fmu.evaluate.pool.PoolEvaluator`), so that the time
limit holds and a crashing FMU fails only its row; ``timeout=0`` keeps them in this
process (:class:`~tsid_fmu.evaluate.serial.SerialEvaluator`). This measures what that
isolation costs on the SISO example: simulations per second of both evaluators on the
same parameter sets (batches of ``--sets``, as the L25 array sends them), alternated over
``--rounds`` in the same run, start-up (worker start, FMU extraction) timed apart. With
``--study`` the whole example study runs both ways too (wall time).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from _common import REPO

from tsid_fmu import identify
from tsid_fmu.evaluate import PoolEvaluator, SerialEvaluator
from tsid_fmu.study import load_study, prepare

STUDY = REPO / "examples" / "lsea_siso" / "study.toml"


def parameter_sets(study, n: int, seed: int) -> list[dict[str, float]]:
    """``n`` sets drawn between each parameter's lowest and highest first level."""
    rng = np.random.default_rng(seed)
    ranges = {p.name: (min(p.levels), max(p.levels)) for p in study.parameters}
    return [{k: float(rng.uniform(lo, hi)) for k, (lo, hi) in ranges.items()} for _ in range(n)]


def rate(ev, sets: list[dict[str, float]]) -> float:
    """Simulations per second of ``ev`` on ``sets`` (never seen by it before)."""
    before = ev.nfev
    t0 = time.perf_counter()
    ev.evaluate(sets)
    return (ev.nfev - before) / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", type=int, default=25)
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--study", action="store_true", help="the whole study both ways too")
    args = parser.parse_args()
    study = load_study(STUDY)
    spec = prepare(study)
    t0 = time.perf_counter()
    serial = SerialEvaluator(spec)
    t_serial = time.perf_counter() - t0
    t0 = time.perf_counter()
    pool = PoolEvaluator(spec, workers=1)
    t_pool = time.perf_counter() - t0
    rates: dict[str, list[float]] = {"in this process": [], "one worker process": []}
    with serial, pool:
        rate(serial, parameter_sets(study, 3, 99))  # warm both up
        rate(pool, parameter_sets(study, 3, 99))
        for r in range(args.rounds):
            sets = parameter_sets(study, args.sets, r)
            order = [("in this process", serial), ("one worker process", pool)]
            for label, ev in order if r % 2 == 0 else order[::-1]:
                rates[label].append(rate(ev, sets))
    print(f"SISO example, {args.rounds} rounds of {args.sets} parameter sets, alternated")
    print(f"  start-up: in this process {t_serial:.2f} s, one worker process {t_pool:.2f} s")
    for label, values in rates.items():
        print(f"  {label:<22}{statistics.median(values):9.1f} simulations/s (median)")
    ratio = statistics.median(rates["one worker process"]) / statistics.median(
        rates["in this process"]
    )
    print(f"  ratio one worker process / in this process: {ratio:.3f}")
    if args.study:
        for label, timeout in (("in this process", 0), ("one worker process", None)):
            t0 = time.perf_counter()
            result = identify(study, workers=1, timeout=timeout, plots=False)
            wall = time.perf_counter() - t0
            print(f"  study, {label:<20}{wall:8.2f} s, {result.nfev} simulations")


if __name__ == "__main__":
    main()
