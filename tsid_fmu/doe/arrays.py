"""Standard Taguchi orthogonal arrays.

The arrays are the ones of Taguchi's published tables, with their columns in the
published order, so that "column 4 of L9" means what a reader of a Taguchi text
expects. Levels are stored 0-based (``0 .. k-1``); :meth:`OrthogonalArray.to_pandas`
shows them 1-based, as printed in the tables.

========================  ======  =========================================================
Name                      Runs    Construction
========================  ======  =========================================================
``L4``   (2^3)            4       GF(2), Rao–Hamming
``L8``   (2^7)            8       GF(2), Rao–Hamming
``L9``   (3^4)            9       GF(3), Rao–Hamming
``L12``  (2^11)           12      Plackett–Burman, literal table (Taguchi's row order)
``L16``  (2^15)           16      GF(2), Rao–Hamming
``L16(4^5)``              16      GF(4), Rao–Hamming (GF(4) arithmetic, not mod 4)
``L18``  (2^1 3^7)        18      literal table (Taguchi's L18)
``L25``  (5^6)            25      GF(5), Rao–Hamming
``L27``  (3^13)           27      GF(3), Rao–Hamming
``L32``  (2^31)           32      GF(2), Rao–Hamming
``L36``  (2^11 3^12)      36      L12 × difference scheme D(12,12,3), see below
``L50``  (2^1 5^11)       50      difference scheme D(10,10,5), see below
``L64``  (2^63)           64      GF(2), Rao–Hamming
``L64(4^21)``             64      GF(4), Rao–Hamming
``L81``  (3^40)           81      GF(3), Rao–Hamming
========================  ======  =========================================================

Pure arrays (Rao–Hamming / Bose). With ``k`` basic factors ``A, B, C, ...`` over
GF(q), run ``r`` (0-based) has the base-q digits of ``r`` as the levels of the basic
factors, ``A`` the most significant. The columns are all linear forms whose last
non-zero coefficient is 1, ordered first by the position of that coefficient and then
by the earlier coefficients read as a base-q number with ``A`` the least significant
digit. This reproduces Taguchi's tables: L8 = ``A, B, A+B, C, A+C, B+C, A+B+C``;
L9 = ``A, B, A+B, 2A+B``; L25 = ``A, B, A+B, 2A+B, 3A+B, 4A+B``; L27 columns 1-13 =
``A, B, A+B, 2A+B, C, A+C, 2A+C, B+C, A+B+C, 2A+B+C, 2B+C, A+2B+C, 2A+2B+C``; and
L16(4^5) = ``A, B, A+B, 2A+B, 3A+B`` over GF(4) with ``2 = x``, ``3 = x + 1``. The
tests compare L4, L8, L9, L16(4^5), L25 and L27 cell by cell with the published
tables; L32, L64, L64(4^21) and L81 follow the same rule.

Mixed arrays. ``L12`` and ``L18`` are literal copies of Taguchi's tables. ``L36`` and
``L50`` are *constructed* (no public-domain copy of the published tables was at hand),
with the same structure as Taguchi's: run ``s*r + j`` (``j = 0 .. s-1``) takes row
``r`` of a "row part" in its leading columns and ``(D[r, c] + j) mod s`` in the others,
where ``D`` is a difference scheme (every column difference contains each level
equally often):

* ``L36``: row part = the 12 rows of L12 (columns 1-11), ``D`` = a 12 × 12 difference
  scheme over GF(3) (columns 12-23), found by a lexicographic search and stored below.
  Runs 1-6 agree with the published table; later 3-level cells may be a relabelled or
  permuted version of it.
* ``L50``: row part = ``(h, i)`` for ``h`` in 0..1 (column 1, 2 levels) and ``i`` in
  GF(5) (column 2); ``D[(h, i), (g, k)] = a_hg i^2 + b_hg i k + c_hg k^2`` over GF(5)
  (columns 3-12), an Addelman–Kempthorne-type quadratic scheme. Its first 25 runs,
  columns 2-7, are exactly L25.

Whatever the source, every table is checked for balance and pairwise orthogonality by
the test suite (:func:`check_orthogonal`).
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from tsid_fmu.doe.tables import BUILDERS, COMPOSITION
from tsid_fmu.errors import ArrayError

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "OrthogonalArray",
    "available_arrays",
    "check_orthogonal",
    "get_array",
    "select_array",
]


@dataclass(frozen=True, eq=False)
class OrthogonalArray:
    """An orthogonal array: a named table of 0-based factor levels.

    Parameters
    ----------
    name : str
        Canonical name, e.g. ``"L25"`` or ``"L16(4^5)"``.
    table : numpy.ndarray
        Integer array of shape ``(runs, columns)`` holding 0-based levels; column ``j``
        uses the levels ``0 .. levels[j] - 1``. It is stored as a read-only copy.

    Notes
    -----
    Instances compare equal when name and table are equal. The arrays returned by
    :func:`get_array` are shared (cached), which is why their table is read-only.
    """

    name: str
    table: np.ndarray

    def __post_init__(self) -> None:
        table = np.array(self.table, copy=True)
        if table.ndim != 2 or table.size == 0:
            raise ArrayError(f"{self.name}: table must be a non-empty 2-D array")
        if not np.issubdtype(table.dtype, np.integer):
            raise ArrayError(f"{self.name}: table must hold integer levels")
        if table.min() < 0:
            raise ArrayError(f"{self.name}: levels must be 0-based (found a negative level)")
        dtype = np.int8 if table.max() < 127 else np.int16
        table = table.astype(dtype)
        table.setflags(write=False)
        object.__setattr__(self, "table", table)

    @property
    def n_runs(self) -> int:
        """Number of runs (rows)."""
        return int(self.table.shape[0])

    @property
    def n_columns(self) -> int:
        """Number of columns."""
        return int(self.table.shape[1])

    @property
    def levels(self) -> tuple[int, ...]:
        """Number of levels of each column (``max level + 1``)."""
        return tuple(int(m) + 1 for m in self.table.max(axis=0))

    @property
    def designation(self) -> str:
        """Taguchi's designation, e.g. ``"L18(2^1 3^7)"``."""
        counts = Counter(self.levels)
        spec = " ".join(f"{k}^{counts[k]}" for k in sorted(counts))
        return f"L{self.n_runs}({spec})"

    def to_pandas(self, one_based: bool = True) -> pd.DataFrame:
        """Return the table as a DataFrame.

        Parameters
        ----------
        one_based : bool, optional
            Show levels as ``1 .. k`` (as printed in Taguchi's tables) instead of
            ``0 .. k-1``. Default True.

        Returns
        -------
        pandas.DataFrame
            Index ``run`` (1-based), columns ``1 .. n_columns`` (the published column
            numbers).
        """
        import pandas as pd

        data = self.table.astype(np.int64) + (1 if one_based else 0)
        index = pd.RangeIndex(1, self.n_runs + 1, name="run")
        columns = pd.RangeIndex(1, self.n_columns + 1, name="column")
        return pd.DataFrame(data, index=index, columns=columns)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, OrthogonalArray):
            return NotImplemented
        return self.name == other.name and np.array_equal(self.table, other.table)

    def __hash__(self) -> int:
        return hash((self.name, self.table.shape, self.table.tobytes()))

    def __repr__(self) -> str:
        return (
            f"OrthogonalArray(name={self.name!r}, runs={self.n_runs}, "
            f"columns={self.n_columns}, designation={self.designation!r})"
        )


