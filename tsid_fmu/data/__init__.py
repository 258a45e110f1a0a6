"""Measured data: files or frames, checks, and derived channels (input reconstruction).

* :func:`load_data` / :meth:`MeasuredData.from_frame`: read and check a record (uniform
  time, numeric and finite values), naming the file, column and row of any problem;
* :mod:`~tsid_fmu.data.expressions`: the safe expression language of derived channels,
  with ``der()`` for velocities and accelerations of logged positions
  (:func:`~tsid_fmu.data.derivative.derivative`).
"""

from tsid_fmu.data.derivative import DEFAULT_WINDOW, derivative
from tsid_fmu.data.expressions import FUNCTIONS, evaluate, names_used
from tsid_fmu.data.measured import MeasuredData, load_data

__all__ = [
    "DEFAULT_WINDOW",
    "FUNCTIONS",
    "MeasuredData",
    "derivative",
    "evaluate",
    "load_data",
    "names_used",
]
