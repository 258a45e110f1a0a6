"""Checksums of the trail: a record names its files' hashes and carries its own digest.

Every ``record.json`` lists the SHA-256 of each file its iteration wrote before it
(``files``) and ends with a ``digest``: the SHA-256 of the rest of the record in a
canonical JSON form. ``stage.json`` and ``fingerprint.json`` carry a digest too. On
``--resume`` the trail recomputes them, so a file that was damaged (a truncated copy,
a disk error) or changed by hand (an edited ``best_cost``) is named instead of being
trusted. ``next_levels.toml`` is the one file a person may edit: its hash is kept but
not checked.

The digests detect damage and careless edits, not a forger: anyone who can write the
folder can recompute them.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tsid_fmu.errors import StudyError
from tsid_fmu.trail.files import strict

__all__ = [
    "EDITABLE",
    "REPORT_FIGURES",
    "file_hashes",
    "seal",
    "sha256_file",
    "unexpected_files",
    "unseal",
    "verify_files",
]

EDITABLE = frozenset({"next_levels.toml"})
"""Files of an iteration that a person may edit between runs."""

REPORT_FIGURES = frozenset({"main_effects.svg", "fit.svg"})
"""Files the report draws into an iteration's folder after its record (report/render.py)."""

_CHUNK = 1 << 20


def sha256_file(path: Path) -> str:
    """Return the SHA-256 of a file's bytes, as hexadecimal.

    Raises
    ------
    OSError
        Also for a path that is not a regular file (``/dev/zero``, a named pipe), whose
        reading would never end; it is opened without blocking and not read.
    """
    h = hashlib.sha256()
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with open(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", os.fspath(path))
        while chunk := fh.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def _digest(data: Mapping[str, Any]) -> str:
    text = json.dumps(strict(dict(data)), sort_keys=True, allow_nan=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def seal(data: Mapping[str, Any]) -> dict[str, Any]:
    """Return ``data`` with its ``digest`` (strict JSON, as it will be written)."""
    body = strict({k: v for k, v in data.items() if k != "digest"})
    return {**body, "digest": _digest(body)}


def unseal(data: Any, path: Path, what: str, advice: str) -> dict[str, Any]:
    """Return a sealed file's content without its digest, after checking it.

    ``advice`` ends the message: what a person can do about it.

    Raises
    ------
    StudyError
        The digest is missing or does not match: the file was changed or damaged.
    """
    if not isinstance(data, dict) or not isinstance(data.get("digest"), str):
        raise StudyError(f"{path}: damaged {what} (no checksum); {advice}")
    body = {k: v for k, v in data.items() if k != "digest"}
    if _digest(body) != data["digest"]:
        raise StudyError(
            f"{path}: the {what} was changed or damaged after tsid-fmu wrote it (its "
            f"checksum does not match); {advice}"
        )
    return body


def file_hashes(folder: Path, skip: str = "record.json") -> dict[str, str]:
    """Return ``{name: sha256}`` of the plain files in ``folder`` (hidden ones left out)."""
    return {
        p.name: sha256_file(p)
        for p in sorted(folder.iterdir())
        if p.is_file() and not p.name.startswith(".") and p.name != skip
    }


def verify_files(folder: Path, hashes: Any, record: Path) -> None:
    """Check the files listed in an iteration's record against their hashes.

    Raises
    ------
    StudyError
        Naming the first file that is missing, changed or damaged.
    """
    if not isinstance(hashes, dict) or not all(isinstance(v, str) for v in hashes.values()):
        raise StudyError(f"{record}: damaged iteration record (no list of file hashes)")
    for name, expected in sorted(hashes.items()):
        path = folder / name
        if name in EDITABLE or Path(name).name != name:
            continue
        if not path.is_file():
            raise StudyError(
                f"{path}: missing, but {record.name} lists it; restore it, or delete "
                f"{folder} and the iterations after it to redo them"
            )
        if sha256_file(path) != expected:
            raise StudyError(
                f"{path}: changed or damaged since tsid-fmu wrote it (its SHA-256 differs "
                f"from the one in {record.name}); restore it, or delete {folder} and the "
                "iterations after it to redo them"
            )


def unexpected_files(folder: Path, hashes: Any) -> list[str]:
    """Return the names in an iteration's folder that tsid-fmu did not write there.

    Known are the files the record lists, ``record.json`` and :data:`REPORT_FIGURES`;
    hidden names (an atomic write cut short) are left out.
    """
    known = {*(hashes if isinstance(hashes, dict) else {}), "record.json", *REPORT_FIGURES}
    return sorted(
        p.name for p in folder.iterdir() if not p.name.startswith(".") and p.name not in known
    )
