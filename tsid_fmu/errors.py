"""Exception types of tsid-fmu.

Every error the package raises on purpose derives from :class:`TsidError`, and its
message names the file, column, variable or FMI call at fault, so that the command
line can print it as one readable line instead of a traceback.
"""

from __future__ import annotations

__all__ = [
    "ArrayError",
    "BuildError",
    "DataError",
    "FMUError",
    "ResourceError",
    "SimulationError",
    "StudyError",
    "TsidError",
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
