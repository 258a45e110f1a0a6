"""Extract each FMU once per process and lend the folder to the sessions that open it.

Loading an FMU's shared library from a new folder loads one more copy of it, and some
libraries are never unloaded again: pythonfmu's has ``STB_GNU_UNIQUE`` symbols, so
``dlclose`` leaves it mapped and its destructors wait for ``exit()``, where one of them
frees memory twice (``corrupted double-linked list``, exit status 134).  A study opens
the same FMU several times in its main process (the evaluator, the solver checks), so
this module keeps the extraction folders for the life of the process and lends them:

- :func:`borrow` returns a folder holding the checked extraction
  (:func:`~tsid_fmu.fmu.archive.safe_extract`) of the FMU file; a folder is lent to one
  session at a time, so sessions open at the same time still get a copy each (an FMU
  that supports one instance per library keeps working), and sessions opened one after
  the other get the same folder -- and so the same library handle from ``dlopen``;
- :func:`give_back` returns it; the folder stays, ready for the next session;
- the folders are removed when the process exits (:mod:`atexit`), by the process that
  made them only: a forked child never removes its parent's folders, nor reuses them.

A folder is keyed by the FMU file's resolved path and its ``stat`` identity (device,
inode, size, modification and change times), so an FMU file that changed on disk is
extracted afresh; a folder given as the FMU is used as it is and never comes here.

Examples
--------
>>> folder = borrow(Path("plant.fmu"))                 # doctest: +SKIP
>>> give_back(folder)                                  # doctest: +SKIP
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

from tsid_fmu.errors import FMUError, ResourceError
from tsid_fmu.fmu.archive import safe_extract
from tsid_fmu.fmu.fmufile import check_fmu_file

__all__ = ["PREFIX", "borrow", "folders", "give_back"]

#: name prefix of the extraction folders in the temporary folder
PREFIX = "tsid-fmu-"

#: ``(resolved path, st_dev, st_ino, st_size, st_mtime_ns, st_ctime_ns)``
_Key = tuple[str, int, int, int, int, int]


@dataclass
class _Folder:
    """One extraction of an FMU file, made by process ``pid``."""

    path: Path
    pid: int
    lent: bool


_lock = threading.Lock()
_folders: dict[_Key, list[_Folder]] = {}
_exit_hook_pid: int | None = None


def _new_lock_in_child() -> None:
    """Give a forked child a free lock (another thread may have held the parent's)."""
    global _lock
    _lock = threading.Lock()


os.register_at_fork(after_in_child=_new_lock_in_child)


def _key(fmu: Path) -> _Key:
    """Return the identity of the FMU file; FMUError if it is missing or not an FMU."""
    check_fmu_file(fmu)
    try:
        st = fmu.stat()
        resolved = fmu.resolve()
    except OSError as exc:
        raise FMUError(f"cannot read FMU file {fmu}: {exc.strerror or exc}") from None
    return (str(resolved), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def _extract(fmu: Path) -> Path:
    """Extract ``fmu`` into a new temporary folder (removed again if extraction fails)."""
    try:
        folder = Path(tempfile.mkdtemp(prefix=PREFIX))
    except OSError as exc:  # no usable temporary folder: the machine's, not the FMU's
        raise ResourceError(
            f"cannot create a folder to extract {fmu.name} in the temporary "
            f"folder (TMPDIR={os.environ.get('TMPDIR', 'not set')}): "
            f"{exc.strerror or exc}; point TMPDIR at a writable folder with room"
        ) from None
    try:
        # checks member names, types and sizes; FMUError names the member at fault
        safe_extract(fmu, folder, running=True)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    return folder


def borrow(fmu: Path) -> Path:
    """Return a folder holding the extracted ``fmu``, lent until :func:`give_back`.

    Parameters
    ----------
    fmu : pathlib.Path
        The ``.fmu`` file.

    Returns
    -------
    pathlib.Path
        A folder no other session of this process holds now: one this process
        extracted before from the same, unchanged file, or a new extraction.

    Raises
    ------
    FMUError
        The file is missing, not a ZIP archive, or refused by
        :func:`~tsid_fmu.fmu.archive.safe_extract`.
    ResourceError
        No folder can be created or written in the temporary folder.
    """
    key = _key(fmu)
    pid = os.getpid()
    with _lock:
        for entry in _folders.get(key, ()):
            if entry.pid == pid and not entry.lent and entry.path.is_dir():
                entry.lent = True
                return entry.path
        # extracting under the lock: two sessions opening the same FMU at once must
        # not both extract it, and extraction is done once per file anyway
        folder = _extract(fmu)
        _folders.setdefault(key, []).append(_Folder(folder, pid, lent=True))
        _remove_at_exit(pid)
        return folder


def give_back(folder: Path) -> None:
    """Mark ``folder`` (from :func:`borrow`) free for the next session; it is kept."""
    with _lock:
        for entries in _folders.values():
            for entry in entries:
                if entry.path == folder:
                    entry.lent = False
                    return


def folders() -> list[Path]:
    """Return the extraction folders this process made and still keeps (for tests)."""
    pid = os.getpid()
    with _lock:
        return [e.path for entries in _folders.values() for e in entries if e.pid == pid]


def _remove_at_exit(pid: int) -> None:
    """Register :func:`_remove_all` once per process (a forked child registers again)."""
    global _exit_hook_pid
    if _exit_hook_pid != pid:
        _exit_hook_pid = pid
        atexit.register(_remove_all, pid)


def _remove_all(pid: int) -> None:
    """Remove the folders process ``pid`` made (at its exit; nothing in another process)."""
    if os.getpid() != pid:
        return
    with _lock:
        mine = [e for entries in _folders.values() for e in entries if e.pid == pid]
        for entry in mine:
            shutil.rmtree(entry.path, ignore_errors=True)
        for key in list(_folders):
            _folders[key] = [e for e in _folders[key] if e.pid != pid]
