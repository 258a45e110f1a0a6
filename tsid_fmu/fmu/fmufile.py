"""Check that a path is an FMU archive tsid can read, saying what it is where not.

``zipfile.is_zipfile`` answers False for a file it cannot open, so that a file without
read permission was reported "not an FMU (an FMU is a ZIP archive)", and
``Path.is_file`` answers False for a folder, so that an unpacked FMU was "FMU file not
found". :func:`check_fmu_file` tells these apart, each in one line naming the path.
"""

from __future__ import annotations

import errno
import os
import stat
import zipfile
from pathlib import Path

from tsid_fmu.errors import FMUError

__all__ = ["check_fmu_file"]


def _reason(exc: OSError) -> str:
    if isinstance(exc, PermissionError) or exc.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    return (exc.strerror or type(exc).__name__).lower()


def check_fmu_file(path: str | os.PathLike[str]) -> Path:
    """Return ``path`` if it is a readable ZIP archive, else raise :class:`FMUError`.

    Raises
    ------
    FMUError
        The path does not exist; is a folder (an unpacked FMU: give the ``.fmu``
        archive); is not a regular file (a FIFO, a device, read without end); cannot be
        read (permission denied); or is not a ZIP archive.
    """
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise FMUError(f"FMU file not found: {path}") from None
    except OSError as exc:
        raise FMUError(f"cannot read FMU file {path}: {_reason(exc)}") from None
    if stat.S_ISDIR(st.st_mode):
        described = (path / "modelDescription.xml").is_file()
        raise FMUError(
            f"{path} is a folder: give the .fmu archive"
            + (
                " (this looks like an unpacked FMU: zip its contents, modelDescription.xml "
                "at the archive's root, into a .fmu file)"
                if described
                else ""
            )
        )
    if not stat.S_ISREG(st.st_mode):
        raise FMUError(f"{path} is not a regular file (a pipe or a device): give the .fmu archive")
    try:
        with open(path, "rb") as fh:
            fh.read(4)
    except OSError as exc:
        raise FMUError(f"cannot read FMU file {path}: {_reason(exc)}") from None
    if not zipfile.is_zipfile(path):
        raise FMUError(f"{path}: not an FMU (an FMU is a ZIP archive)")
    return path