def available_arrays() -> list[str]:
    """Return the canonical names of the available arrays, fewest runs first.

    Returns
    -------
    list of str
        ``["L4", "L8", "L9", "L12", "L16", "L16(4^5)", "L18", "L25", "L27", "L32",
        "L36", "L50", "L64", "L64(4^21)", "L81"]``.
    """
    return list(BUILDERS)


@cache
def _build(name: str) -> OrthogonalArray:
    return OrthogonalArray(name, BUILDERS[name]())


def _runs_of(name: str) -> int:
    return int(re.match(r"L(\d+)", name).group(1))  # type: ignore[union-attr]


_NAME_RE = re.compile(r"L\s*(\d+)\s*(B?)\s*(?:\(\s*([^()]*?)\s*\)|([^()]*?))\s*")


def _resolve(name: str) -> str:
    """Map a user-supplied array name to its canonical name."""
    if not isinstance(name, str):
        raise ArrayError(f"array name must be a string, got {type(name).__name__}")
    text = name.strip().upper().replace("**", "^")
    for sep in ("×", "*", "_", ",", "·"):
        text = text.replace(sep, " ")
    text = re.sub(r"(?<=\d)\s*X\s*(?=\d)", " ", text)
    match = _NAME_RE.fullmatch(text)
    candidates: list[str] = []
    if match:
        runs, alt = int(match.group(1)), match.group(2)
        spec = match.group(3) if match.group(3) is not None else match.group(4)
        same_runs = [n for n in BUILDERS if _runs_of(n) == runs]
        terms = re.findall(r"(\d+)\s*\^\s*(\d+)", spec)
        leftover = re.sub(r"(\d+)\s*\^\s*(\d+)", "", spec).strip()
        if leftover or (alt and spec):
            same_runs = []
        if alt:
            candidates = same_runs[1:2]
        elif terms:
            wanted: Counter[int] = Counter()
            for lev, cnt in terms:
                wanted[int(lev)] += int(cnt)
            candidates = [n for n in same_runs if COMPOSITION[n] == dict(wanted)]
        else:
            candidates = same_runs[:1]
    if not candidates:
        raise ArrayError(
            f"unknown orthogonal array {name!r}; available: {', '.join(available_arrays())}"
        )
    return candidates[0]


