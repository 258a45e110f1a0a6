"""Experiment design: what to measure next (``tsid design``).

:func:`design` takes a finished identification and proposes, from the family of inputs
the study's ``[design]`` table allows (:class:`~tsid_fmu.study.designopts.DesignOptions`),
the experiment that best determines what the data left weak, with the intervals the
study plus that experiment would give; or it finds that no such input can separate
some parameters (a structural symmetry), names what the data do fix, and says what
would fix the rest. :func:`write_design` writes the input to replay on the rig, a plot,
the tables and the report section.
"""

from tsid_fmu.design.files import plot_design, write_design
from tsid_fmu.design.outcome import Design, Structural
from tsid_fmu.design.run import design
from tsid_fmu.design.signals import Signal
from tsid_fmu.study.designopts import DesignOptions

__all__ = [
    "Design",
    "DesignOptions",
    "Signal",
    "Structural",
    "design",
    "plot_design",
    "write_design",
]
