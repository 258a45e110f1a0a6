"""Time per simulation, side by side on the same FMU and inputs.

    python benchmarks/bench_loop.py [--repeats N]

Rows: the project's session with the Numba loop (default), the same session with the
Python loop, FMPy's ``simulate_fmu``, and a pure C master loop compiled here with gcc
(the floor). FMUs: a trivial feed-through (10 s at 1 kHz, with input) built by
``tests/crash_factory.py``, and ``fmus/LSEA_SISO.fmu`` driven by the SISO example data.
Times include everything a study pays per run (reset, parameters, initialization, the
step loop, terminate); FMU loading is done once, outside the timing, for all rows.

Targets (issue 5): feed-through >= 50x faster than FMPy and within 2x of C; SISO within
1.5x of C.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import numpy as np
from _common import REPO, build_master, run_master, timeit

from tsid_fmu.fmu import FMUSession
from tsid_fmu.fmu import compiled as fastloop


def bench(name, fmu, t, u, inputs, outputs, work, exe, repeats, fmpy_repeats):
    import fmpy

    rows = {}
    # read-only copies, as a study passes them (runner.prepare_experiment): the session
    # then checks the time and input arrays once instead of at every simulation
    t_ro, u_ro = np.array(t, dtype=np.float64), np.array(u, dtype=np.float64)
    t_ro.flags.writeable = u_ro.flags.writeable = False
    with FMUSession(fmu, inputs, outputs) as s:
        os.environ.pop(fastloop.LOOP_ENV, None)
        rows["tsid (Numba loop)"] = timeit(lambda: s.simulate(t_ro, u_ro, {}), repeats)
        y_ours = s.simulate(t, u, {})
        os.environ[fastloop.LOOP_ENV] = "python"
        rows["tsid (Python loop)"] = timeit(lambda: s.simulate(t, u, {}), max(3, repeats // 10))
        os.environ.pop(fastloop.LOOP_ENV)
    signal = np.zeros(t.size, dtype=[("time", np.float64)] + [(n, np.float64) for n in inputs])
    signal["time"] = t
    for j, n in enumerate(inputs):
        signal[n] = u[:, j]
    dt = float(t[1] - t[0])

    def run_fmpy():
        return fmpy.simulate_fmu(
            str(fmu), input=signal, output=list(outputs), step_size=dt,
            output_interval=dt, stop_time=float(t[-1]), validate=False,
        )  # fmt: skip

    rows["FMPy simulate_fmu"] = timeit(run_fmpy, fmpy_repeats)
    best, mean, last = run_master(exe, fmu, work, t, u, inputs, outputs, repeats)
    rows["pure C master loop"] = (best, mean)
    assert np.isclose(last, y_ours[-1, 0], rtol=1e-9, atol=1e-12), (last, y_ours[-1, 0])

    floor = rows["pure C master loop"][0]
    ours = rows["tsid (Numba loop)"][0]
    print(f"\n{name}: {t.size - 1} steps, backend {fastloop.backend()}")
    print(f"  {'master':<22}{'best [ms]':>11}{'median [ms]':>13}{'x C floor':>11}{'x tsid':>9}")
    for label, (b, m) in rows.items():
        print(f"  {label:<22}{b * 1e3:>11.3f}{m * 1e3:>13.3f}{b / floor:>11.2f}{b / ours:>9.1f}")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()
    import pandas as pd
    from crash_factory import build_crash_fmu

    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        exe = build_master(work)
        feed = build_crash_fmu(work, "FeedThrough")
        t = np.arange(10001) * 1e-3
        u = np.sin(2 * np.pi * t)[:, None]
        a = bench("feed-through FMU (10 s at 1 kHz)", feed, t, u, ["u"], ["y"], work, exe,
                  args.repeats, 3)  # fmt: skip
        data = pd.read_csv(REPO / "examples" / "lsea_siso" / "measured.csv")
        ts = data["time"].to_numpy()
        us = data[["F_m"]].to_numpy()
        b = bench("LSEA SISO FMU (SISO example data)", REPO / "fmus" / "LSEA_SISO.fmu", ts, us,
                  ["F_m"], ["F_o", "x_m"], work, exe, max(5, args.repeats // 5), 2)  # fmt: skip
    r1 = a["FMPy simulate_fmu"][0] / a["tsid (Numba loop)"][0]
    r2 = a["tsid (Numba loop)"][0] / a["pure C master loop"][0]
    r3 = b["tsid (Numba loop)"][0] / b["pure C master loop"][0]
    print("\nacceptance (best of runs):")
    print(f"  feed-through: tsid {r1:.0f}x faster than FMPy (target >= 50x): "
          f"{'PASS' if r1 >= 50 else 'FAIL'}")  # fmt: skip
    print(f"  feed-through: tsid / C = {r2:.2f} (target <= 2): {'PASS' if r2 <= 2 else 'FAIL'}")
    print(f"  SISO:         tsid / C = {r3:.2f} (target <= 1.5): {'PASS' if r3 <= 1.5 else 'FAIL'}")


if __name__ == "__main__":
    main()
