"""Sensitivity screening before an identification: which parameters the outputs feel.

:func:`screen` runs Morris (cheap) or Sobol (thorough) through SALib over a study's first
ranges, with the search's evaluator, and the MISO paper's eq. (7) from an L25 beside it;
:class:`ScreeningResult` holds the indices, the parameters set apart and both rankings.
"""

from __future__ import annotations

from tsid_fmu.screening.result import ScreeningResult
from tsid_fmu.screening.run import screen

__all__ = ["ScreeningResult", "screen"]
