"""The phases of a study and the contribution analyses that plan them (MISO paper).

Re-exported by :mod:`tsid_fmu.study.schema`, beside the other parts of a study.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tsid_fmu.errors import StudyError
from tsid_fmu.study.checks import check_number

__all__ = ["ContributionOptions", "Phase"]


@dataclass
class Phase:
    """One phase of a phased identification: a group of parameters, some experiments.

    Parameters
    ----------
    parameters : list of str
        Parameters identified in this phase; the others stay at their current values.
    experiments : list of str
        Names of the experiments fitted in this phase (default: every ``identify`` one).
    name : str
        Label (default ``phase N``).
    array : str, optional
        Orthogonal array of this phase (default: the smallest that fits).
    max_iterations : int, optional
        Iteration limit of this phase (default: the study's).
    """

    parameters: list[str]
    experiments: list[str] = field(default_factory=list)
    name: str = ""
    array: str | None = None
    max_iterations: int | None = None


@dataclass
class ContributionOptions:
    """Contribution analyses of the MISO paper that plan the phases automatically.

    Parameters
    ----------
    enabled : bool
        Run the input and parameter contribution analyses and identify in phases.
    group_ratio : float
        Gap between the contributions of consecutive parameters that starts a new group
        (see :func:`tsid_fmu.search.phases.contribution.group_parameters`). Default 1.75.
    min_percent : float
        A parameter contributing less than this (% of error variation) to an
        experiment is left for the next experiment's phases. Default 1.
    values : mapping of str to list of float
        Three values per parameter for the one-at-a-time runs (default: lowest,
        middle and highest first-iteration level).
    compare_ungrouped : bool
        Also identify all parameters in one array on all experiments and report the
        difference in cost and simulations (why grouping exists, or where it does not
        pay).
    refine_jointly : bool
        After the phases, one more phase identifies all parameters together on all
        identification experiments, from ranges within ``refine_span`` of the phase
        results. Default true.
    refine_span : float
        Relative half-width of the joint phase's first levels. Default 0.2.
    """

    enabled: bool = False
    group_ratio: float = 1.75
    min_percent: float = 1.0
    values: dict[str, list[float]] = field(default_factory=dict)
    compare_ungrouped: bool = False
    refine_jointly: bool = True
    refine_span: float = 0.2

    def __post_init__(self) -> None:
        if not 0 < check_number(self.refine_span, "refine_span") < 1:
            raise StudyError(f"refine_span must be between 0 and 1, got {self.refine_span}")
        if not check_number(self.group_ratio, "group_ratio") > 1:
            raise StudyError(f"group_ratio must be > 1, got {self.group_ratio}")
        if not check_number(self.min_percent, "min_percent") >= 0:
            raise StudyError(f"min_percent must be >= 0, got {self.min_percent}")
        for name, vals in self.values.items():
            nums = [check_number(v, f"contribution value of {name!r}") for v in vals]
            if len(nums) != 3 or len(set(nums)) != 3:
                raise StudyError(f"contribution values of {name!r} must be 3 distinct numbers")
