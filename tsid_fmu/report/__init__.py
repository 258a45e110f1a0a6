"""Reports of a study: ``report.html``, ``report.md``, figures, and the files scripts read.

The figures are drawn once, at the end of a study, from its iteration records
(:mod:`.render`): each iteration's as SVG (:mod:`.svgfig`), the study's fit, convergence
and parameter trajectories as PNG at 2x (:mod:`.figures`, :mod:`.fitfig`).
``report.html`` (:mod:`.html`) embeds them all; :mod:`.notebook` gives the notebook view.
"""

from tsid_fmu.report.console import ConsoleProgress
from tsid_fmu.report.files import parameter_set_ssv, write_result_files
from tsid_fmu.report.html import html_report, write_html
from tsid_fmu.report.markdown import markdown_report, markdown_table
from tsid_fmu.report.notebook import parameter_rows  # registers the result's views
from tsid_fmu.report.plots import convergence_plot, fit_plot, main_effects_plot
from tsid_fmu.report.render import Figures, draw_study
from tsid_fmu.report.text import fit_report, text_report

__all__ = [
    "ConsoleProgress",
    "Figures",
    "convergence_plot",
    "draw_study",
    "fit_plot",
    "fit_report",
    "html_report",
    "main_effects_plot",
    "markdown_report",
    "markdown_table",
    "parameter_rows",
    "parameter_set_ssv",
    "text_report",
    "write_html",
    "write_result_files",
]
