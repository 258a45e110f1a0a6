"""tsid-fmu: Taguchi-method identification of FMU parameters from measured data.

The flat public API, over the layers of the data flow (see ``docs/explanation/architecture.md``):

- :func:`simulate`: one FMU simulation against a DataFrame of inputs;
- :func:`identify`: a whole study, returning an :class:`IdentificationResult`;
- :func:`screen`: a sensitivity screening (Morris or Sobol, through SALib) over a
  study's first ranges, beside the MISO paper's eq. (7) from an L25
  (:class:`ScreeningResult`);
- :func:`design`: the experiment that determines what a result left open, or why none
  can (:class:`Design`, from the study's ``[design]`` table, :class:`DesignOptions`),
  and :func:`write_design`, its files;
- :func:`load`: the :class:`IdentificationResult` of a finished study's results folder;
- :class:`Study` with :class:`Parameter`, :class:`Choice` (a discrete factor),
  :class:`ModelChoice` (a choice among FMU files), :class:`Experiment` and :class:`Method`,
  built in Python or read with :meth:`Study.from_toml`;
- the error types, all derived from :class:`TsidError`.
"""

from __future__ import annotations

# first of all: `tsid` on the command line holds Ctrl-C while the imports below run
import tsid_fmu._startup  # noqa: F401  # isort: skip
from tsid_fmu.design import Design, DesignOptions, design, write_design
from tsid_fmu.errors import (
    ArrayError,
    BuildError,
    DataError,
    FMUError,
    ResourceError,
    SimulationError,
    StudyError,
    TsidError,
)
from tsid_fmu.fmu import simulate
from tsid_fmu.identify import identify
from tsid_fmu.load import load
from tsid_fmu.params import Param, Parameters
from tsid_fmu.result import IdentificationResult
from tsid_fmu.screening import ScreeningResult, screen
from tsid_fmu.study import (
    Choice,
    ContributionOptions,
    Experiment,
    Method,
    ModelChoice,
    Parameter,
    Phase,
    Study,
)

__version__ = "0.2.0"

__all__ = [
    "ArrayError",
    "BuildError",
    "Choice",
    "ContributionOptions",
    "DataError",
    "Design",
    "DesignOptions",
    "Experiment",
    "FMUError",
    "IdentificationResult",
    "Method",
    "ModelChoice",
    "Param",
    "Parameter",
    "Parameters",
    "Phase",
    "ResourceError",
    "ScreeningResult",
    "SimulationError",
    "Study",
    "StudyError",
    "TsidError",
    "__version__",
    "design",
    "identify",
    "load",
    "screen",
    "simulate",
    "write_design",
]
