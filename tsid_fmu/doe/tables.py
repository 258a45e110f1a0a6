"""How the standard orthogonal arrays are constructed (see :mod:`tsid_fmu.doe.arrays`).

Pure arrays come from the Rao-Hamming construction over GF(q); L12 and L18 are Taguchi's
published tables, kept as text in ``published/``; L36 and L50 are expanded from
difference schemes. Each builder returns a 0-based ``(runs, columns)`` integer table.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from importlib import resources

import numpy as np

from tsid_fmu.errors import ArrayError

__all__ = ["BUILDERS", "COMPOSITION"]


# --------------------------------------------------------------------------- fields


@cache
def _gf_tables(q: int) -> tuple[np.ndarray, np.ndarray]:
    """Addition and multiplication tables of GF(q) for q in {2, 3, 4, 5}."""
    if q in (2, 3, 5):
        e = np.arange(q)
        return (e[:, None] + e[None, :]) % q, (e[:, None] * e[None, :]) % q
    if q == 4:
        # Elements are polynomials b1*x + b0 encoded as 2*b1 + b0, modulo x^2 + x + 1.
        e = np.arange(4)
        add = e[:, None] ^ e[None, :]
        mul = np.zeros((4, 4), dtype=np.int64)
        for a in range(4):
            for b in range(4):
                prod = 0
                for bit in range(2):
                    if (b >> bit) & 1:
                        prod ^= a << bit
                if prod & 0b100:
                    prod ^= 0b111
                mul[a, b] = prod
        return add, mul
    raise ArrayError(f"GF({q}) is not supported")


def _rao_hamming(q: int, k: int) -> np.ndarray:
    """Saturated array of strength 2 with q**k runs and (q**k - 1)/(q - 1) columns."""
    add, mul = _gf_tables(q)
    runs = np.arange(q**k)
    digits = [(runs // q ** (k - 1 - f)) % q for f in range(k)]  # A most significant
    columns = []
    for lead in range(k):
        for number in range(q**lead):
            value = digits[lead]
            for f in range(lead):
                coef = (number // q**f) % q
                if coef:
                    value = add[value, mul[coef, digits[f]]]
            columns.append(value)
    return np.column_stack(columns)


def _from_difference_scheme(row_part: np.ndarray, scheme: np.ndarray, s: int) -> np.ndarray:
    """Expand each row ``r`` into ``s`` runs: ``row_part[r]`` and ``(scheme[r] + j) % s``."""
    n_rows = scheme.shape[0]
    shift = np.tile(np.arange(s), n_rows)[:, None]
    left = np.repeat(row_part, s, axis=0)
    right = (np.repeat(scheme, s, axis=0) + shift) % s
    return np.hstack([left, right])


# --------------------------------------------------------------- published tables

# Coefficients of the quadratic D(10, 10, 5) used by L50: entry [h][g].
_D10_A = ((0, 1), (0, 2))
_D10_B = ((1, 1), (1, 2))
_D10_C = ((0, 0), (2, 4))


def _published(name: str) -> np.ndarray:
    """Read the table ``published/<name>.txt`` (``#`` lines are comments)."""
    text = (
        resources.files(__package__)
        .joinpath("published", f"{name}.txt")
        .read_text(encoding="utf-8")
    )
    rows = [line.split() for line in text.splitlines() if line.strip() and line[0] != "#"]
    return np.array(rows, dtype=int)


def _l12() -> np.ndarray:
    return _published("L12") - 1


def _l18() -> np.ndarray:
    return _published("L18") - 1


def _l36() -> np.ndarray:
    return _from_difference_scheme(_l12(), _published("D12_3"), 3)


def _l50() -> np.ndarray:
    q = 5
    h, i = np.divmod(np.arange(2 * q), q)
    g, k = np.divmod(np.arange(2 * q), q)
    a = np.asarray(_D10_A)[h[:, None], g[None, :]]
    b = np.asarray(_D10_B)[h[:, None], g[None, :]]
    c = np.asarray(_D10_C)[h[:, None], g[None, :]]
    scheme = (a * i[:, None] ** 2 + b * i[:, None] * k[None, :] + c * k[None, :] ** 2) % q
    return _from_difference_scheme(np.column_stack([h, i]), scheme, q)


# Canonical name -> builder, in order of runs (ties: published 2-level array first).
BUILDERS: dict[str, Callable[[], np.ndarray]] = {
    "L4": lambda: _rao_hamming(2, 2),
    "L8": lambda: _rao_hamming(2, 3),
    "L9": lambda: _rao_hamming(3, 2),
    "L12": _l12,
    "L16": lambda: _rao_hamming(2, 4),
    "L16(4^5)": lambda: _rao_hamming(4, 2),
    "L18": _l18,
    "L25": lambda: _rao_hamming(5, 2),
    "L27": lambda: _rao_hamming(3, 3),
    "L32": lambda: _rao_hamming(2, 5),
    "L36": _l36,
    "L50": _l50,
    "L64": lambda: _rao_hamming(2, 6),
    "L64(4^21)": lambda: _rao_hamming(4, 3),
    "L81": lambda: _rao_hamming(3, 4),
}

# Level composition of every array (levels -> number of columns), without building it.
COMPOSITION: dict[str, dict[int, int]] = {
    "L4": {2: 3},
    "L8": {2: 7},
    "L9": {3: 4},
    "L12": {2: 11},
    "L16": {2: 15},
    "L16(4^5)": {4: 5},
    "L18": {2: 1, 3: 7},
    "L25": {5: 6},
    "L27": {3: 13},
    "L32": {2: 31},
    "L36": {2: 11, 3: 12},
    "L50": {2: 1, 5: 11},
    "L64": {2: 63},
    "L64(4^21)": {4: 21},
    "L81": {3: 40},
}