def get_array(name: str) -> OrthogonalArray:
    """Return a standard orthogonal array by name.

    Parameters
    ----------
    name : str
        Case-insensitive name. Accepted forms: the bare run count (``"L9"``,
        ``"l25"``); the full designation in any factor order, with ``^`` or ``**``
        and spaces, ``x``, ``×`` or ``_`` as separators (``"L18(2^1 3^7)"``,
        ``"L16(4^5)"``, ``"L16_4^5"``, ``"L36(3^12 2^11)"``); and a ``B`` suffix for
        the second array of a run size (``"L16B"`` = L16(4^5), ``"L64B"`` =
        L64(4^21)). A bare ``"L16"`` means L16(2^15) and ``"L64"`` means L64(2^63).

    Returns
    -------
    OrthogonalArray
        The shared, cached array (its table is read-only).

    Raises
    ------
    ArrayError
        If the name matches no available array; the message lists the available
        names.
    """
    return _build(_resolve(name))


def _level_word(k: int) -> str:
    words = {2: "two", 3: "three", 4: "four", 5: "five", 6: "six", 7: "seven"}
    return f"{words.get(k, str(k))}-level"


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _fit_message(array: OrthogonalArray, needed: Counter[int]) -> str | None:
    """Why ``array`` cannot host factors with the given level counts, or None."""
    have = Counter(array.levels)
    for k in sorted(needed):
        if needed[k] > have.get(k, 0):
            return (
                f"{array.name} has {_plural(have.get(k, 0), _level_word(k) + ' column')}; "
                f"the study has {_plural(needed[k], 'factor')} with {k} levels"
            )
    return None


def _greedy_columns(array: OrthogonalArray, levels: Sequence[int]) -> list[int]:
    used: set[int] = set()
    chosen = []
    array_levels = array.levels
    for k in levels:
        col = next(j for j, lj in enumerate(array_levels) if lj == k and j not in used)
        used.add(col)
        chosen.append(col)
    return chosen


def select_array(
    levels: Sequence[int],
    name: str | None = None,
    columns: Sequence[int] | None = None,
) -> tuple[OrthogonalArray, list[int]]:
    """Choose an orthogonal array and a column for each factor.

    Parameters
    ----------
    levels : sequence of int
        Number of levels of each factor, e.g. ``[5, 5, 5, 5, 5]``. Each must be >= 2.
    name : str, optional
        Use this array (any name :func:`get_array` accepts) instead of the smallest one
        that fits.
    columns : sequence of int, optional
        Explicit 0-based column of each factor. They must be distinct, exist in the
        array and have exactly the factor's number of levels. Without it, each factor
        takes the first unused column with its number of levels, in published order.

    Returns
    -------
    array : OrthogonalArray
        Without ``name``: the array with the fewest runs that has a column of the
        right number of levels for every factor (at equal runs, the one listed first by
        :func:`available_arrays`). Columns left over are allowed.
    columns : list of int
        The 0-based column assigned to each factor, in the order of ``levels``.

    Raises
    ------
    ArrayError
        If the levels are invalid, no array (or not the named one) can host the
        factors, or ``columns`` is invalid; the message says why.
    """
    levels = list(levels)
    if not levels:
        raise ArrayError("no factors given: levels is empty")
    for i, k in enumerate(levels):
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 2:
            raise ArrayError(f"factor {i} has {k!r} levels; every factor needs an integer >= 2")
    levels = [int(k) for k in levels]
    needed = Counter(levels)

    if name is not None:
        array = get_array(name)
        if columns is None:
            reason = _fit_message(array, needed)
            if reason is not None:
                raise ArrayError(reason)
    elif columns is not None:
        raise ArrayError("columns given without an array name: pass name= as well")
    else:
        array = None
        for candidate in BUILDERS:
            have = COMPOSITION[candidate]
            if all(needed[k] <= have.get(k, 0) for k in needed):
                array = _build(candidate)
                break
        if array is None:
            spec = ", ".join(f"{needed[k]} with {k} levels" for k in sorted(needed))
            raise ArrayError(
                f"no standard orthogonal array can host the factors ({spec}); "
                f"available: {', '.join(available_arrays())}"
            )

    if columns is None:
        return array, _greedy_columns(array, levels)
    return array, _check_columns(array, levels, columns)


