"""The factors of one Taguchi iteration and where their levels lie.

A :class:`Frame` is a centre and one :class:`Factor` per parameter. A factor is either
**a parameter** (axis-aligned, as in the papers), whose levels are exact parameter
values (the user's first levels, or levels made by :func:`tsid_fmu.doe.leveling.relevel`),
or **a rotated factor**: a direction in the search coordinates of
:mod:`tsid_fmu.search.space` along which several parameters move together, with level
offsets along it. Rotated factors are the principal axes of the cost surface as the
array runs show it (:mod:`tsid_fmu.search.taguchi.surface`): where parameters act only in
combination (a mass and a stiffness through the natural frequency), one factor moves
the combination and another its complement, so the main effects of an orthogonal array
are no longer confounded by that interaction.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.search.space import Space

__all__ = ["Factor", "Frame"]


@dataclass
class Factor:
    """One factor of an iteration.

    Attributes
    ----------
    name : str
        The parameter's name, or ``A1``, ``A2``, ... for rotated factors (stiffest
        combination first).
    direction : numpy.ndarray
        Unit vector in search coordinates.
    offsets : numpy.ndarray
        Increasing offsets of the levels from the centre along ``direction``.
    values : list of float or None
        For a parameter: the exact parameter value of each level.
    """

    name: str
    direction: np.ndarray
    offsets: np.ndarray
    values: list[float] | None = None

    @property
    def n_levels(self) -> int:
        """Number of levels."""
        return len(self.offsets)

    @property
    def half_width(self) -> float:
        """Half the span of the levels along the direction."""
        return 0.5 * float(self.offsets[-1] - self.offsets[0])

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy."""
        return {
            "name": self.name,
            "direction": [float(v) for v in self.direction],
            "offsets": [float(v) for v in self.offsets],
            "values": self.values,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Factor:
        """Re-create a factor written by :meth:`to_dict`."""
        return cls(
            name=str(d["name"]),
            direction=np.asarray(d["direction"], dtype=float),
            offsets=np.asarray(d["offsets"], dtype=float),
            values=None if d.get("values") is None else [float(v) for v in d["values"]],
        )


@dataclass
class Frame:
    """The factors of one iteration, around a centre in search coordinates."""

    centre: np.ndarray
    factors: list[Factor]
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    anchor: dict[str, float] | None = None

    def coords(self, space: Space) -> Space:
        """Return the coordinates the centre and directions are in.

        The stage's search space, or linear coordinates anchored at ``anchor`` (rotated
        factors).
        """
        return space if self.anchor is None else space.anchored(self.anchor)

    @property
    def axis_aligned(self) -> bool:
        """True if every factor is a parameter with exact level values."""
        return all(f.values is not None for f in self.factors)

    @property
    def names(self) -> list[str]:
        """Factor names, in order."""
        return [f.name for f in self.factors]

    @classmethod
    def from_levels(
        cls, space: Space, levels: Mapping[str, Sequence[float]], note: str = ""
    ) -> Frame:
        """Make an axis-aligned frame with exact levels per parameter (centred mid-range)."""
        factors, centre = [], np.zeros(space.dim)
        for j, name in enumerate(space.names):
            values = sorted(float(v) for v in levels[name])
            s = np.array([space.coordinate(j, v) for v in values])
            centre[j] = 0.5 * (s[0] + s[-1])
            direction = np.zeros(space.dim)
            direction[j] = 1.0
            factors.append(Factor(name, direction, s - centre[j], values))
        return cls(centre=centre, factors=factors, note=note)

    def level_values(self, space: Space) -> dict[str, list[float]]:
        """Levels by factor: parameter values for parameters, offsets for rotated ones."""
        return {
            f.name: list(f.values) if f.values is not None else [float(o) for o in f.offsets]
            for f in self.factors
        }

    def point(self, z: np.ndarray) -> np.ndarray:
        """Search coordinates of the point with offset ``z[k]`` along each factor."""
        return self.centre + sum(
            (z[k] * f.direction for k, f in enumerate(self.factors)), np.zeros_like(self.centre)
        )

    def parameter_sets(self, space: Space, level_index: np.ndarray) -> list[dict[str, float]]:
        """Parameter set of each array run (0-based levels, one column per factor)."""
        sets = []
        for row in np.asarray(level_index, dtype=int):
            if self.axis_aligned:
                sets.append({f.name: float(f.values[row[k]]) for k, f in enumerate(self.factors)})  # type: ignore[index]
            else:
                z = np.array([f.offsets[row[k]] for k, f in enumerate(self.factors)])
                sets.append(self.coords(space).to_x(self.point(z)))
        return sets

    def at_offsets(self, space: Space, z: np.ndarray) -> dict[str, float]:
        """Return the parameter set at offsets ``z`` along the factors.

        For parameters the values are interpolated in the working domain between the
        exact levels.
        """
        return self.coords(space).to_x(self.point(z))

    def coordinates(self, s: np.ndarray) -> np.ndarray:
        """Offsets along each factor of the point ``s`` (least squares if not square)."""
        d = np.column_stack([f.direction for f in self.factors])
        return np.linalg.lstsq(d, np.asarray(s) - self.centre, rcond=None)[0]

    def spans(self, space: Space) -> dict[str, float]:
        """Largest relative change of any parameter across each factor's levels."""
        out = {}
        space = self.coords(space)
        base = space.to_x(self.centre)
        for f in self.factors:
            lo = space.to_x(self.centre + f.offsets[0] * f.direction)
            hi = space.to_x(self.centre + f.offsets[-1] * f.direction)
            out[f.name] = max(abs(hi[n] - lo[n]) / max(abs(base[n]), 1e-300) for n in space.names)
        return out

    def describe(self, space: Space, factor: Factor) -> str:
        """Say which parameters a factor moves: ``+0.71 lg F_vm -0.70 lg B_s``.

        In the stage's working domain (``space``), also for anchored frames: their unit
        steps mean there what they mean in ``space`` (relative changes for log
        parameters), whereas their own parameter units would let the parameter with the
        largest value swamp every direction.
        """
        if factor.values is not None:
            return factor.name
        u = space.u_direction(factor.direction)
        terms = [(abs(c), c, space.label(j)) for j, c in enumerate(u) if abs(c) >= 0.05]
        terms.sort(reverse=True)
        return " ".join(f"{c:+.2f} {label}" for _, c, label in terms)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy."""
        return {
            "centre": [float(v) for v in self.centre],
            "factors": [f.to_dict() for f in self.factors],
            "note": self.note,
            "extra": self.extra,
            "anchor": self.anchor,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Frame:
        """Re-create a frame written by :meth:`to_dict`."""
        return cls(
            centre=np.asarray(d["centre"], dtype=float),
            factors=[Factor.from_dict(f) for f in d["factors"]],
            note=str(d.get("note", "")),
            extra=dict(d.get("extra", {})),
            anchor=None
            if d.get("anchor") is None
            else {k: float(v) for k, v in d["anchor"].items()},
        )
