"""The FMU runtime: open an FMU once, simulate it many times against measured inputs.

- :func:`simulate`: one call, a DataFrame in and out (sessions cached);
- :class:`FMUSession`: extract once, instantiate once, reset between runs
  (Co-Simulation and Model Exchange, FMI 2.0 and 3.0);
- :func:`fmu_info`: a summary of an FMU's variables; :class:`VariableInfo`;
- :func:`safe_extract`: extract an untrusted FMU archive.

Modules, in the order of the data flow: :mod:`~tsid_fmu.fmu.archive` (extraction),
:mod:`~tsid_fmu.fmu.extraction` (one extraction per FMU file and process),
:mod:`~tsid_fmu.fmu.variables` and :mod:`~tsid_fmu.fmu.info` (model description),
:mod:`~tsid_fmu.fmu.library` (shared library), :mod:`~tsid_fmu.fmu.logs` (FMU log
messages), :mod:`~tsid_fmu.fmu.grid` (input hold, communication points),
:mod:`~tsid_fmu.fmu.steploop` and :mod:`~tsid_fmu.fmu.compiled` (the step loop,
interpreted or compiled), :mod:`~tsid_fmu.fmu.meloop` and :mod:`~tsid_fmu.fmu.mesolver`
(the Model Exchange integrator, likewise), :mod:`~tsid_fmu.fmu.exchange` (Model
Exchange by FMPy's CVode),
:mod:`~tsid_fmu.fmu.session` and :mod:`~tsid_fmu.fmu.facade` (:func:`simulate`).
"""

from __future__ import annotations

from tsid_fmu.fmu.archive import safe_extract
from tsid_fmu.fmu.facade import simulate
from tsid_fmu.fmu.info import fmu_info
from tsid_fmu.fmu.session import FMUSession
from tsid_fmu.fmu.variables import VariableInfo

__all__ = ["FMUSession", "VariableInfo", "fmu_info", "safe_extract", "simulate"]
