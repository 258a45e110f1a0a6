"""Under ``-q``, Python warnings go to the study's ``warnings.log``, not to stderr.

A library's warning (NumPy's "overflow encountered in square" from a cost past 1e154,
a deprecation in pandas) printed in the middle of a quiet run is noise on stderr, where
a script looks for tsid's one error line. Under ``-q`` each warning is kept instead: as
a line of ``warnings.log`` in the study's output folder (``tsid identify``), or dropped
where the command has no folder of its own (``tsid screen``, ``tsid design``).
"""

from __future__ import annotations

import contextlib
import logging
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["WARNINGS_LOG", "warnings_to_log"]

WARNINGS_LOG = "warnings.log"
"""The file in a study's output folder that holds the warnings of a quiet run."""

LOGGER = "tsid_fmu.warnings"
"""The logger the warnings of a quiet run go through (one record per warning)."""


class _FolderLog(logging.Handler):
    """Append each record to ``folder / warnings.log`` once the folder is the study's.

    A folder without tsid's fingerprint gets no file from tsid: the next run would
    refuse it as holding files tsid did not write. Records wait until the fingerprint
    is there (the study loaded, its trail opened), then go out in order; the ones still
    waiting when the run ends are dropped, as is a record the file cannot take.
    """

    def __init__(self, folder: Path | None) -> None:
        super().__init__()
        self.folder = folder
        self.pending: list[str] = []
        self.setFormatter(logging.Formatter("%(asctime)s %(message)s"))

    def emit(self, record: logging.LogRecord) -> None:
        self.pending.append(self.format(record))
        self.flush()

    def flush(self) -> None:
        from tsid_fmu.trail.owner import FINGERPRINT

        if self.folder is None or not self.pending or not (self.folder / FINGERPRINT).is_file():
            return
        with contextlib.suppress(OSError):
            with open(self.folder / WARNINGS_LOG, "a", encoding="utf-8") as f:
                f.write("".join(f"{line}\n" for line in self.pending))
            self.pending.clear()


@contextlib.contextmanager
def warnings_to_log(folder: Path | None) -> Iterator[None]:
    """Send the Python warnings raised in the block to ``folder / warnings.log``.

    The warnings filters stay as they are (a warning shown once per place is recorded
    once); what would have been printed on stderr becomes a record of the
    :data:`LOGGER` logger, which writes it to the folder's :data:`WARNINGS_LOG`
    (:class:`_FolderLog`); without a folder the records are dropped. The filters, the
    printing of warnings and the logger are as before when the block ends.
    """
    logger = logging.getLogger(LOGGER)
    handler = _FolderLog(folder)
    saved = logger.propagate, logger.level
    logger.addHandler(handler)
    logger.propagate = False  # not to the root logger, whose last resort is stderr
    logger.setLevel(logging.WARNING)

    def record(message: Any, category: Any, filename: str, lineno: int, *_: Any) -> None:
        text = warnings.formatwarning(message, category, filename, lineno, None).strip()
        logger.warning("%s", " ".join(text.split()))

    try:
        with warnings.catch_warnings():
            warnings.showwarning = record
            yield
    finally:
        logger.removeHandler(handler)
        logger.propagate, level = saved
        logger.setLevel(level)
        handler.flush()
