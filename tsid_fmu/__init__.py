"""tsid-fmu: Taguchi-method identification of FMU parameters from measured data."""

from __future__ import annotations

from tsid_fmu.errors import (
    ArrayError,
    BuildError,
    DataError,
    FMUError,
    SimulationError,
    StudyError,
    TsidError,
)
from tsid_fmu.fmu import simulate

__version__ = "0.1.0"

__all__ = [
    "ArrayError",
    "BuildError",
    "DataError",
    "FMUError",
    "SimulationError",
    "StudyError",
    "TsidError",
    "__version__",
    "simulate",
]
