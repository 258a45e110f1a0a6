"""Reports of a study: plots, ``report.md``, and the files other tools and scripts open."""

from tsid_fmu.report.console import ConsoleProgress
from tsid_fmu.report.files import parameter_set_ssv, write_result_files
from tsid_fmu.report.markdown import markdown_report, markdown_table
from tsid_fmu.report.plots import convergence_plot, fit_plot, main_effects_plot

__all__ = [
    "ConsoleProgress",
    "convergence_plot",
    "fit_plot",
    "main_effects_plot",
    "markdown_report",
    "markdown_table",
    "parameter_set_ssv",
    "write_result_files",
]
