"""Plumbing shared by the examples' independent data generators (``*/make_data.py``).

Each generator solves its own plant's equations; what they share is the rig around the
plant: the 1 kHz sample instants, the exact response of a linear system to a command
held over each sample, the sensors (compression-only load cells with white noise, a
quantising encoder), the CSV format of the committed data and the command line.  Like
the generators, this module uses NumPy, pandas and SciPy only, never ``tsid_fmu``.

A generator run as a script (``python examples/lsea_siso/make_data.py``) or loaded from
its path puts this folder on ``sys.path`` and imports ``_datagen``.
"""

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.linalg import expm


def sample_times(duration: float = 10.0, rate: float = 1000.0) -> np.ndarray:
    """Sample instants ``t_k = k / rate`` from 0 to ``duration`` (s)."""
    return np.round(np.arange(round(duration * rate) + 1) / rate, 9)


def zoh_response(a: np.ndarray, t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Exact response from rest of a linear system to ``u[k]`` held over ``[t[k], t[k+1])``.

    Parameters
    ----------
    a : numpy.ndarray
        Augmented system matrix, shape ``(n + 1, n + 1)``: the state's ``n`` rows, then
        the input's row of zeros (the input is constant over a hold interval).
    t : numpy.ndarray
        Sample instants (s), strictly increasing, starting at the initial time.
    u : numpy.ndarray
        The input, one value per sample.

    Returns
    -------
    numpy.ndarray
        Shape ``(len(t), n)``: the states at ``t`` (``expm(a h)`` once per step ``h``).
    """
    cache: dict[float, np.ndarray] = {}
    z = np.zeros(a.shape[0])
    out = np.zeros((len(t), a.shape[0] - 1))
    for k in range(len(t) - 1):
        h = round(float(t[k + 1] - t[k]), 15)
        if h not in cache:
            cache[h] = expm(a * h)
        z[-1] = u[k]
        z = cache[h] @ z
        out[k + 1] = z[:-1]
    return out


def load_cells(
    f_o: np.ndarray, sigma_front: float, sigma_rear: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Readings of two compression-only load cells on the force ``f_o`` (front, rear).

    Front ``max(f_o, 0)`` and rear ``max(-f_o, 0)``, each with its own white Gaussian
    noise, drawn from ``rng`` in that order.
    """
    front = np.maximum(f_o, 0.0) + rng.normal(0.0, sigma_front, f_o.size)
    rear = np.maximum(-f_o, 0.0) + rng.normal(0.0, sigma_rear, f_o.size)
    return front, rear


def quantise(x: np.ndarray, step: float) -> np.ndarray:
    """An encoder's reading of ``x``: rounded to whole multiples of ``step``."""
    return np.round(x / step) * step


def write_csv(frame: pd.DataFrame, path: Path) -> None:
    """Write ``frame`` as the committed data files are: no index, 9 significant digits."""
    frame.to_csv(path, index=False, float_format="%.9g")


def command_line(
    doc: str,
    *,
    seed: int,
    make: Callable[[int], dict[str, pd.DataFrame]],
    folder: Path,
    truth: dict[str, float],
    noise: dict[str, float],
    check: Callable[[], None],
) -> None:
    """Run a generator's command line: write its CSV files, or ``check()`` with ``--check``.

    Parameters
    ----------
    doc : str
        The generator's docstring (its first line describes the command).
    seed : int
        Default seed of the sensor noise (``--seed``).
    make : callable
        ``make(seed)`` returns the data, one frame per file name (``<name>.csv``); each
        frame logs the load cells ``F_of`` and ``F_or``.
    folder : pathlib.Path
        Where the CSV files go.
    truth, noise : dict
        The parameters and the sensor sigmas the data were made with (printed).
    check : callable
        The tolerance study (``--check``), which writes no file.
    """
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="tolerance study; writes no file")
    parser.add_argument("--seed", type=int, default=seed)
    args = parser.parse_args()
    if args.check:
        check()
        return
    t0 = time.perf_counter()
    for name, frame in make(args.seed).items():
        path = folder / f"{name}.csv"
        write_csv(frame, path)
        f_o = frame["F_of"] - frame["F_or"]
        print(f"wrote {path} ({len(frame)} rows): F_o from {f_o.min():.1f} to {f_o.max():.1f} N")
    print(f"{time.perf_counter() - t0:.1f} s; truth {truth}; noise {noise}")
