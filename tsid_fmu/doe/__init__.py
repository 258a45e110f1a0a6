"""Design of experiments: orthogonal arrays, S/N ratios, response tables, ANOVA, re-leveling.

The pure, FMU-free half of the Taguchi method. Everything here works on numbers: the
array rows to run, the S/N of each run, the mean S/N per level, the share of each factor
in the variation, and the levels of the next iteration.
"""

from tsid_fmu.doe.anova import AnovaTable, anova
from tsid_fmu.doe.arrays import (
    OrthogonalArray,
    available_arrays,
    check_orthogonal,
    get_array,
    select_array,
)
from tsid_fmu.doe.leveling import LevelingDecision, make_levels, relative_span, relevel
from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.doe.response import ResponseTable, response_table
from tsid_fmu.doe.rules import FactorDecision, FactorState, decide_factor, main_effect_optimum
from tsid_fmu.doe.sn import SN_CAP, sn_larger_the_better, sn_nominal_the_best, sn_smaller_the_better

__all__ = [
    "SN_CAP",
    "AnovaTable",
    "FactorDecision",
    "FactorState",
    "LevelingDecision",
    "LevelingOptions",
    "OrthogonalArray",
    "ResponseTable",
    "anova",
    "available_arrays",
    "check_orthogonal",
    "decide_factor",
    "get_array",
    "main_effect_optimum",
    "make_levels",
    "relative_span",
    "relevel",
    "response_table",
    "select_array",
    "sn_larger_the_better",
    "sn_nominal_the_best",
    "sn_smaller_the_better",
]
