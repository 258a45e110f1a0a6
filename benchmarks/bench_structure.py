"""What a discrete factor that forces a fresh instance costs, in simulations per second.

    python benchmarks/bench_structure.py [--runs 300] [--samples 1001] [--pythonfmu]

A structure study changes discrete ``fixed`` switches (FMU Integer/Boolean/Enumeration
variables with ``variability="fixed"``, FMI 3 structural parameters) from run to run;
such a change gets a fresh instance (free + instantiate) instead of ``fmi2Reset``
(``tsid_fmu.fmu.variables.restarts_instance``). Three sequences of runs on the same
session, the same FMU and data:

* ``reset``: only a Real parameter changes (the baseline: every run resets);
* ``switch, same value``: the Boolean switch is set every run, always to the same value
  (a study whose discrete factor is fixed: still a reset);
* ``switch alternating``: the switch flips every run (every run a fresh instance: the
  worst case; an orthogonal array's rows change it about every other run).

The hand-written C lag of ``tests/fmu_factory.py`` (cheap to instantiate), and with
``--pythonfmu`` the pythonfmu lag with a Boolean switch (a Python class behind the FMI
calls). The table gives simulations per second (the best of three measurements) and the
ratio to the baseline measured in the same run.
"""

from __future__ import annotations

import argparse
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np
from _common import REPO  # noqa: F401  (puts tests/ on the path)
from fmu_factory import build_c_fmu, pythonfmu_available

from tsid_fmu.fmu import FMUSession

PYSWITCH = '''
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class PySwitch(Fmi2Slave):
    """First-order lag with a Boolean offset switch (fixed)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u, self.y, self.tau, self.offset_on = 0.0, 0.0, 1.0, False
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        self.register_variable(Real("tau", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))
        self.register_variable(Boolean("offset_on", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed))

    def do_step(self, current_time, step_size):
        self.y += step_size * (self.u - self.y) / self.tau
        return True
'''


def _pythonfmu(folder: Path) -> Path:
    import subprocess
    import sys

    script = folder / "pyswitch.py"
    script.write_text(textwrap.dedent(PYSWITCH))
    subprocess.run(
        [sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(folder)],
        check=True,
        capture_output=True,
    )
    return folder / "PySwitch.fmu"


def _rate(fmu: Path, runs: int, samples: int, sequence: str) -> tuple[float, int]:
    t = np.linspace(0.0, 1.0, samples)
    t.flags.writeable = False
    u = np.where(t < 0.5, 1.0, 0.0).reshape(-1, 1)
    u.flags.writeable = False

    def params(k: int) -> dict[str, float]:
        tau = 0.3 + 0.001 * k
        switch = {"reset": 0, "switch, same value": 0, "switch alternating": k % 2}[sequence]
        return {"tau": tau} if sequence == "reset" else {"tau": tau, "offset_on": switch}

    with FMUSession(fmu, ["u"], ["y"], parameters=["tau", "offset_on"]) as s:
        s.simulate(t, u, params(-1))  # warm up (the structure of the odd runs)
        start = time.perf_counter()
        for k in range(runs):
            s.simulate(t, u, params(k))
        seconds = time.perf_counter() - start
        return runs / seconds, s.instantiations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=300)
    parser.add_argument("--samples", type=int, default=1001)
    parser.add_argument("--pythonfmu", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        fmus = {"C lag (fmu_factory)": build_c_fmu(folder, "Lag", interfaces=("cs",))}
        if args.pythonfmu and pythonfmu_available():
            fmus["pythonfmu lag"] = _pythonfmu(folder)
        print(f"{args.runs} runs of {args.samples} samples each\n")
        print(f"{'FMU':<22} {'sequence':<20} {'sim/s':>9} {'ratio':>7} {'instances':>10}")
        for label, fmu in fmus.items():
            base = None
            for sequence in ("reset", "switch, same value", "switch alternating"):
                # the best of 3 (the machine is shared: the least disturbed measurement)
                tries = [_rate(fmu, args.runs, args.samples, sequence) for _ in range(3)]
                rate, made = max(tries)
                base = base or rate
                print(f"{label:<22} {sequence:<20} {rate:>9.1f} {rate / base:>7.3f} {made:>10d}")


if __name__ == "__main__":
    main()
