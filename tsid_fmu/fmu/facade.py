"""``tsid_fmu.simulate``: run an FMU on a table of measured inputs, in one call.

The flat facade over :class:`~tsid_fmu.fmu.FMUSession`, in the spirit of FMPy's
``simulate_fmu``, but repeated calls are cheap: the sessions (extracted folder, loaded
library, instance) are kept in a small least-recently-used cache keyed by the FMU
file (resolved path, size, modification time) and the variable lists, and closed at
interpreter exit.  A call on an FMU already open costs one simulation.

Examples
--------
>>> import pandas as pd, tsid_fmu                                  # doctest: +SKIP
>>> data = pd.read_csv("examples/lsea_siso/measured.csv")          # doctest: +SKIP
>>> y = tsid_fmu.simulate("fmus/LSEA_SISO.fmu", data, outputs=["F_o", "x_m"],
...                       parameters={"K_s": 8600.0})              # doctest: +SKIP
"""

from __future__ import annotations

import atexit
import functools
import os
import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tsid_fmu.errors import DataError, FMUError
from tsid_fmu.fmu.delay import check_delays, delayed_inputs, split_delays
from tsid_fmu.fmu.fmufile import check_fmu_file
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.session import FMUSession
from tsid_fmu.fmu.variables import REAL_TYPES, read_description, suggest

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["MAX_OPEN", "clear_cache", "simulate"]

MAX_OPEN = 4
"""Sessions kept open by :func:`simulate` (least recently used ones are closed)."""

_lock = threading.Lock()
_open: OrderedDict[tuple[Any, ...], tuple[FMUSession, threading.Lock]] = OrderedDict()


def clear_cache() -> None:
    """Close every session :func:`simulate` keeps open (also run at interpreter exit)."""
    with _lock:
        entries = list(_open.values())
        _open.clear()
    for session, lock in entries:
        with lock:
            session.close()


atexit.register(clear_cache)


def _fmu_path(fmu: str | os.PathLike[str]) -> tuple[Path, tuple[Any, ...]]:
    """Return the resolved FMU path and its identity (path, size, modification time)."""
    path = check_fmu_file(Path(fmu).expanduser())
    try:
        stat = path.stat()
        path = path.resolve()
    except OSError:
        raise FMUError(f"FMU file not found: {path}") from None
    return path, (str(path), stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=32)
