"""Writing files so that an interruption leaves the old file or the new one, never half."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tsid_fmu.errors import StudyError

__all__ = ["atomic_write", "read_json", "strict", "write_json"]


def atomic_write(path: Path, write: Callable[[Path], None] | str | bytes) -> None:
    """Write a file atomically: to a temporary file in the same folder, then rename.

    The file gets the default permissions of a new file (the umask applies).

    Parameters
    ----------
    path : Path
        Destination.
    write : str, bytes or callable
        Content, or a function that writes the file at the path it is given.

    Raises
    ------
    OSError
        The folder cannot be written (full disk, read-only, no permission); its
        ``filename`` is ``path``, whatever step failed.
    """
    try:
        _write_replace(path, write)
    except OSError as exc:
        if exc.filename == str(path) or exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror, str(path)) from None


def _write_replace(path: Path, write: Callable[[Path], None] | str | bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        if isinstance(write, str):
            tmp_path.write_text(write, encoding="utf-8")
        elif isinstance(write, bytes):
            tmp_path.write_bytes(write)
        else:
            write(tmp_path)
        with open(tmp_path, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def strict(data: Any, nonfinite: Callable[[float], Any] = lambda x: None) -> Any:
    """Return ``data`` for strict JSON.

    Non-finite floats become ``nonfinite(x)`` (default ``None``), numpy scalars and
    arrays plain numbers and lists, tuples lists, dataclass instances dicts of their
    fields, other objects their ``str``.
    """
    if isinstance(data, dict):
        return {str(k): strict(v, nonfinite) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [strict(v, nonfinite) for v in data]
    if hasattr(data, "tolist"):
        return strict(data.tolist(), nonfinite)
    if dataclasses.is_dataclass(data) and not isinstance(data, type):
        fields = dataclasses.fields(data)
        return {f.name: strict(getattr(data, f.name), nonfinite) for f in fields}
    if isinstance(data, bool) or data is None or isinstance(data, int | str):
        return data
    if isinstance(data, float):
        return data if math.isfinite(data) else nonfinite(data)
    return str(data)


def write_json(path: Path, data: Any) -> None:
    """Write strict JSON (no NaN or infinity) atomically."""
    atomic_write(path, json.dumps(strict(data), indent=1, allow_nan=False) + "\n")


def read_json(path: Path, what: str) -> Any:
    """Read a JSON file of the trail; a damaged one is a StudyError naming it."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise StudyError(f"{path}: damaged {what} ({type(exc).__name__})") from None
