r"""Extract FMU archives without trusting them.

An FMU is a ZIP archive that a study downloads from a colleague, a vendor or a model
exchange.  :func:`zipfile.ZipFile.extractall` would write whatever the archive says:
members named ``../../.bashrc`` or ``/etc/...``, Windows paths such as
``C:\evil.dll`` or ``..\..\x``, symbolic links pointing anywhere, and "zip bombs"
whose few kilobytes expand to gigabytes.  :func:`safe_extract` checks every member
first and refuses the archive with an :class:`~tsid_fmu.errors.FMUError` naming the
FMU file and the member at fault, then extracts while counting the bytes actually
written, so a header that lies about a member's size cannot fill the disk either.

Examples
--------
>>> safe_extract("plant.fmu", "/tmp/plant")            # doctest: +SKIP
PosixPath('/tmp/plant')
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import stat
import zipfile
import zlib
from pathlib import Path, PurePosixPath

from tsid_fmu.errors import FMUError, ResourceError
from tsid_fmu.fmu.fmufile import check_fmu_file

__all__ = ["MAX_BYTES", "MAX_MEMBERS", "NOT_RUN", "safe_extract"]

#: default limit on the total uncompressed size of an FMU (bytes)
MAX_BYTES = 2 * 1024**3
#: default limit on the number of members of an FMU
MAX_MEMBERS = 100_000

_CHUNK = 1 << 20
#: errors of writing that are the machine's (full disk, file-size limit, read-only
#: or forbidden folder), not the FMU's
_ENVIRONMENT = {
    errno.ENOSPC,
    errno.EDQUOT,
    errno.EFBIG,
    errno.EROFS,
    errno.EACCES,
    errno.EPERM,
    errno.EMFILE,
    errno.ENFILE,
}
_DRIVE_RE = re.compile(r"^[A-Za-z]:")
#: ``create_system`` values whose ``external_attr`` high word is a Unix mode
_UNIX_SYSTEMS = {3, 19}  # Unix, OS X


def _member_path(fmu: Path, info: zipfile.ZipInfo) -> PurePosixPath | None:
    """Return the checked relative path of a member (None for the archive root).

    Raises
    ------
    FMUError
        The name is absolute, has a drive letter, a ``..`` component or a NUL byte.
    """
    raw = info.filename
    if "\x00" in raw:
        raise FMUError(f"{fmu}: member {raw!r} has a NUL byte in its name; refusing the FMU")
    # FMI requires '/', but archives zipped on Windows may use '\'; treat both alike so
    # that neither 'C:\x' nor '..\x' slips through as a plain file name.
    name = raw.replace("\\", "/")
    if name.startswith("/"):
        raise FMUError(
            f"{fmu}: member {raw!r} has an absolute path (it would be written outside the "
            "extraction folder); refusing the FMU"
        )
    parts = [p for p in name.split("/") if p not in ("", ".")]
    if ".." in parts:
        raise FMUError(
            f"{fmu}: member {raw!r} has a '..' path component (it would be written "
            "outside the extraction folder); refusing the FMU"
        )
    if any(_DRIVE_RE.match(p) for p in parts):
        raise FMUError(
            f"{fmu}: member {raw!r} has a Windows drive letter in its path (it could be "
            "written outside the extraction folder); refusing the FMU"
        )
    return PurePosixPath(*parts) if parts else None


def _check_type(fmu: Path, info: zipfile.ZipInfo) -> None:
    """Refuse symbolic links and special files (devices, pipes, sockets)."""
    mode = info.external_attr >> 16
    # many zip writers store only the permission bits (file type 0): a regular file
    if info.create_system not in _UNIX_SYSTEMS or stat.S_IFMT(mode) == 0:
        return
    if stat.S_ISLNK(mode):
        raise FMUError(f"{fmu}: member {info.filename!r} is a symbolic link; refusing the FMU")
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise FMUError(
            f"{fmu}: member {info.filename!r} is a special file (mode {stat.filemode(mode)}); "
            "refusing the FMU"
        )


def _too_big(fmu: Path, what: str, size: int, limit: int) -> FMUError:
    return FMUError(
        f"{fmu}: {what} expands to {size:,} bytes, more than the limit of {limit:,} bytes "
        "(a damaged archive or a 'zip bomb'); refusing the FMU"
    )


def _open(fmu: Path) -> zipfile.ZipFile:
    check_fmu_file(fmu)
    try:
        return zipfile.ZipFile(fmu)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise FMUError(f"{fmu}: cannot read the ZIP archive: {exc}") from exc


def _plan(
    fmu: Path, archive: zipfile.ZipFile, limit: int, member_limit: int
) -> tuple[list[tuple[zipfile.ZipInfo, PurePosixPath]], int]:
    """Check every member before anything is written; return them and their total size."""
    members = archive.infolist()
    if len(members) > member_limit:
        raise FMUError(
            f"{fmu}: the archive has {len(members):,} members, more than the limit of "
            f"{member_limit:,}; refusing the FMU"
        )
    plan: list[tuple[zipfile.ZipInfo, PurePosixPath]] = []
    total = 0
    for info in members:
        rel = _member_path(fmu, info)
        _check_type(fmu, info)
        if rel is None:
            continue
        if info.file_size > limit:
            raise _too_big(fmu, f"member {info.filename!r}", info.file_size, limit)
        total += info.file_size
        plan.append((info, rel))
    if total > limit:
        largest = max(plan, key=lambda p: p[0].file_size)[0]
        raise _too_big(fmu, f"the archive (largest member {largest.filename!r})", total, limit)
    if not any(rel == PurePosixPath("modelDescription.xml") for _, rel in plan):
        nested = [str(rel) for _, rel in plan if rel.name == "modelDescription.xml"]
        hint = (
            f"; the archive holds {nested[0]!r}: zip the contents of the FMU folder, "
            "not the folder itself"
            if nested
            else ""
        )
        raise FMUError(
            f"{fmu}: not a valid FMU, modelDescription.xml is missing (no such member "
            f"at the root of the archive){hint}"
        )
    return plan, total


def _copy(
    fmu: Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo, target: Path, room: int
) -> int:
    """Write one member to ``target`` counting the bytes; return how many were written.

    ``room`` is what is left of the total limit.
    """
    size = 0
    with archive.open(info) as src, open(target, "wb") as out:
        while chunk := src.read(_CHUNK):
            size += len(chunk)
            if size > info.file_size:
                raise FMUError(
                    f"{fmu}: member {info.filename!r} expands beyond its declared "
                    f"size of {info.file_size:,} bytes (a forged header); refusing the FMU"
                )
            if size > room:
                return size
            out.write(chunk)
    return size


def _extract_member(
    fmu: Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo, target: Path, room: int
) -> int:
    """Create one member's folder or file; return the bytes written (FMUError on failure)."""
    try:
        if info.is_dir() or info.filename.endswith("\\"):
            target.mkdir(parents=True, exist_ok=True)
            return 0
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.is_symlink() or target.is_dir():
            raise FMUError(
                f"{fmu}: member {info.filename!r} clashes with another member of "
                "the same path; refusing the FMU"
            )
        return _copy(fmu, archive, info, target, room)
    except FMUError:
        raise
    except NotImplementedError as exc:  # before RuntimeError, its base
        raise FMUError(
            f"{fmu}: member {info.filename!r} uses ZIP compression method "
            f"{info.compress_type}, which cannot be read (FMUs use deflate or none)"
        ) from exc
    except RuntimeError as exc:  # zipfile: "... is encrypted, password required"
        raise FMUError(
            f"{fmu}: member {info.filename!r} is encrypted; an FMU must not be password-protected"
        ) from exc
    except (zipfile.BadZipFile, zlib.error, EOFError, ValueError) as exc:
        raise FMUError(f"{fmu}: member {info.filename!r} is damaged: {exc}") from exc
    except OSError as exc:
        if exc.errno in _ENVIRONMENT:
            raise _no_room(fmu, target, exc.strerror or str(exc)) from exc
        raise FMUError(
            f"{fmu}: cannot extract member {info.filename!r} to {target}: {exc}"
        ) from exc


