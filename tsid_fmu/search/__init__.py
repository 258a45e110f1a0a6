"""The search: the stages that find the answer, one sub-package per part of the procedure.

- :mod:`~tsid_fmu.search.taguchi`: the Taguchi stage (:mod:`~tsid_fmu.search.taguchi.stage`),
  its iterations (:mod:`~tsid_fmu.search.taguchi.iteration`) over factors
  (:mod:`~tsid_fmu.search.taguchi.frame`) and re-leveling
  (:mod:`~tsid_fmu.search.taguchi.nextlevels`);
- :mod:`~tsid_fmu.search.phases`: the MISO paper's contribution analyses and phases;
- :mod:`~tsid_fmu.search.local`: the local search after the arrays (refinement,
  horizons, restarts; :mod:`~tsid_fmu.search.local.flow`);
- :mod:`~tsid_fmu.search.structure`: structure identification (mixed arrays,
  candidates, nesting, selection);
- :mod:`~tsid_fmu.search.verdict`: the stationarity tests that earn exit status 0;
- :mod:`~tsid_fmu.search.pipeline`: the stages of a study, in order; shared:
  :mod:`~tsid_fmu.search.space` (coordinates), :mod:`~tsid_fmu.search.record` (what an
  iteration leaves), :mod:`~tsid_fmu.search.stage` (a stage's result),
  :mod:`~tsid_fmu.search.context` (what the stages share).
"""

from tsid_fmu.search.pipeline import Control, run_stages
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageResult

__all__ = ["Control", "IterationRecord", "StageResult", "run_stages"]
