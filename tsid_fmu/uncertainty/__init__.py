"""How well the data determine the answer: sensitivities, intervals, fit and mismatch."""

from tsid_fmu.uncertainty.assess import MISMATCH, Assessment, assess, standard_errors, validate
from tsid_fmu.uncertainty.intervals import Z95, Uncertainty, uncertainty
from tsid_fmu.uncertainty.residuals import Whiteness, ljung_box, long_run_covariance
from tsid_fmu.uncertainty.sensitivity import Sensitivities, sensitivities

__all__ = [
    "MISMATCH",
    "Z95",
    "Assessment",
    "Sensitivities",
    "Uncertainty",
    "Whiteness",
    "assess",
    "ljung_box",
    "long_run_covariance",
    "sensitivities",
    "standard_errors",
    "uncertainty",
    "validate",
]