def _no_room(fmu: Path, where: Path, reason: str) -> ResourceError:
    """Return the error of an extraction the machine, not the FMU, stopped (exit 4)."""
    return ResourceError(
        f"cannot extract {fmu.name}: writing {where}: {reason}; this is the temporary "
        "folder unless you chose another: point TMPDIR at a folder with room (and check "
        "the file-size limit, ulimit -f)"
    )


#: top folders of an FMU that no simulation reads (FMI 2 and FMI 3)
NOT_RUN = ("documentation", "terminalsAndIcons")


def _for_running(
    plan: list[tuple[zipfile.ZipInfo, PurePosixPath]],
) -> list[tuple[zipfile.ZipInfo, PurePosixPath]]:
    """Keep the members a simulation on this machine reads.

    ``modelDescription.xml``, ``resources/`` (its folder even when empty: JModelica.org's
    FMUs fail to instantiate without it) and ``extra/``; the binaries of this platform
    (FMI 2's ``linux64``, FMI 3's ``x86_64-linux``, ...) where the FMU has them, else
    every binary and the sources (to compile, or to name what is there). Documentation,
    icons, other platforms' binaries and stray files at the root are checked but not
    written: a vendor's manuals or a 2 GB member there cost no disk.
    """
    import fmpy  # the platform names, as FMPy loads the binaries

    mine = {fmpy.platform, fmpy.platform_tuple}

    def binary_here(rel: PurePosixPath) -> bool:
        return len(rel.parts) > 2 and rel.parts[0] == "binaries" and rel.parts[1] in mine

    has_binary = any(binary_here(rel) for _, rel in plan)
    keep = []
    for info, rel in plan:
        head = rel.parts[0]
        if len(rel.parts) == 1:  # a folder of its own (resources/, even empty) or the XML
            wanted = head == "modelDescription.xml" or (
                info.is_dir() and head not in (*NOT_RUN, "binaries", "sources")
            )
        elif head == "binaries":
            wanted = binary_here(rel) or not has_binary
        elif head == "sources":
            wanted = not has_binary
        else:
            wanted = head not in NOT_RUN
        if wanted:
            keep.append((info, rel))
    return keep


