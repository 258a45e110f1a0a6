"""Split the Cascaded Tanks benchmark record into the example's two experiments.

The shared file ``/work/shared/data/cascaded_tanks/dataBenchmark.csv`` (or the path
given as the first argument) holds the benchmark's estimation and validation records
side by side (columns ``uEst``, ``yEst``, ``uVal``, ``yVal``; ``Ts`` = 4 s in the first
row). This script writes each record as its own experiment file with a time column:

- ``est.csv``: ``time``, ``u``, ``y`` of the estimation record (fitted);
- ``val.csv``: the same of the validation record (``role = "validate"``: never fitted).

Run ``python make_data.py [dataBenchmark.csv]`` from this folder; the CSVs are
committed, so the example runs without the shared file.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
SOURCE = Path("/work/shared/data/cascaded_tanks/dataBenchmark.csv")


def split(source: Path, out: Path = HERE) -> tuple[Path, Path]:
    """Write ``est.csv`` and ``val.csv`` from the benchmark's file.

    Parameters
    ----------
    source : Path
        The benchmark's ``dataBenchmark.csv``.
    out : Path, optional
        Folder the two files are written to (default this script's folder).

    Returns
    -------
    tuple of Path
        The estimation and the validation file.
    """
    data = pd.read_csv(source)
    ts = float(data["Ts"].iloc[0])
    time = np.arange(len(data)) * ts
    paths = []
    for record, name in (("Est", "est"), ("Val", "val")):
        frame = pd.DataFrame({"time": time, "u": data[f"u{record}"], "y": data[f"y{record}"]})
        path = out / f"{name}.csv"
        frame.to_csv(path, index=False, float_format="%.6g")
        paths.append(path)
    return paths[0], paths[1]


if __name__ == "__main__":
    print(*split(Path(sys.argv[1]) if len(sys.argv) > 1 else SOURCE), sep="\n")
