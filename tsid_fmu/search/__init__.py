"""The search: stages of Taguchi iterations over factors, phases, and the refinement.

- :mod:`~tsid_fmu.search.space` and :mod:`~tsid_fmu.search.frame`: the coordinates and
  the factors (parameters, or rotated combinations) of an iteration;
- :mod:`~tsid_fmu.search.iteration`: one iteration (array runs, S/N, prediction,
  confirmation, re-leveling) and :mod:`~tsid_fmu.search.record`, what it leaves;
- :mod:`~tsid_fmu.search.taguchi`: the Taguchi stage, iterations until Case 3;
- :mod:`~tsid_fmu.search.phases` and :mod:`~tsid_fmu.search.contribution`: the MISO
  paper's contribution analyses and phases;
- :mod:`~tsid_fmu.search.refine`: the optional least-squares refinement;
- :mod:`~tsid_fmu.search.pipeline`: the stages of a study, in order.
"""

from tsid_fmu.search.pipeline import Control, run_stages
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageResult

__all__ = ["Control", "IterationRecord", "StageResult", "run_stages"]
