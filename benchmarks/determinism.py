"""Identical runs identical: the SISO example N times, with 1 and 2 workers, some loaded.

Issue 49's acceptance: every run of the same study on the same data gives the same
``nfev`` and the same ``result.json`` (its ``digest`` and timings aside), whatever the
number of workers and the load on the machine. A loaded run has ``--load`` busy
processes (a pure-Python spin each) beside it for its whole length.

    python benchmarks/determinism.py --runs 10 --load 2

Prints one line per run (workers, load, nfev, cost, seconds, same as run 1) and a
summary; exits 1 if any run differs.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
STUDY = REPO / "examples" / "lsea_siso" / "study.toml"


def _timeless(obj):
    """``obj`` without its ``digest`` and ``seconds`` entries, at any depth."""
    if isinstance(obj, dict):
        return {k: _timeless(v) for k, v in obj.items() if k not in {"digest", "seconds"}}
    if isinstance(obj, list):
        return [_timeless(v) for v in obj]
    return obj


def _differences(a, b, path: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            out += _differences(a.get(k), b.get(k), f"{path}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [
            d
            for i, (u, v) in enumerate(zip(a, b, strict=True))
            for d in _differences(u, v, f"{path}[{i}]")
        ]
    return [] if a == b else [f"{path}: {a!r:.60} != {b!r:.60}"]


def _run(out: Path, workers: int, load: int) -> tuple[dict, float]:
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(load)]
    t0 = time.perf_counter()
    try:
        subprocess.run(
            [
                sys.executable,
                "-m",
                "tsid_fmu",
                "identify",
                str(STUDY),
                "--out",
                str(out),
                "--workers",
                str(workers),
                "-q",
            ],
            check=False,
            stdout=subprocess.DEVNULL,
        )
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    seconds = time.perf_counter() - t0
    data = json.loads((out / "result.json").read_text(encoding="utf-8"))
    return data, seconds


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--load", type=int, default=2, help="busy processes beside a loaded run")
    args = ap.parse_args()
    plan = [(1 + i % 2, args.load if i % 3 == 2 else 0) for i in range(args.runs)]
    first = None
    same = 0
    with tempfile.TemporaryDirectory() as tmp:
        for i, (workers, load) in enumerate(plan):
            data, seconds = _run(Path(tmp) / f"run{i}", workers, load)
            body = _timeless(data)
            body.pop("study_folder", None)
            diffs = [] if first is None else _differences(first, body)
            first = body if first is None else first
            same += not diffs
            print(
                f"run {i + 1:2d}: workers {workers}, busy {load}, nfev {data['nfev']}, "
                f"cost {data['fun']!r}, {seconds:5.1f} s, "
                + ("same as run 1" if not diffs else f"DIFFERS: {diffs[:3]}"),
                flush=True,
            )
    print(f"{same}/{len(plan)} runs identical to run 1 (digest and timings aside)")
    return 0 if same == len(plan) else 1


if __name__ == "__main__":
    sys.exit(main())