def safe_extract(
    fmu_path: str | os.PathLike[str],
    dest: str | os.PathLike[str],
    *,
    max_bytes: int | None = None,
    max_members: int | None = None,
    running: bool = False,
) -> Path:
    """Extract an FMU archive into ``dest`` after checking every member.

    Parameters
    ----------
    fmu_path : str or pathlib.Path
        The ``.fmu`` file.
    dest : str or pathlib.Path
        Folder to extract into (created if missing).  Nothing is written outside it.
    max_bytes : int, optional
        Limit on the total uncompressed size; default :data:`MAX_BYTES` (2 GiB).
    max_members : int, optional
        Limit on the number of members; default :data:`MAX_MEMBERS`.
    running : bool, optional
        Write only what a simulation on this machine reads (every member is still
        checked): no documentation, icons or other platforms' binaries, and the sources
        only where this platform has no binary.

    Returns
    -------
    pathlib.Path
        ``dest``, resolved.

    Raises
    ------
    FMUError
        The file is missing or not a ZIP archive; it has no ``modelDescription.xml`` at
        its root; a member's name is absolute, has a drive letter, ``..`` or a NUL byte;
        a member is a symbolic link or a special file; the declared sizes, or the bytes
        actually decompressed, exceed ``max_bytes``; a member is corrupt, encrypted or
        uses an unsupported compression.  The message names the FMU file and the member
        at fault.
    ResourceError
        Not the FMU's fault: not enough free space in ``dest``, a file-size limit, a
        folder that cannot be written (the message names the folder and ``TMPDIR``).

    ``dest`` may hold part of the archive afterwards; the caller owns and removes it.
    """
    fmu = Path(fmu_path)
    limit = MAX_BYTES if max_bytes is None else int(max_bytes)
    member_limit = MAX_MEMBERS if max_members is None else int(max_members)
    with _open(fmu) as archive:
        # 1. check everything before writing anything
        plan, total = _plan(fmu, archive, limit, member_limit)
        if running:
            plan = _for_running(plan)
            total = sum(info.file_size for info, _ in plan)
        root = Path(dest)
        root.mkdir(parents=True, exist_ok=True)
        root = root.resolve()
        free = shutil.disk_usage(root).free
        if total > free:
            raise _no_room(fmu, root, f"it needs {total:,} bytes but only {free:,} are free")
        # 2. extract, counting the bytes actually produced
        written = 0
        for info, rel in plan:
            target = root.joinpath(*rel.parts)
            # defence in depth: the joined path must stay inside root
            if os.path.commonpath([root, target.parent.resolve()]) != str(root):
                raise FMUError(
                    f"{fmu}: member {info.filename!r} would be written outside the "
                    "extraction folder; refusing the FMU"
                )
            written += _extract_member(fmu, archive, info, target, limit - written)
            if written > limit:
                raise _too_big(fmu, f"member {info.filename!r}", written, limit)
        if running:  # the standard hands every FMU its resources folder's URI
            _make_folder(fmu, root / "resources")
    return root


def _make_folder(fmu: Path, folder: Path) -> None:
    """Create ``folder`` unless it exists (a file of that name is the FMU's fault)."""
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise FMUError(f"{fmu}: {folder.name} is not a folder; refusing the FMU")
    try:
        folder.mkdir(exist_ok=True)
    except OSError as exc:
        raise ResourceError(f"cannot create {folder}: {exc.strerror or exc}") from None
