"""Name the files a report was made from without giving away where they lie.

A report is shared (mailed, attached to a ticket); an absolute path in it tells the
reader the author's user name and folder layout and nothing they can use. The FMU is
named by its file name and the first :data:`DIGEST_CHARS` hex digits of its SHA-256,
which identify the exact file a reader holds.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

__all__ = ["DIGEST_CHARS", "fmu_label"]

DIGEST_CHARS = 12
"""Hex digits of the SHA-256 shown beside a file name."""


def _sha256(path: Path) -> str | None:
    digest = hashlib.sha256()
    try:
        with path.open("rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
    except OSError:  # moved or deleted since the study ran: the name alone
        return None
    return digest.hexdigest()


def fmu_label(study: Any) -> str:
    """Return ``"Model.fmu (SHA-256 0123456789ab)"`` for the study's FMU, ``"-"`` if none.

    Parameters
    ----------
    study : Study or None
        The study whose ``fmu`` is named.

    Returns
    -------
    str
        The file name and its digest (the name alone if the file cannot be read).
    """
    if study is None:
        return "-"
    path = Path(getattr(study, "simulated_fmu", study.fmu))
    digest = _sha256(path)
    if digest is None:
        return path.name
    return f"{path.name} (SHA-256 {digest[:DIGEST_CHARS]})"
