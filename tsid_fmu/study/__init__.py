"""Studies: what to identify, from which data, with which method; and their preparation.

* :class:`Study` with its parts :class:`Parameter`, :class:`Experiment`,
  :class:`Method`, :class:`Phase` and :class:`ContributionOptions`;
* :meth:`Study.from_toml` / :meth:`Study.to_toml` (:mod:`tsid_fmu.study.toml`);
* :func:`prepare`: the loaded, weighted experiments an evaluator needs.
"""

from tsid_fmu.study import schema
from tsid_fmu.study.choice import Choice, ModelChoice
from tsid_fmu.study.definition import Study, load_study
from tsid_fmu.study.prepare import load_experiment, prepare, serial_evaluator
from tsid_fmu.study.schema import *  # noqa: F403 (the parts, listed once in schema.__all__)

__all__ = [
    *schema.__all__,
    "Choice",
    "ModelChoice",
    "Study",
    "load_experiment",
    "load_study",
    "prepare",
    "serial_evaluator",
]
