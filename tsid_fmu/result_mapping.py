"""The result as a mapping, in the manner of :class:`scipy.optimize.OptimizeResult`.

SciPy's ``OptimizeResult`` is a ``dict`` with attribute access: ``res.x`` and
``res["x"]`` are one value, and ``res.keys()`` lists them. :class:`ResultMapping` is that
base for :class:`~tsid_fmu.result.IdentificationResult`, a dataclass whose fields are the
items: ``x``, derived from ``params``, is read through its property, and listed first.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any, TypeVar

import numpy as np
from scipy.optimize import OptimizeResult

__all__ = ["COMPUTED", "ResultMapping", "unshadowed"]

COMPUTED = ("x",)
"""Keys of the mapping that are properties (derived from ``params``), not stored."""

T = TypeVar("T")


class ResultMapping(OptimizeResult):
    """An :class:`OptimizeResult` whose keys are a dataclass's fields and ``x``."""

    def __getitem__(self, key: str) -> Any:
        if key in COMPUTED:
            return getattr(self, key)
        return dict.__getitem__(self, key)

    def __contains__(self, key: object) -> bool:
        return key in COMPUTED or dict.__contains__(self, key)

    def __iter__(self) -> Any:
        return iter(self.keys())

    def __len__(self) -> int:
        return len(self.keys())

    def keys(self) -> list[str]:  # type: ignore[override]
        """Return the keys: ``x`` and every field, as :class:`OptimizeResult`'s."""
        return [*COMPUTED, *dict.keys(self)]

    def items(self) -> list[tuple[str, Any]]:  # type: ignore[override]
        """Return ``(key, value)`` for every key of :meth:`keys`."""
        return [(k, self[k]) for k in self.keys()]

    def values(self) -> list[Any]:  # type: ignore[override]
        """Return the value of every key of :meth:`keys`."""
        return [self[k] for k in self.keys()]

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(
            _same(getattr(self, f.name), getattr(other, f.name))
            for f in fields(self)  # type: ignore[arg-type]
            if f.compare
        )

    __hash__ = None  # type: ignore[assignment]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(a, b, equal_nan=True))
    return bool(a == b)


def unshadowed(cls: type[T]) -> type[T]:
    """Return the dataclass ``cls`` without its fields' defaults as class attributes.

    A dataclass keeps each default as a class attribute, which would shadow the mapping
    :class:`OptimizeResult` reads attributes from (``res.nit`` would always be 0): the
    defaults live in ``__init__`` alone.
    """
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name in cls.__dict__:
            delattr(cls, f.name)
    return cls
