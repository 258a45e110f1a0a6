"""``tsid_fmu.simulate`` against FMPy's ``simulate_fmu``, side by side on the same run.

    python benchmarks/bench_simulate.py [--repeats N]

The SISO plant ``fmus/LSEA_SISO.fmu``, 10 s at 1 kHz, input F_m from
``examples/lsea_siso/measured.csv``, outputs F_o and x_m, default parameters.  Both
calls start from a file name and a table and return the outputs; the first call of each
is not timed (tsid_fmu extracts and instantiates the FMU then and keeps the session;
FMPy does that at every call).  Best and median of the repeats.

Target: tsid_fmu.simulate >= 10x faster than FMPy's simulate_fmu.
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd
from _common import REPO, timeit

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
    rows = {
        "tsid_fmu.simulate": timeit(ours, args.repeats),
        "fmpy.simulate_fmu": timeit(theirs, max(3, args.repeats // 4)),
    }
    print(f"LSEA SISO FMU, {t.size - 1} steps, inputs F_m, outputs {', '.join(OUTPUTS)}")
    print(f"  {'call':<20}{'best [ms]':>11}{'median [ms]':>13}")
    for label, (best, median) in rows.items():
        print(f"  {label:<20}{best * 1e3:>11.3f}{median * 1e3:>13.3f}")
    ratio = rows["fmpy.simulate_fmu"][0] / rows["tsid_fmu.simulate"][0]
    print(f"\nacceptance (best of runs): tsid_fmu.simulate {ratio:.1f}x faster than FMPy "
          f"(target >= 10x): {'PASS' if ratio >= 10 else 'FAIL'}")  # fmt: skip


if __name__ == "__main__":
    main()
