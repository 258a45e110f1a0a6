"""Time and disk of extracting an FMU that carries a large member it never runs.

Issue 25: an FMU with a 1.9 GiB member of zeros took 80 s and 4.7 GB of temporary disk.
This builds the lag FMU of the tests with such a member under ``documentation/`` (where
vendors put manuals) and extracts it twice in one run: everything (as before) and only
what a simulation reads (:func:`tsid_fmu.fmu.archive.safe_extract` with ``running``, as
sessions now do). Run::

    python benchmarks/extraction.py            # 1.9 GiB member
    python benchmarks/extraction.py --mib 256
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
import zipfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmu_factory import build_c_fmu

from tsid_fmu.fmu.archive import safe_extract


def _ballast(src: Path, dst: Path, mib: int) -> None:
    chunk = bytes(1024**2)
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as b:
        for info in a.infolist():
            b.writestr(info, a.read(info))
        with b.open("documentation/zeros.bin", "w", force_zip64=True) as f:
            for _ in range(mib):
                f.write(chunk)


def _size(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mib", type=int, default=1946, help="size of the member (MiB)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        fmu = work / "ballast.fmu"
        _ballast(build_c_fmu(work / "lag", "Lag", interfaces=("cs",)), fmu, args.mib)
        print(f"FMU {fmu.stat().st_size / 1024:.0f} KiB with a {args.mib} MiB member")
        print(f"{'extraction':<28}{'seconds':>10}{'disk (MiB)':>12}")
        rows = {}
        for label, running in (("everything (before)", False), ("what a simulation reads", True)):
            out = work / f"out-{running}"
            t0 = time.perf_counter()
            safe_extract(fmu, out, running=running)
            rows[label] = (time.perf_counter() - t0, _size(out) / 1024**2)
            print(f"{label:<28}{rows[label][0]:>10.2f}{rows[label][1]:>12.1f}")
            shutil.rmtree(out)
        (a, da), (b, db) = rows.values()
        print(f"ratio (now / before): time {b / a:.4f}, disk {db / max(da, 1e-9):.6f}")


if __name__ == "__main__":
    main()
