"""Memory and time of a study against the length of its data (issue 25: a 1,000,000-row CSV).

For each row count, a child process (so that each peak is its own) writes a CSV of a
lag's noisy response at 1 ms, then runs ``identify`` on the C factory's lag FMU in this
process (``workers=1, timeout=0``: no worker copies of the data), two Taguchi
iterations and no refinement (``refine = "none"``), and prints its peak resident memory
(``ru_maxrss``, of this process: worker processes hold their own copy), the memory per
row above the 10,000-row run, the wall time and the simulations. ``--as-users-run``:
the default method instead (noise-weighted SSE, adaptive refinement, default
replicates) on the default workers. Run::

    python benchmarks/bench_rows.py                  # 1e4, 1e5, 1e6 rows
    python benchmarks/bench_rows.py 10000 2000000
    python benchmarks/bench_rows.py --as-users-run
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile

from _common import REPO

CHILD = r"""
import json, resource, sys, time
from pathlib import Path
import numpy as np, pandas as pd
sys.path.insert(0, {tests!r}); sys.path.insert(0, {repo!r})
from fmu_factory import build_c_fmu, lag_response
from tsid_fmu import Experiment, Method, Parameter, Study, identify
n, folder, users = int(sys.argv[1]), Path(sys.argv[2]), sys.argv[3] == "users"
fmu = build_c_fmu(folder, interfaces=("cs",))
t = np.arange(n) * 1e-3
u = np.where((t % 2.0) < 1.0, 1.0, -0.5)
y = lag_response(t, u, 0.37) + np.random.default_rng(0).normal(0, 0.01, n)
pd.DataFrame({{"time": t, "u": u, "y": y}}).to_csv(folder / "d.csv", index=False)
del t, u, y
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
study = Study(
    fmu=fmu,
    parameters=[Parameter("tau", [0.05, 0.5, 2.0], min=0.0)],
    experiments=[Experiment(folder / "d.csv", inputs={{"u": "u"}}, outputs={{"y": "y"}})],
    method=Method(max_iterations=2, cost="sse", weighting="noise", replicates=2) if users
    else Method(max_iterations=2, cost="iae", weighting="none", refine="none", replicates=1),
)
res = identify(study, workers=None if users else 1, timeout=None if users else 0, plots=False)
print(json.dumps({{
    "rows": n, "seconds": time.perf_counter() - t0, "nfev": res.nfev,
    "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "before_mib": before / 1024,
}}))
"""


def run(rows: int, users: bool) -> dict:
    """Run one row count in a child process; return its figures."""
    code = CHILD.format(tests=str(REPO / "tests"), repo=str(REPO))
    with tempfile.TemporaryDirectory() as folder:
        out = subprocess.run(
            [sys.executable, "-c", code, str(rows), folder, "users" if users else "lean"],
            capture_output=True,
            text=True,
            check=False,
        )
    if out.returncode != 0:
        raise SystemExit(f"{rows} rows failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    users = "--as-users-run" in sys.argv
    counts = [int(a) for a in sys.argv[1:] if a.isdigit()] or [10_000, 100_000, 1_000_000]
    print(f"{'rows':>10} {'seconds':>8} {'sims':>5} {'peak MiB':>9} {'KiB/row':>8}")
    base = None
    for n in counts:
        r = run(n, users)
        base = base or r
        extra = r["peak_mib"] - base["peak_mib"]
        per_row = 1024 * extra / (n - base["rows"]) if n > base["rows"] else float("nan")
        print(f"{n:>10} {r['seconds']:>8.1f} {r['nfev']:>5} {r['peak_mib']:>9.0f} {per_row:>8.2f}")


if __name__ == "__main__":
    main()
