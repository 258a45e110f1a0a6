"""How well the data determine the answer: sensitivities, intervals, fit and mismatch.

Also whether the FMU's solver, not the physics, decides it (:mod:`.fidelity`).
"""

from tsid_fmu.uncertainty.assess import MISMATCH, Assessment, assess, standard_errors, validate
from tsid_fmu.uncertainty.fidelity import Fidelity, check_fidelity
from tsid_fmu.uncertainty.intervals import Z95, Uncertainty, uncertainty
from tsid_fmu.uncertainty.longrun import long_run_covariance
from tsid_fmu.uncertainty.residuals import Whiteness, ljung_box
from tsid_fmu.uncertainty.sensitivity import Sensitivities, sensitivities

__all__ = [
    "MISMATCH",
    "Z95",
    "Assessment",
    "Fidelity",
    "Sensitivities",
    "Uncertainty",
    "Whiteness",
    "assess",
    "check_fidelity",
    "ljung_box",
    "long_run_covariance",
    "sensitivities",
    "standard_errors",
    "uncertainty",
    "validate",
]
