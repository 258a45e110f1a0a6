"""Measured data: load a file (or take a DataFrame), derive channels, check it.

Every problem is a :class:`~tsid_fmu.errors.DataError` whose message names the file
and the column and row at fault, e.g.::

    data.csv: column 'F_of' has a non-numeric value in row 17

Rows are counted like a spreadsheet user reads them: row 1 is the first data row.
Messages never quote the file's contents: not a cell, and column names only when the
first line looks like a header (:mod:`tsid_fmu.data.names`).
"""

from __future__ import annotations

import csv
import difflib
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tsid_fmu.data.expressions import evaluate
from tsid_fmu.data.names import column_label, describe_columns, safe_names
from tsid_fmu.data.textfile import (
    check_duplicates,
    check_regular,
    header_fields,
    hide_names_unless_table,
    read_head,
    sniff_decimal,
    sniff_delimiter,
)
from tsid_fmu.errors import DataError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["MeasuredData", "load_data"]

#: allowed relative deviation of a sampling interval from the median interval
JITTER_TOLERANCE = 0.01


@dataclass
class MeasuredData:
    """Measured time series on a uniform time grid.

    Attributes
    ----------
    path : str
        The source file (or ``"<frame>"`` for data given as a DataFrame).
    time : numpy.ndarray
        Sample times, ``float64``, strictly increasing and uniformly spaced.
    frame : pandas.DataFrame
        Every numeric column, including derived ones (the time column too).
    sample_time : float
        The sampling interval (mean of the intervals).
    time_column : str
        Name of the time column in ``frame``.
    """

    path: str
    time: np.ndarray
    frame: pd.DataFrame
    sample_time: float
    time_column: str = field(default="time")

    @property
    def names(self) -> list[str]:
        """Names of all columns, including derived ones."""
        return [str(c) for c in self.frame.columns]

    def column(self, name: str) -> np.ndarray:
        """Return one column as a ``float64`` array.

        Raises
        ------
        DataError
            No such column (the message lists the columns and close matches).
        """
        if name not in self.frame.columns:
            raise DataError(f"{self.path}: no column {name!r}; {_listing(name, self.names)}")
        return self.frame[name].to_numpy(dtype=np.float64)

    def columns(self, names: Sequence[str]) -> np.ndarray:
        """Return the named columns as an ``(n, k)`` ``float64`` array."""
        if not names:
            return np.zeros((len(self.time), 0))
        return np.column_stack([self.column(n) for n in names])

    def to_pandas(self) -> pd.DataFrame:
        """Return a copy of the data as a DataFrame indexed by time."""
        return self.frame.set_index(self.time_column, drop=True).copy()

    def __len__(self) -> int:
        return len(self.time)

    @classmethod
    def from_frame(
        cls,
        df: pd.DataFrame,
        time_column: str = "time",
        *,
        source: str = "<frame>",
        derived: Mapping[str, str] | None = None,
        sample_time: float | None = None,
    ) -> MeasuredData:
        """Check a DataFrame and wrap it (for scripts and notebooks).

        Parameters
        ----------
        df : pandas.DataFrame
            One column per channel, one of them the time.
        time_column : str, optional
            Name of the time column.
        source : str, optional
            Name used in error messages.
        derived : mapping of str to str, optional
            New channels as expressions over the columns, e.g. ``{"F": "F_of - F_or"}``.
        sample_time : float, optional
            The sampling interval the study expects; a different one is an error.

        Returns
        -------
        MeasuredData
            A checked copy of ``df`` with the derived channels added.

        Raises
        ------
        DataError
            As :func:`load_data` for the frame's content; the message names ``source``.
        """
        import pandas as pd

        if not isinstance(df, pd.DataFrame):
            raise DataError(f"{source}: expected a pandas DataFrame, got {type(df).__name__}")
        frame = df.copy()
        # spaces only: a tab or control character keeps the name from looking like a
        # header, so that a file that is not a data file is never quoted (data.names)
        frame.columns = [str(c).strip(" ") for c in frame.columns]
        check_duplicates(list(frame.columns), source)
        if frame.shape[0] == 0 or frame.shape[1] == 0:
            raise DataError(f"{source}: no data (the table is empty)")
        if time_column not in frame.columns:
            raise DataError(
                f"{source}: time column {time_column!r} not found; "
                + _listing(time_column, list(frame.columns), cutoff=0.5)
            )
        frame = _to_numeric(frame, source)
        _check_finite(frame, source)
        time = frame[time_column].to_numpy(dtype=np.float64)
        dt = _check_time(time, time_column, source)
        if derived:
            frame = _derive(frame, derived, source, dt)
            _check_finite(frame[list(derived)], source)
        if sample_time is not None and not np.isclose(
            dt, sample_time, rtol=JITTER_TOLERANCE, atol=0.0
        ):
            raise DataError(
                f"{source}: sample time is {dt:g} s but the study expects {sample_time:g} s"
            )
        return cls(
            path=source,
            time=time,
            frame=frame.reset_index(drop=True),
            sample_time=dt,
            time_column=time_column,
        )


