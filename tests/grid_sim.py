"""Drive an FMU with FMPy on a fixed 1 ms grid, as the plant-FMU tests do.

``grid(stop_time)``
    The sample times ``0, DT, ..., stop_time``.
``input_signal(t, **columns)``
    FMPy's structured input array: ``time`` then one column a name.
``simulate_grid(fmu, stop_time, **kw)``
    ``fmpy.simulate_fmu`` from 0 to ``stop_time`` with step size and output interval
    ``DT``; ``kw`` goes to ``simulate_fmu`` as it is.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fmpy import simulate_fmu

DT = 1e-3


def grid(stop_time: float) -> np.ndarray:
    return np.arange(0, stop_time + DT / 2, DT)


def input_signal(t: np.ndarray, **columns: np.ndarray) -> np.ndarray:
    sig = np.zeros(len(t), dtype=[("time", float)] + [(n, float) for n in columns])
    sig["time"] = t
    for n, v in columns.items():
        sig[n] = v
    return sig


def simulate_grid(fmu: Path | str, stop_time: float, **kw):
    return simulate_fmu(str(fmu), stop_time=stop_time, step_size=DT, output_interval=DT, **kw)
