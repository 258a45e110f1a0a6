"""How often ``tsid identify`` on a pythonfmu FMU ends by a crash at exit (issue 25).

    python benchmarks/exit_abort.py [--tries 10] [--model lag|dcmotor] [--source DIR]

pythonfmu 0.7's library frees its interpreter state twice at ``exit()`` (a C++ static
destructor, then its own library destructor), after ``result.json`` is written:
``corrupted double-linked list`` and exit status 134, more often when two studies share
the machine.  Each try here starts two identical studies at once on a pythonfmu FMU (a
first-order lag, or the DC motor of ``benchmarks/problems/dc_motor.py`` on 0.2 s of its
data) with the default workers, and records both exit statuses.  A clean try is one
where both exit 0 or 1 (a result; 1 says a limit was reached) and both wrote
``result.json``; anything else (134, a signal) is an abort.

``--source`` runs the tsid-fmu package found in DIR instead of this checkout's (to
measure the same tries on the code before a fix, e.g. an exported older commit).

Target (issue 25): 10 clean tries out of 10.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from _common import REPO

MOTOR_TOML = """\
[study]
fmu = "{fmu}"
[data]
file = "d.csv"
inputs = {{ V = "V" }}
outputs = {{ w = "w", i = "i" }}
[method]
seed = 7
max_iterations = 2
[parameters]
{parameters}
"""


def _lag_case(folder: Path) -> Path:
    """A pythonfmu lag and 2 s of noisy data from it; return the study file."""
    from fmu_factory import PYLAG_TOML, build_pythonfmu

    import tsid_fmu

    fmu = build_pythonfmu(folder)
    t = np.round(np.arange(0, 2.0 + 1e-9, 0.01), 9)
    u = np.where((t % 1.0) < 0.5, 1.0, -0.5)
    y = tsid_fmu.simulate(fmu, pd.DataFrame({"time": t, "u": u}), parameters={"tau": 0.37})
    y = y["y"].to_numpy() + np.random.default_rng(0).normal(0, 0.003, t.size)
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(folder / "d.csv", index=False)
    (folder / "study.toml").write_text(PYLAG_TOML.format(fmu=fmu.name))
    return folder / "study.toml"


def _motor_case(folder: Path) -> Path:
    """The DC motor of benchmarks/problems on its first 0.2 s of data."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from problems.dc_motor import RANGES, build_fmu, make_data

    fmu = build_fmu()
    data = make_data()
    data[data["time"] <= 0.2].to_csv(folder / "d.csv", index=False)
    rows = [
        f"{name} = {{ levels = [{lo!r}, {(lo * hi) ** 0.5!r}, {hi!r}], min = 0 }}"
        for name, (lo, hi, _unit) in RANGES.items()
    ]
    (folder / "study.toml").write_text(MOTOR_TOML.format(fmu=fmu, parameters="\n".join(rows)))
    return folder / "study.toml"


def _try(study: Path, env: dict[str, str], k: int) -> list[tuple[int, bool, str]]:
    """Start two identical studies at once; return (status, result written, last line)."""
    procs = []
    for j in range(2):
        out = study.parent / f"out_{k}_{j}"
        cmd = [sys.executable, "-m", "tsid_fmu", "identify", str(study), "--out", str(out)]
        procs.append(
            (
                out,
                subprocess.Popen(
                    [*cmd, "--no-plots", "-q"],
                    cwd=study.parent,
                    env=env,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE,
                    text=True,
                ),
            )
        )
    results = []
    for out, proc in procs:
        _, err = proc.communicate(timeout=900)
        last = (err.strip().splitlines() or [""])[-1]
        results.append((proc.returncode, (out / "result.json").is_file(), last))
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tries", type=int, default=10)
    parser.add_argument("--model", choices=("lag", "dcmotor"), default="lag")
    parser.add_argument("--source", type=Path, default=REPO, help="folder holding tsid_fmu/")
    args = parser.parse_args()
    env = {**os.environ, "PYTHONPATH": str(args.source.resolve())}
    with tempfile.TemporaryDirectory(prefix="tsid-exit-abort-") as tmp:
        study = (_lag_case if args.model == "lag" else _motor_case)(Path(tmp))
        aborts = clean = 0
        start = time.perf_counter()
        for k in range(args.tries):
            t0 = time.perf_counter()
            results = _try(study, env, k)
            bad = [r for r in results if r[0] not in (0, 1) or not r[1]]
            aborts += len(bad)
            clean += not bad
            codes = " ".join(f"{code:4d}" for code, _, _ in results)
            note = f"  {bad[0][2][:90]}" if bad else ""
            print(f"try {k + 1:2d}: exit {codes}  {time.perf_counter() - t0:5.1f} s{note}")
        print(
            f"{args.model} from {args.source}: {clean} of {args.tries} tries clean, "
            f"{aborts} of {2 * args.tries} runs ended abnormally "
            f"({time.perf_counter() - start:.0f} s in all)"
        )
    sys.exit(1 if aborts else 0)


if __name__ == "__main__":
    main()
