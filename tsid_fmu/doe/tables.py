"""How the standard orthogonal arrays are constructed (see :mod:`tsid_fmu.doe.arrays`).

Pure arrays come from the Rao-Hamming construction over GF(q); L12 and L18 are literal
copies of Taguchi's tables; L36 and L50 are expanded from difference schemes. Each
builder returns a 0-based ``(runs, columns)`` integer table.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

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


# ----------------------------------------------------------------- literal tables

# Taguchi's L12 (Plackett–Burman, 2^11), 1-based as published.
_L12 = """
1 1 1 1 1 1 1 1 1 1 1
1 1 1 1 1 2 2 2 2 2 2
1 1 2 2 2 1 1 1 2 2 2
1 2 1 2 2 1 2 2 1 1 2
1 2 2 1 2 2 1 2 1 2 1
1 2 2 2 1 2 2 1 2 1 1
2 1 2 2 1 1 2 2 1 2 1
2 1 2 1 2 2 2 1 1 1 2
2 1 1 2 2 2 1 2 2 1 1
2 2 2 1 1 1 1 2 2 1 2
2 2 1 2 1 2 1 1 1 2 2
2 2 1 1 2 1 2 1 2 2 1
"""

# Taguchi's L18 (2^1 3^7), 1-based as published.
_L18 = """
1 1 1 1 1 1 1 1
1 1 2 2 2 2 2 2
1 1 3 3 3 3 3 3
1 2 1 1 2 2 3 3
1 2 2 2 3 3 1 1
1 2 3 3 1 1 2 2
1 3 1 2 1 3 2 3
1 3 2 3 2 1 3 1
1 3 3 1 3 2 1 2
2 1 1 3 3 2 2 1
2 1 2 1 1 3 3 2
2 1 3 2 2 1 1 3
2 2 1 2 3 1 3 2
2 2 2 3 1 2 1 3
2 2 3 1 2 3 2 1
2 3 1 3 2 3 1 2
2 3 2 1 3 1 2 3
2 3 3 2 1 2 3 1
"""

# A 12 x 12 difference scheme D(12, 12, 3) over GF(3), 0-based (used by L36).
_D12_3 = """
0 0 0 0 0 0 0 0 0 0 0 0
0 0 0 0 1 1 1 1 2 2 2 2
0 0 0 1 0 2 2 2 1 1 1 2
0 0 1 2 2 0 1 2 0 1 2 1
0 1 0 2 2 1 2 0 2 0 1 1
0 1 2 0 1 2 0 2 0 2 1 1
0 1 2 1 2 0 0 1 2 1 0 2
0 1 2 2 0 2 1 1 1 0 2 0
0 2 1 0 2 0 2 1 1 2 1 0
0 2 1 1 0 2 1 0 2 2 0 1
0 2 1 2 1 1 0 2 1 0 0 2
0 2 2 1 1 1 2 0 0 1 2 0
"""

# Coefficients of the quadratic D(10, 10, 5) used by L50: entry [h][g].
_D10_A = ((0, 1), (0, 2))
_D10_B = ((1, 1), (1, 2))
_D10_C = ((0, 0), (2, 4))


def _parse(text: str) -> np.ndarray:
    return np.array([[int(v) for v in line.split()] for line in text.strip().splitlines()])


def _l12() -> np.ndarray:
    return _parse(_L12) - 1


def _l18() -> np.ndarray:
    return _parse(_L18) - 1


def _l36() -> np.ndarray:
    return _from_difference_scheme(_l12(), _parse(_D12_3), 3)


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
