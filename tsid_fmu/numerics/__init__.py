"""Numerics the search and the uncertainty share, so that neither imports the other.

- :mod:`~tsid_fmu.numerics.space`: search coordinates (log or linear, scaled by the
  first levels' range) and back;
- :mod:`~tsid_fmu.numerics.fdstep`: the one forward-difference Jacobian, its steps from
  the FMU's own noise;
- :mod:`~tsid_fmu.numerics.lsq`: the one least-squares driver (SciPy's trust region);
- :mod:`~tsid_fmu.numerics.rank`: the rank threshold of an unseen direction.

``tsid_fmu.search`` and ``tsid_fmu.uncertainty`` import these and never each other
(``tests/test_layers.py``).
"""
