"""Share of a study's wall time spent on plots, on both bundled examples.

    python benchmarks/bench_plots.py [--repeats N] [--example siso|miso]

Runs each example study end to end with ``plots=True`` into a temporary folder and
reads the time ``identify`` spent drawing (the ``"report done"`` progress event: every
iteration's SVG figures, the simulations of each iteration's best set, and the PNG fit,
convergence and parameter plots), and prints it as a share of the study's wall time in
the same run. The same study without plots is run too, and the difference of the two
wall times is printed beside it as a cross-check (noisier: it holds all the run-to-run
variation of the study). One untimed run first starts the worker processes' caches, so
that neither timed run pays for it. Target (issue 14): plots at most 20 % of the wall
time.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from _common import REPO, cores

from tsid_fmu import identify
from tsid_fmu.study import load_study

EXAMPLES = {
    "siso": REPO / "examples" / "lsea_siso" / "study.toml",
    "miso": REPO / "examples" / "lsea_miso" / "study.toml",
}
TARGET = 0.20


def run(path: Path, plots: bool) -> tuple[float, dict]:
    """Run one study; return its wall time and the report event's figures."""
    seen: dict = {}

    def progress(event: str, info: dict) -> None:
        if event == "report done":
            seen.update(info)

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        identify(load_study(path), Path(tmp) / "out", plots=plots, progress=progress)
        wall = time.perf_counter() - t0
    return wall, seen


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--example", choices=sorted(EXAMPLES), action="append")
    args = parser.parse_args()
    print(f"plots' share of the study's wall time, {cores()} cores")
    print(f"  {'example':<8}{'wall':>9}{'plots':>9}{'share':>8}{'no plots':>10}{'diff share':>12}")
    verdicts = []
    for name in args.example or sorted(EXAMPLES):
        run(EXAMPLES[name], plots=False)  # warm-up: worker start-up, compiled loops
        shares = []
        for _ in range(args.repeats):
            wall, info = run(EXAMPLES[name], plots=True)
            bare, _ = run(EXAMPLES[name], plots=False)
            plots = float(info.get("plots_seconds", 0.0))
            report = float(info.get("seconds", 0.0))
            share = plots / wall
            shares.append(share)
            print(
                f"  {name:<8}{wall:>8.2f}s{plots:>8.2f}s{100 * share:>7.1f}%{bare:>9.2f}s"
                f"{100 * (wall - bare) / wall:>11.1f}%"
            )
            for what, sec in info.get("plots_timings", {}).items():
                print(f"      {what:<44}{sec:>7.3f} s")
            print(f"      {'report files in all (plots included)':<44}{report:>7.3f} s")
        worst = max(shares)
        verdicts.append(worst <= TARGET)
        print(
            f"  {name}: plots at most {100 * worst:.1f} % of the wall time "
            f"(median {100 * statistics.median(shares):.1f} %): "
            f"{'PASS' if worst <= TARGET else 'FAIL'} (target <= {100 * TARGET:.0f} %)"
        )
    print("all PASS" if all(verdicts) else "some FAIL")


if __name__ == "__main__":
    main()
