"""The search coordinates: :class:`~tsid_fmu.numerics.space.Space` (kept here by name).

The search (:mod:`tsid_fmu.search`) and the assessment of its answer
(:mod:`tsid_fmu.uncertainty`) share their numerics through :mod:`tsid_fmu.numerics`
alone, never by importing each other.
"""

from tsid_fmu.numerics.space import FLOOR_BAND, Space

__all__ = ["FLOOR_BAND", "Space"]