def _to_numeric(frame: pd.DataFrame, source: str) -> pd.DataFrame:
    import pandas as pd

    out = {}
    for name in frame.columns:
        col = frame[name]
        if pd.api.types.is_bool_dtype(col) or pd.api.types.is_numeric_dtype(col):
            out[name] = col.astype(np.float64)
            continue
        try:
            converted = pd.to_numeric(col, errors="coerce")
        except (OverflowError, ValueError):  # an integer cell of hundreds of digits
            converted = pd.to_numeric(col.map(_cell_number), errors="coerce")
        bad = converted.isna() & col.notna() & (col.astype(str).str.strip() != "")
        if bad.any():
            pos = int(np.flatnonzero(bad.to_numpy())[0])
            raise DataError(
                f"{source}: {column_label(name, list(frame.columns))} has a non-numeric "
                f"value in row {pos + 1}"
            )
        out[name] = converted.astype(np.float64)
    return pd.DataFrame(out, index=frame.index)


def _cell_number(value: Any) -> float:
    """Return a cell as a float (an integer beyond the float range is +-inf), NaN if text."""
    text = str(value).strip()
    try:
        return float("nan") if "_" in text else float(text)  # "1_000": text to pandas too
    except ValueError:
        return float("nan")


def _listing(name: str, names: list[str], cutoff: float = 0.6) -> str:
    """``columns are ...`` and the close matches, when the names may be shown."""
    if not safe_names(names):
        return describe_columns(names)
    close = difflib.get_close_matches(name, names, n=3, cutoff=cutoff)
    hint = f" Did you mean {', '.join(map(repr, close))}?" if close else ""
    return f"{describe_columns(names)}.{hint}"


def _reason(exc: BaseException) -> str:
    """Why a reader failed, in words that never quote the file."""
    import pandas as pd

    if isinstance(exc, UnicodeDecodeError):
        return f"not {exc.encoding} text (byte {exc.start + 1})"
    if isinstance(exc, pd.errors.ParserError | csv.Error | FileNotFoundError | PermissionError):
        text = str(exc) if not isinstance(exc, OSError) else (exc.strerror or "")
        # pandas' C parser says "Error tokenizing data. C error: ..." before the reason
        text = text.removeprefix("Error tokenizing data. C error: ")
        return text.splitlines()[0][:200] if text else type(exc).__name__
    return type(exc).__name__


