"""Exception types of tsid-fmu.

Every error the package raises on purpose derives from :class:`TsidError`, and its
message names the file, column, variable or FMI call at fault, so that the command
line can print it as one readable line instead of a traceback.
"""

from __future__ import annotations

import unicodedata

__all__ = [
    "ArrayError",
    "BuildError",
    "DataError",
    "FMUError",
    "ResourceError",
    "SimulationError",
    "StudyError",
    "TsidError",
    "one_line",
]


class TsidError(Exception):
    """Base class of every error raised on purpose by tsid-fmu."""


class ArrayError(TsidError):
    """An orthogonal array was asked for that does not exist or cannot hold the factors."""


class BuildError(TsidError):
    """Turning a Modelica model into an FMU failed (parse, flatten, code generation, compile)."""


class DataError(TsidError):
    """A measured data file is missing, unreadable or inconsistent."""


class StudyError(TsidError):
    """A study file or study definition is invalid."""


class FMUError(TsidError):
    """An FMU cannot be opened, is malformed, or does not fit the study."""


class SimulationError(TsidError):
    """A simulation of an FMU failed (FMI error status, non-finite output, time-out)."""


class ResourceError(TsidError):
    """The machine lacks what a run needs: room or write access in a folder, a file-size limit.

    An environment error, not bad input: the command line exits with 4 (a full temporary
    folder while an FMU is extracted names ``TMPDIR``, where that folder can be moved).
    """


REASON = 400
"""Characters of a failed simulation's reason kept in a one-line message (:func:`one_line`)."""


def one_line(text: str) -> str:
    """Return ``text`` as one line: line breaks as `` | ``, control characters dropped.

    What an FMU printed can hold newlines and terminal escapes; a CLI error is one line.
    Longer than :data:`REASON` characters, it is cut with an ellipsis.
    """
    lines = [ln.strip() for ln in str(text).splitlines()]
    joined = " | ".join(ln for ln in lines if ln)
    kept = "".join(c for c in joined if not unicodedata.category(c).startswith("C"))
    return kept if len(kept) <= REASON else kept[: REASON - 3] + "..."
