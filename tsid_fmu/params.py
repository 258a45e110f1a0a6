"""Identified parameters in lmfit's manner: ``res.params[name].stderr``.

:class:`Param` is a ``float`` (the identified value, so that arithmetic, NumPy and JSON
take it as the number it is) that also carries lmfit's attributes: ``value``,
``stderr``, ``min``, ``max``, ``vary``, and tsid's ``interval``, ``unit`` and ``weak``.
:class:`Parameters` is the mapping of them by name, in the study's order.
:func:`describe` fills them in from a finished result.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["Param", "Parameters", "describe"]


class Param(float):
    """One identified parameter: its value as a float, with lmfit's attributes.

    Parameters
    ----------
    value : float
        The identified value.
    name : str
        The parameter's name (the FMU variable, or ``name[<experiment>]`` for a copy).
    stderr : float
        Standard error in the parameter's units (``inf``: not determined; ``nan``: not
        computed, e.g. a paused study or a discrete choice).
    interval : tuple of float or None
        The 95 % interval ``(low, high)``; an end of ``None`` is open (not determined);
        ``None`` where no interval was computed.
    unit : str
        The unit (the study's, else the FMU's declared one).
    min, max : float
        The physical bounds the search kept to (lmfit's names).
    vary : bool
        False for a discrete choice of structure identification (lmfit: a fixed
        parameter); it then has no standard error.
    weak : str or None
        Why the data determine it poorly, where they do.
    correl : dict or None
        Its correlation with each other parameter the data determine, by name (lmfit's
        ``Param.correl``); ``None`` where none was computed or it is not determined.
    """

    name: str
    stderr: float
    interval: tuple[float | None, float | None] | None
    unit: str
    min: float
    max: float
    vary: bool
    weak: str | None
    correl: dict[str, float] | None

    def __new__(cls, value: float, **attrs: Any) -> Param:  # noqa: D102
        self = super().__new__(cls, value)
        self.name = str(attrs.get("name", ""))
        self.stderr = float(attrs.get("stderr", math.nan))
        self.interval = attrs.get("interval")
        self.unit = str(attrs.get("unit", ""))
        self.min = float(attrs.get("min", -math.inf))
        self.max = float(attrs.get("max", math.inf))
        self.vary = bool(attrs.get("vary", True))
        self.weak = attrs.get("weak")
        correl = attrs.get("correl")
        self.correl = None if correl is None else {str(k): float(v) for k, v in correl.items()}
        return self

    @property
    def value(self) -> float:
        """The identified value, as a plain float."""
        return float(self)

    def __reduce__(self) -> tuple[Any, ...]:
        return (_param, (float(self), dict(self.__dict__)))

    __repr__ = float.__repr__  # the number, as before: files and f-strings write it
    __str__ = float.__repr__


def _param(value: float, attrs: dict[str, Any]) -> Param:
    """Rebuild a pickled :class:`Param`."""
    return Param(value, **attrs)


class Parameters(dict[str, float]):
    """The identified parameters by name, in the study's order (lmfit's ``Parameters``).

    Each value is a :class:`Param`: a float with ``stderr``, ``interval``, ``unit``,
    ``min``, ``max``, ``vary`` and ``weak``.
    """

    def valuesdict(self) -> dict[str, float]:
        """Return the values as plain floats by name (lmfit's name)."""
        return {k: float(v) for k, v in self.items()}


def describe(result: Any) -> Parameters:
    """Return :attr:`IdentificationResult.params` with each value's attributes filled in.

    Parameters
    ----------
    result : IdentificationResult
        A result whose ``params``, ``intervals``, ``uncertainty``, ``weak`` and ``study``
        are set (any of the last four may be empty).

    Returns
    -------
    tsid_fmu.params.Parameters
        The same values, in the same order, each a :class:`Param`.
    """
    from tsid_fmu.study.units import study_units

    study = result.study
    units = study_units(study) if study is not None else {}
    bounds = study.bounds() if study is not None else {}
    u = result.uncertainty
    chosen = (result.structure or {}).get("values") or {}
    out = Parameters()
    for name, value in result.params.items():
        low, high = bounds.get(name, (-math.inf, math.inf))
        interval = result.intervals.get(name)
        se = math.nan
        if u is not None and name in u.std_error and name not in chosen:
            se = float(u.std_error[name])
        correl = None
        if u is not None and math.isfinite(se) and name in u.correlation:
            correl = {
                other: float(c)
                for other, c in u.correlation[name].items()
                if other != name
                and other not in chosen
                and math.isfinite(float(u.std_error.get(other, math.nan)))
                and math.isfinite(float(c))
            }
        out[name] = Param(
            float(value),
            name=name,
            stderr=se,
            interval=None if not interval else (interval[0], interval[1]),
            unit=units.get(name, ""),
            min=low,
            max=high,
            vary=name not in chosen,
            weak=result.weak.get(name),
            correl=correl,
        )
    return out
