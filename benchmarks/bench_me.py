"""Model-Exchange-only FMUs: the project's integrator against FMPy's CVode, one run each.

    python benchmarks/bench_me.py [--repeats N]

Part 1 (issue 15, item 6): a first-order lag ``der(x) = (u - x)/tau`` built as an
FMI 2.0 FMU with Model Exchange only (``tests/fmu_factory.py``), 10 s at 1 kHz with a
held (zero-order-hold) input that changes at every sample. Rows: ``FMUSession`` with
the compiled integrator (default, ``me_solver="rk45"``), the same loop interpreted
(``TSID_FMU_LOOP=python``), and FMPy's CVode with an input event per sample
(``me_solver="cvode"``, the path every ME-only FMU took before). The error is the
largest deviation from the analytic solution for the held input, relative to the
largest output. Targets: >= 50x faster than the CVode path, error <= 0.01 %.

Part 2: the project's plants (``fmus/`` FMI 2.0, ``fmus/fmi3/`` FMI 3.0) in Model
Exchange through both solvers against ``models/reference/`` (NRMS; target 1 %), with
the event counts of the integrator (the SISO plant sticks and slips).
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import numpy as np
from _common import REPO, timeit

from tsid_fmu.fmu import FMUSession, compiled

TAU = 0.05


def lag_part(repeats: int) -> None:
    from fmu_factory import build_c_fmu, lag_response

    t = np.arange(10001) * 1e-3
    rng = np.random.default_rng(0)
    u = np.sign(np.sin(2 * np.pi * 0.5 * t)) + 0.2 * rng.standard_normal(t.size)
    exact = lag_response(t, u, TAU)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        fmu = build_c_fmu(Path(tmp), "LagME", interfaces=("me",))
        for label, solver, env, n in (
            ("tsid rk45 (Numba loop)", "rk45", None, repeats),
            ("tsid rk45 (Python loop)", "rk45", "python", max(3, repeats // 10)),
            ("FMPy CVode (me_solver='cvode')", "cvode", None, 3),
        ):
            if env:
                os.environ[compiled.LOOP_ENV] = env
            with FMUSession(fmu, ["u"], ["y"], parameters=["tau"], me_solver=solver) as s:
                best, median = timeit(lambda s=s: s.simulate(t, u, {"tau": TAU}), n)
                y = s.simulate(t, u, {"tau": TAU})[:, 0]
            os.environ.pop(compiled.LOOP_ENV, None)
            rows[label] = (best, median, np.max(np.abs(y - exact)) / np.max(np.abs(exact)))
    ours = rows["tsid rk45 (Numba loop)"][0]
    cvode = rows["FMPy CVode (me_solver='cvode')"][0]
    print(f"first-order lag, ME only, 10 s at 1 kHz, tau = {TAU} s; backend {compiled.backend()}")
    print(f"  {'solver':<32}{'best [ms]':>11}{'median [ms]':>13}{'max error [%]':>15}")
    for label, (b, m, err) in rows.items():
        print(f"  {label:<32}{b * 1e3:>11.2f}{m * 1e3:>13.2f}{err * 100:>15.2e}")
    print(f"  speed-up of the compiled integrator over CVode (same run): {cvode / ours:.0f}x")


def nrms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b**2)))


def plants_part() -> None:
    from fmpy.util import read_csv

    print("\nplants in Model Exchange against models/reference/ (NRMS of F_o)")
    print(f"  {'FMU':<22}{'solver':<8}{'time [ms]':>11}{'NRMS':>11}  events (state/input)")
    for model, inputs in (("LSEA_SISO", ["F_m"]), ("LSEA_MISO", ["F_m", "x_o", "v_o", "a_o"])):
        folder = REPO / "models" / "reference" / model
        inp, ref = read_csv(folder / f"{model}_in.csv"), read_csv(folder / f"{model}_ref.csv")
        t = ref["time"]
        if model == "LSEA_SISO":  # square wave: the value after each jump, held
            idx = np.searchsorted(inp["time"], t, side="right") - 1
            u, hold = np.column_stack([inp[n][idx] for n in inputs]), {}
        else:  # piecewise-linear inputs
            u = np.column_stack([np.interp(t, inp["time"], inp[n]) for n in inputs])
            hold = dict.fromkeys(inputs, "linear")
        for version, path in ((2, REPO / "fmus"), (3, REPO / "fmus" / "fmi3")):
            for solver in ("rk45", "cvode"):
                with FMUSession(
                    path / f"{model}.fmu", inputs, ["F_o"], interface="me", hold=hold,
                    me_solver=solver,
                ) as s:  # fmt: skip
                    best, _ = timeit(lambda s=s, t=t, u=u: s.simulate(t, u, {}), 3)
                    y = s.simulate(t, u, {})[:, 0]
                    ev = s.me_stats
                events = f"{ev['state_events']}/{ev['input_events']}" if ev else ""
                label = f"{model} FMI {version}"
                print(
                    f"  {label:<22}{solver:<8}{best * 1e3:>11.1f}"
                    f"{nrms(y, ref['F_o']):>11.1e}  {events}"
                )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    lag_part(args.repeats)
    plants_part()


if __name__ == "__main__":
    main()