def _defaults(path: Path, identity: tuple[Any, ...]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Return the FMU's Real inputs and outputs in model-description order (read once)."""
    md = (
        read_description(path / "modelDescription.xml", path)
        if path.is_dir()
        else read_fmu_description(path)
    )
    reals = [v for v in md.modelVariables if v.type in REAL_TYPES]
    return (
        tuple(v.name for v in reals if v.causality == "input"),
        tuple(v.name for v in reals if v.causality == "output"),
    )


def _session(
    path: Path,
    identity: tuple[Any, ...],
    inputs: tuple[str, ...],
    outputs: tuple[str, ...],
    hold: Mapping[str, str],
) -> tuple[FMUSession, threading.Lock]:
    """Return an open session for these variables (from the cache, or a new one)."""
    key = (identity, inputs, outputs, tuple(sorted(hold.items())))
    with _lock:
        entry = _open.get(key)
        if entry is not None and not entry[0].closed:
            _open.move_to_end(key)
            return entry
        session = FMUSession(path, inputs, outputs, hold=hold)
        entry = (session, threading.Lock())
        # the FMU file changed (or too many are open): close what is no longer wanted
        stale = [k for k in _open if k[0][0] == identity[0] and k[0] != identity]
        evicted = [_open.pop(k) for k in stale]
        _open[key] = entry
        while len(_open) > MAX_OPEN:
            evicted.append(_open.popitem(last=False)[1])
    for old, lock in evicted:
        with lock:
            old.close()
    return entry


def _frame(data: Any) -> pd.DataFrame:
    import pandas as pd

    if not isinstance(data, pd.DataFrame):
        raise DataError(
            f"data must be a pandas DataFrame with a 'time' column, not {type(data).__name__}"
        )
    if "time" not in data.columns:
        columns = [str(c) for c in data.columns]
        raise DataError(
            f"data: no 'time' column (columns: {', '.join(columns)}).{suggest('time', columns)}"
        )
    return data


def _column(data: pd.DataFrame, column: str, what: str) -> np.ndarray:
    """Return ``data[column]`` as finite float64 values; DataError naming it otherwise.

    Rows are counted as in :mod:`tsid_fmu.data`: row 1 is the first data row.
    """
    columns = [str(c) for c in data.columns]
    if column not in data.columns:
        raise DataError(
            f"data: no column {column!r} for {what} (columns: {', '.join(columns)})."
            f"{suggest(column, columns)}"
        )
    series = data[column]
    if series.ndim != 1:
        raise DataError(f"data: more than one column is named {column!r}")
    try:
        values = np.asarray(series, dtype=np.float64)
    except (TypeError, ValueError):
        pos = next(i for i, v in enumerate(series) if not _is_number(v))
        raise DataError(
            f"data: column {column!r} has non-numeric value {series.iloc[pos]!r} in row {pos + 1}"
        ) from None
    finite = np.isfinite(values)
    if not finite.all():
        pos = int(np.argmin(finite))
        what = "missing (NaN)" if np.isnan(values[pos]) else f"{values[pos]}"
        raise DataError(f"data: column {column!r} is {what} in row {pos + 1}")
    return values


def _is_number(value: Any) -> bool:
    try:
        float(value)
    except (TypeError, ValueError):
        return False
    return True


def _time(data: pd.DataFrame) -> np.ndarray:
    t = _column(data, "time", "the sample times")
    if t.size < 2:
        raise DataError(f"data: {t.size} rows; at least 2 samples are needed")
    steps = np.diff(t)
    if not (steps > 0).all():
        pos = int(np.argmin(steps > 0)) + 1
        raise DataError(
            f"data: column 'time' is not strictly increasing: row {pos + 1} "
            f"({t[pos]:g}) after {t[pos - 1]:g}"
        )
    return t


def simulate(
    fmu: str | os.PathLike[str],
    data: pd.DataFrame,
    *,
    inputs: Mapping[str, str] | None = None,
    outputs: Sequence[str] | None = None,
    parameters: Mapping[str, float] | None = None,
    start_values: Mapping[str, float] | None = None,
    hold: Mapping[str, str] | None = None,
) -> pd.DataFrame:
    """Simulate an FMU driven by measured inputs; return its outputs at the data's times.

    Parameters
    ----------
    fmu : str or pathlib.Path
        The ``.fmu`` file (FMI 2.0 or 3.0, Co-Simulation preferred), or a folder it was
        extracted to.
    data : pandas.DataFrame
        A ``time`` column (strictly increasing) and the input signals.
    inputs : mapping of str to str, optional
        ``{fmu_input: column}``.  Default: every Real input of the FMU, each from the
        column of the same name.
    outputs : sequence of str, optional
        Variables to return.  Default: every Real output of the FMU.
    parameters : mapping of str to float, optional
        Parameter values for this run; ``delay(<input>)`` delays that input by so many
        seconds (:mod:`tsid_fmu.fmu.delay`).
    start_values : mapping of str to float, optional
        Other values to set before initialization (e.g. initial states).
    hold : mapping of str to {"previous", "linear"}, optional
        Per FMU input: zero-order hold (default) or linear interpolation between
        samples (see :class:`~tsid_fmu.fmu.FMUSession`).

    Returns
    -------
    pandas.DataFrame
        ``time`` and one column per output, with the index of ``data``; row ``k`` is
        the outputs at ``time[k]`` after the inputs of ``time[k]`` are set.

    Raises
    ------
    DataError
        ``data`` is not a DataFrame, lacks ``time`` or an input column, or has a value
        that is not a finite number (the message names the column and row).
    FMUError
        The FMU cannot be opened or lacks a named variable (with suggestions).
    SimulationError
        An FMI call failed or an output is not finite (naming the call and the time).
    StudyError
        A ``delay(<input>)`` of an input that is not simulated.
    """
    import pandas as pd

    frame = _frame(data)
    path, identity = _fmu_path(fmu)
    if inputs is None or outputs is None:
        default_in, default_out = _defaults(path, identity)
    mapping = {name: name for name in default_in} if inputs is None else dict(inputs)
    names_out = default_out if outputs is None else tuple(outputs)
    if "time" in names_out:
        raise FMUError(f"{path.name}: an output named 'time' would clash with the time column")
    t = _time(frame)
    u = np.column_stack(
        [_column(frame, col, f"the FMU input {name!r}") for name, col in mapping.items()]
        or [np.zeros((t.size, 0))]
    )
    values, delays = split_delays(dict(parameters or {}))
    check_delays(list(parameters or {}), tuple(mapping), "this simulation")
    u = delayed_inputs(t, u, tuple(mapping), delays) if mapping else u
    session, lock = _session(path, identity, tuple(mapping), names_out, dict(hold or {}))
    with lock:
        session.set_start_values(dict(start_values or {}))
        y = session.simulate(t, u if mapping else None, values)
    result = pd.DataFrame(y, columns=list(names_out), index=frame.index)
    result.insert(0, "time", t)
    return result
