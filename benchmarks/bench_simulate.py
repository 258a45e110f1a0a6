"""``tsid_fmu.simulate`` against FMPy's ``simulate_fmu``, side by side on the same run.

    python benchmarks/bench_simulate.py [--repeats N]

The SISO plant ``fmus/LSEA_SISO.fmu``, 10 s at 1 kHz, input F_m from
``examples/lsea_siso/measured.csv``, outputs F_o and x_m, default parameters.  Both
calls start from a file name and a table and return the outputs; the first call of each
is not timed (tsid_fmu extracts and instantiates the FMU then and keeps the session;
FMPy does that at every call).  The calls are timed in paired rounds (one FMPy call,
then four tsid calls), so that both see the same load of a shared machine; the ratio
is the median over the rounds of FMPy's time over tsid's best in the round.

Target: tsid_fmu.simulate >= 10x faster than FMPy's simulate_fmu.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np
import pandas as pd
from _common import REPO

import tsid_fmu

FMU = REPO / "fmus" / "LSEA_SISO.fmu"
DATA = REPO / "examples" / "lsea_siso" / "measured.csv"
OUTPUTS = ["F_o", "x_m"]


def main() -> None:
    import fmpy

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    data = pd.read_csv(DATA)[["time", "F_m"]]
    t = data["time"].to_numpy()
    signal = np.zeros(t.size, dtype=[("time", np.float64), ("F_m", np.float64)])
    signal["time"], signal["F_m"] = t, data["F_m"].to_numpy()
    dt = float(t[1] - t[0])

    def ours() -> pd.DataFrame:
        return tsid_fmu.simulate(FMU, data, outputs=OUTPUTS)

    def theirs() -> np.ndarray:
        return fmpy.simulate_fmu(
            str(FMU), input=signal, output=OUTPUTS, step_size=dt, output_interval=dt,
            stop_time=float(t[-1]), validate=False,
        )  # fmt: skip

    a, b = ours(), theirs()
    for name in OUTPUTS:  # same answer (FMPy lags no output here: no feed-through)
        np.testing.assert_allclose(a[name], np.interp(t, b["time"], b[name]), rtol=1e-9)
    # paired rounds: one FMPy call, then a few tsid calls, so that both see the same load
    # of this shared machine; the ratio of each round is FMPy's time over tsid's best
    ours(), theirs()  # warm-up
    rounds = max(3, args.repeats // 4)
    mine: list[float] = []
    fmpy_times: list[float] = []
    ratios = []
    for _ in range(rounds):
        fmpy_times.append(seconds(theirs))
        batch = [seconds(ours) for _ in range(4)]
        mine += batch
        ratios.append(fmpy_times[-1] / min(batch))
    print(f"LSEA SISO FMU, {t.size - 1} steps, inputs F_m, outputs {', '.join(OUTPUTS)}")
    print(f"  {'call':<20}{'best [ms]':>11}{'median [ms]':>13}")
    for label, times in (("tsid_fmu.simulate", mine), ("fmpy.simulate_fmu", fmpy_times)):
        best, median = min(times), statistics.median(times)
        print(f"  {label:<20}{best * 1e3:>11.3f}{median * 1e3:>13.3f}")
    ratio = statistics.median(ratios)
    print(f"\nratio per round (FMPy / tsid, {rounds} rounds): {min(ratios):.1f} .. "
          f"{max(ratios):.1f}x")  # fmt: skip
    print(f"acceptance (median of the rounds): tsid_fmu.simulate {ratio:.1f}x faster than "
          f"FMPy (target >= 10x): {'PASS' if ratio >= 10 else 'FAIL'}")  # fmt: skip


def seconds(fn: Callable[[], object]) -> float:
    """Wall seconds of one call of ``fn``."""
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