def _check_columns(
    array: OrthogonalArray, levels: Sequence[int], columns: Sequence[int]
) -> list[int]:
    cols = list(columns)
    if len(cols) != len(levels):
        raise ArrayError(f"{len(cols)} columns given for {_plural(len(levels), 'factor')}")
    seen: dict[int, int] = {}
    result = []
    for i, (col, k) in enumerate(zip(cols, levels, strict=True)):
        if isinstance(col, bool) or not isinstance(col, int | np.integer):
            raise ArrayError(f"column of factor {i} must be an integer, got {col!r}")
        col = int(col)
        if not 0 <= col < array.n_columns:
            raise ArrayError(
                f"column {col} of factor {i} does not exist: {array.name} has columns "
                f"0..{array.n_columns - 1} (0-based)"
            )
        if col in seen:
            raise ArrayError(f"factors {seen[col]} and {i} are both assigned to column {col}")
        if array.levels[col] != k:
            raise ArrayError(
                f"factor {i} has {k} levels but column {col} of {array.name} has "
                f"{array.levels[col]}"
            )
        seen[col] = i
        result.append(col)
    return result


def check_orthogonal(array: OrthogonalArray | np.ndarray) -> None:
    """Check that an array is balanced and pairwise orthogonal (strength 2).

    Balanced: in every column each level ``0 .. k-1`` appears equally often.
    Orthogonal: in every pair of columns each combination of levels appears equally
    often.

    Parameters
    ----------
    array : OrthogonalArray or numpy.ndarray
        The array, or a ``(runs, columns)`` table of 0-based levels.

    Raises
    ------
    ArrayError
        Naming the first column (1-based, as published) or column pair and the level
        or level combination that breaks balance or orthogonality.
    """
    if isinstance(array, OrthogonalArray):
        label, table = array.name, np.asarray(array.table, dtype=np.int64)
    else:
        label, table = "array", np.asarray(array)
        if table.ndim != 2 or table.size == 0 or not np.issubdtype(table.dtype, np.integer):
            raise ArrayError("array must be a non-empty 2-D table of integer levels")
        table = table.astype(np.int64)
        if table.min() < 0:
            raise ArrayError(f"{label} has negative levels; levels must be 0-based")
    n_runs, n_cols = table.shape
    levels = table.max(axis=0) + 1
    for j in range(n_cols):
        k = int(levels[j])
        counts = np.bincount(table[:, j], minlength=k)
        if n_runs % k or (counts != n_runs // k).any():
            bad = int(np.argmax(counts != n_runs // k)) if n_runs % k == 0 else int(counts.argmin())
            raise ArrayError(
                f"{label} column {j + 1} is not balanced: level {bad + 1} appears "
                f"{counts[bad]} times in {n_runs} runs with {k} levels"
            )
    for a in range(n_cols):
        ka = int(levels[a])
        for b in range(a + 1, n_cols):
            kb = int(levels[b])
            counts = np.bincount(table[:, a] * kb + table[:, b], minlength=ka * kb)
            expected = n_runs // (ka * kb)
            if n_runs % (ka * kb) or (counts != expected).any():
                bad = int(np.argmax(counts != expected))
                raise ArrayError(
                    f"{label} columns {a + 1} and {b + 1} are not orthogonal: level pair "
                    f"({bad // kb + 1}, {bad % kb + 1}) appears {counts[bad]} times, "
                    f"expected {n_runs / (ka * kb):g}"
                )
