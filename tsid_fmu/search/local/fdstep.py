"""Finite-difference steps from the FMU's own noise: :mod:`tsid_fmu.numerics.fdstep`.

Kept here by name for the refinement's modules; the numerics live in the neutral
module that the search and the uncertainty both import.
"""

from tsid_fmu.numerics.fdstep import *  # noqa: F403
from tsid_fmu.numerics.fdstep import __all__  # noqa: F401