def _check_finite(frame: pd.DataFrame, source: str) -> None:
    values = frame.to_numpy(dtype=np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        # first offending row, then its first offending column
        row = int(np.flatnonzero(bad.any(axis=1))[0])
        col = int(np.flatnonzero(bad[row])[0])
        what = "missing (NaN)" if np.isnan(values[row, col]) else f"{values[row, col]}"
        label = column_label(frame.columns[col], list(frame.columns))
        raise DataError(f"{source}: {label} is {what} in row {row + 1}")


def _derive(
    frame: pd.DataFrame, derived: Mapping[str, str], source: str, sample_time: float
) -> pd.DataFrame:
    frame = frame.copy()
    for name, expression in derived.items():
        columns = {str(c): frame[c].to_numpy(dtype=np.float64) for c in frame.columns}
        frame[name] = evaluate(
            expression, columns, sample_time=sample_time, channel=name, source=source
        )
    return frame


def _check_time(time: np.ndarray, time_column: str, source: str) -> float:
    if time.size < 2:
        raise DataError(f"{source}: at least 2 samples are needed, got {time.size}")
    dt = np.diff(time)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = int(bad[0]) + 1  # 0-based index of the offending sample
        kind = "repeats" if dt[i - 1] == 0 else "goes back from"
        raise DataError(
            f"{source}: column {time_column!r} is not strictly increasing: row "
            f"{i + 1} {kind} the previous time ({time[i - 1]:g} -> {time[i]:g})"
        )
    median = float(np.median(dt))
    jitter = np.abs(dt - median) / median
    bad = np.flatnonzero(jitter > JITTER_TOLERANCE)
    if bad.size:
        i = int(bad[0]) + 1
        raise DataError(
            f"{source}: non-uniform sampling in column {time_column!r} at row {i + 1}: "
            f"interval {dt[i - 1]:g} s differs from the sample time {median:g} s by "
            f"{100 * jitter[i - 1]:.1f} % (tolerance {100 * JITTER_TOLERANCE:g} %)"
        )
    return float((time[-1] - time[0]) / (time.size - 1))


_BINARY = (".parquet", ".feather", ".xlsx", ".xls", ".mat")
_TSV_SEP = r"\s+|\t|,|;"


def _text_options(path: Path, suffix: str, options: dict[str, Any]) -> dict[str, Any]:
    """Return the reader's options for a text file, reading and checking its header.

    The delimiter is sniffed among the usual ones only (never ``=`` or ``:``), a UTF-8
    byte order mark is dropped, and a header naming a column twice is refused
    (:mod:`tsid_fmu.data.textfile`).
    """
    encoding = options.get("encoding", "utf-8-sig")
    line = read_head(path, encoding)
    defaults: dict[str, Any] = {"engine": "python", "encoding": encoding}
    if suffix in (".tsv", ".txt"):
        defaults["sep"] = _TSV_SEP
    elif "sep" not in options and "delimiter" not in options:
        defaults["sep"] = sniff_delimiter(line)
        if "decimal" not in options and sniff_decimal(path, defaults["sep"], encoding) == ",":
            defaults["decimal"] = ","  # a European CSV, 0,25;1,5 (read by the C parser)
    merged = {**defaults, **options}
    sep = merged.get("sep") or merged.get("delimiter")
    python_only = "skipfooter" in options or callable(options.get("on_bad_lines"))
    if "engine" not in options and isinstance(sep, str) and len(sep) == 1 and not python_only:
        # pandas' C parser reads numbers straight into float64, in chunks; the python
        # engine holds a Python object a cell first (1.27 GiB peak for a 2-million-row,
        # 5-column file of 155 MiB, 0.34 GiB with the C parser)
        merged["engine"] = "c"
    if isinstance(sep, str) and sep and not {"header", "names", "skiprows"} & set(options):
        check_duplicates(header_fields(line, sep), str(path))
    return merged


def _read_excel(path: Path, options: dict[str, Any]) -> pd.DataFrame:
    """Read a spreadsheet, refusing a header row that names a column twice.

    pandas renames a repeated name (``F_m.1``), so the header row is read as it is
    written first (:func:`check_duplicates` names both positions).
    """
    import pandas as pd

    if options.get("header", 0) == 0:
        sheet = {k: v for k, v in options.items() if k == "sheet_name"}
        head = pd.read_excel(path, header=None, nrows=1, **sheet)
        if head.shape[0]:
            check_duplicates([v for v in head.iloc[0].tolist() if v == v], str(path))
    return pd.read_excel(path, **options)


def _read(path: Path, columns: Sequence[str] | None, options: dict[str, Any]) -> pd.DataFrame:
    import pandas as pd

    suffix = path.suffix.lower()
    if suffix not in _BINARY:
        options = _text_options(path, suffix, options)
    try:
        if suffix not in _BINARY:
            with warnings.catch_warnings():  # a chunk's text cell: _to_numeric names it
                warnings.simplefilter("ignore", pd.errors.DtypeWarning)
                frame = pd.read_csv(path, **options)
        elif suffix == ".parquet":
            frame = pd.read_parquet(path, **options)
        elif suffix == ".feather":
            frame = pd.read_feather(path, **options)
        elif suffix in (".xlsx", ".xls"):
            frame = _read_excel(path, options)
        else:
            frame = _read_mat(path, options)
    except ImportError as exc:
        raise DataError(f"{path}: reading {suffix} files needs an optional package: {exc}") from exc
    except pd.errors.EmptyDataError as exc:
        raise DataError(f"{path}: the file is empty") from exc
    except DataError:
        raise
    except (OSError, ValueError, pd.errors.ParserError, UnicodeDecodeError, csv.Error) as exc:
        raise DataError(f"{path}: cannot read the file: {_reason(exc)}") from None
    frame = hide_names_unless_table(frame)
    if columns is not None:
        missing = [c for c in columns if c not in frame.columns]
        if missing:
            raise DataError(
                f"{path}: column(s) {', '.join(map(repr, missing))} not found; "
                + describe_columns(list(frame.columns))
            )
        frame = frame[list(columns)]
    return frame


def _read_mat(path: Path, options: Mapping[str, Any]) -> pd.DataFrame:
    import pandas as pd
    from scipy.io import loadmat

    content = loadmat(path, squeeze_me=True, **options)
    arrays = {k: np.asarray(v) for k, v in content.items() if not k.startswith("__")}
    vectors = {
        k: v.astype(np.float64)
        for k, v in arrays.items()
        if v.ndim == 1 and np.issubdtype(v.dtype, np.number)
    }
    if not vectors:
        raise DataError(f"{path}: no 1-D numeric variables in the .mat file")
    lengths = {len(v) for v in vectors.values()}
    if len(lengths) > 1:
        shown = (
            vectors
            if safe_names(vectors)
            else {f"#{i + 1}": v for i, v in enumerate(vectors.values())}
        )
        raise DataError(
            f"{path}: the .mat variables have different lengths: "
            + ", ".join(f"{k}={len(v)}" for k, v in shown.items())
        )
    return pd.DataFrame(vectors)


def load_data(
    path: str | os.PathLike[str],
    *,
    time_column: str = "time",
    columns: Sequence[str] | None = None,
    derived: Mapping[str, str] | None = None,
    sample_time: float | None = None,
    read_options: Mapping[str, Any] | None = None,
) -> MeasuredData:
    """Load measured data and check it.

    Parameters
    ----------
    path : str or pathlib.Path
        The data file; the reader follows the extension: ``.csv`` (default, separator
        sniffed; ``;`` with decimal commas, ``0,25;1,5``, read as such),
        ``.tsv``/``.txt`` (whitespace, tab, comma or semicolon), ``.parquet``,
        ``.feather`` (need ``pyarrow``), ``.xlsx`` (needs ``openpyxl``), ``.mat``
        (1-D variables of equal length).
    time_column : str, optional
        Name of the time column (seconds).
    columns : sequence of str, optional
        Keep only these columns (the time column must be among them).
    derived : mapping of str to str, optional
        Extra channels computed from columns, e.g. ``{"F_o": "F_of - F_or"}`` for
        compression-only load cells.  Expressions may use column names, numbers,
        arithmetic and the numpy functions ``abs, sqrt, exp, log, sin, cos, ...``;
        nothing else is evaluated.
    sample_time : float, optional
        Expected sampling interval; a file with another one is rejected.
    read_options : mapping, optional
        Passed to the pandas reader (e.g. ``{"sep": ";", "decimal": ","}``).

    Returns
    -------
    MeasuredData
        The checked channels of the file, with the derived ones.

    Raises
    ------
    DataError
        The file is missing, unreadable or empty; the time column is missing; a value is
        not numeric, NaN or infinite; time is not strictly increasing or not uniformly
        sampled (more than 1 % jitter); the sample time differs from ``sample_time``; an
        expression in ``derived`` uses an unknown name.  The message names the file,
        column and row.
    """
    path = Path(path)
    check_regular(path)  # never a device or pipe: reading those does not end
    if path.stat().st_size == 0:
        raise DataError(f"{path}: the file is empty")
    if columns is not None and time_column not in columns:
        columns = [time_column, *columns]
    frame = _read(path, columns, dict(read_options or {}))
    return MeasuredData.from_frame(
        frame, time_column, source=str(path), derived=derived, sample_time=sample_time
    )
