from __future__ import annotations

import numpy as np
import pytest

from tsid_fmu.doe.arrays import (
    OrthogonalArray,
    available_arrays,
    check_orthogonal,
    get_array,
    select_array,
)
from tsid_fmu.errors import ArrayError


def table(text: str) -> np.ndarray:
    """Parse a published (1-based) table into 0-based levels."""
    return np.array([[int(v) for v in row.split()] for row in text.strip().splitlines()]) - 1


# Published tables (Taguchi; also in Roy, "A Primer on the Taguchi Method").
L4 = table("""
1 1 1
1 2 2
2 1 2
2 2 1
""")
L8 = table("""
1 1 1 1 1 1 1
1 1 1 2 2 2 2
1 2 2 1 1 2 2
1 2 2 2 2 1 1
2 1 2 1 2 1 2
2 1 2 2 1 2 1
2 2 1 1 2 2 1
2 2 1 2 1 1 2
""")
L9 = table("""
1 1 1 1
1 2 2 2
1 3 3 3
2 1 2 3
2 2 3 1
2 3 1 2
3 1 3 2
3 2 1 3
3 3 2 1
""")
L16_4 = table("""
1 1 1 1 1
1 2 2 2 2
1 3 3 3 3
1 4 4 4 4
2 1 2 3 4
2 2 1 4 3
2 3 4 1 2
2 4 3 2 1
3 1 3 4 2
3 2 4 3 1
3 3 1 2 4
3 4 2 1 3
4 1 4 2 3
4 2 3 1 4
4 3 2 4 1
4 4 1 3 2
""")
L27 = table("""
1 1 1 1 1 1 1 1 1 1 1 1 1
1 1 1 1 2 2 2 2 2 2 2 2 2
1 1 1 1 3 3 3 3 3 3 3 3 3
1 2 2 2 1 1 1 2 2 2 3 3 3
1 2 2 2 2 2 2 3 3 3 1 1 1
1 2 2 2 3 3 3 1 1 1 2 2 2
1 3 3 3 1 1 1 3 3 3 2 2 2
1 3 3 3 2 2 2 1 1 1 3 3 3
1 3 3 3 3 3 3 2 2 2 1 1 1
2 1 2 3 1 2 3 1 2 3 1 2 3
2 1 2 3 2 3 1 2 3 1 2 3 1
2 1 2 3 3 1 2 3 1 2 3 1 2
2 2 3 1 1 2 3 2 3 1 3 1 2
2 2 3 1 2 3 1 3 1 2 1 2 3
2 2 3 1 3 1 2 1 2 3 2 3 1
2 3 1 2 1 2 3 3 1 2 2 3 1
2 3 1 2 2 3 1 1 2 3 3 1 2
2 3 1 2 3 1 2 2 3 1 1 2 3
3 1 3 2 1 3 2 1 3 2 1 3 2
3 1 3 2 2 1 3 2 1 3 2 1 3
3 1 3 2 3 2 1 3 2 1 3 2 1
3 2 1 3 1 3 2 2 1 3 3 2 1
3 2 1 3 2 1 3 3 2 1 1 3 2
3 2 1 3 3 2 1 1 3 2 2 1 3
3 3 2 1 1 3 2 3 2 1 2 1 3
3 3 2 1 2 1 3 1 3 2 3 2 1
3 3 2 1 3 2 1 2 1 3 1 3 2
""")

EXPECTED_SHAPE = {
    "L4": (4, (2,) * 3),
    "L8": (8, (2,) * 7),
    "L9": (9, (3,) * 4),
    "L12": (12, (2,) * 11),
    "L16": (16, (2,) * 15),
    "L16(4^5)": (16, (4,) * 5),
    "L18": (18, (2,) + (3,) * 7),
    "L25": (25, (5,) * 6),
    "L27": (27, (3,) * 13),
    "L32": (32, (2,) * 31),
    "L36": (36, (2,) * 11 + (3,) * 12),
    "L50": (50, (2,) + (5,) * 11),
    "L64": (64, (2,) * 63),
    "L64(4^21)": (64, (4,) * 21),
    "L81": (81, (3,) * 40),
}


def test_available_arrays_order():
    assert available_arrays() == list(EXPECTED_SHAPE)


@pytest.mark.parametrize("name", list(EXPECTED_SHAPE))
def test_every_array_is_balanced_and_pairwise_orthogonal(name):
    array = get_array(name)
    runs, levels = EXPECTED_SHAPE[name]
    assert array.name == name
    assert array.n_runs == runs
    assert array.levels == levels
    assert array.n_columns == len(levels)
    assert array.table.dtype == np.int8
    check_orthogonal(array)  # raises on failure
    # Independent check: every pair of columns holds each level pair equally often.
    t = array.table.astype(int)
    for a in range(t.shape[1]):
        for b in range(a + 1, t.shape[1]):
            pairs, counts = np.unique(t[:, a] * 10 + t[:, b], return_counts=True)
            assert len(pairs) == levels[a] * levels[b]
            assert (counts == runs // (levels[a] * levels[b])).all(), (name, a, b)
    # Row 1 is all first levels, as in every published table.
    assert (t[0] == 0).all()
    # No two runs are identical.
    assert len({tuple(row) for row in t}) == runs


@pytest.mark.parametrize(
    ("name", "expected"),
    [("L4", L4), ("L8", L8), ("L9", L9), ("L16(4^5)", L16_4), ("L27", L27)],
)
def test_published_tables_cell_by_cell(name, expected):
    np.testing.assert_array_equal(get_array(name).table, expected)


def test_l25_matches_published_first_rows():
    t = get_array("L25").table + 1
    np.testing.assert_array_equal(
        t[:6],
        table_1based(
            [
                "1 1 1 1 1 1",
                "1 2 2 2 2 2",
                "1 3 3 3 3 3",
                "1 4 4 4 4 4",
                "1 5 5 5 5 5",
                "2 1 2 3 4 5",
            ]
        ),
    )
    np.testing.assert_array_equal(t[24], [5, 5, 4, 3, 2, 1])


def table_1based(rows: list[str]) -> np.ndarray:
    return np.array([[int(v) for v in r.split()] for r in rows])


def test_l8_columns_follow_yates_order():
    t = get_array("L8").table
    a, b, c = t[:, 0], t[:, 1], t[:, 3]
    np.testing.assert_array_equal(t[:, 2], a ^ b)
    np.testing.assert_array_equal(t[:, 4], a ^ c)
    np.testing.assert_array_equal(t[:, 5], b ^ c)
    np.testing.assert_array_equal(t[:, 6], a ^ b ^ c)


def test_l16_and_l32_basic_columns():
    t16 = get_array("L16").table
    for bit, col in enumerate((7, 3, 1, 0)):  # D, C, B, A = columns 8, 4, 2, 1
        np.testing.assert_array_equal(t16[:, col], (np.arange(16) >> bit) & 1)
    t32 = get_array("L32").table
    np.testing.assert_array_equal(t32[:, 15], np.arange(32) & 1)  # column 16 = E
    np.testing.assert_array_equal(t32[:, 30], np.bitwise_xor.reduce(t32[:, [0, 1, 3, 7, 15]], 1))


def test_l12_and_l18_published_rows():
    np.testing.assert_array_equal(
        get_array("L12").table[[1, 6, 11]] + 1,
        table_1based(
            [
                "1 1 1 1 1 2 2 2 2 2 2",
                "2 1 2 2 1 1 2 2 1 2 1",
                "2 2 1 1 2 1 2 1 2 2 1",
            ]
        ),
    )
    np.testing.assert_array_equal(
        get_array("L18").table[[3, 9, 17]] + 1,
        table_1based(["1 2 1 1 2 2 3 3", "2 1 1 3 3 2 2 1", "2 3 3 2 1 2 3 1"]),
    )


def test_l36_and_l50_structure():
    t36 = get_array("L36").table
    # 2-level part: each L12 row repeated over three consecutive runs.
    np.testing.assert_array_equal(t36[::3, :11], get_array("L12").table)
    np.testing.assert_array_equal(t36[1::3, :11], get_array("L12").table)
    np.testing.assert_array_equal(t36[:3, 11:] + 1, [[1] * 12, [2] * 12, [3] * 12])
    np.testing.assert_array_equal(t36[3, 11:] + 1, [1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3])
    t50 = get_array("L50").table
    np.testing.assert_array_equal(t50[:, 0], np.repeat([0, 1], 25))
    np.testing.assert_array_equal(t50[:25, 1:7], get_array("L25").table)


@pytest.mark.parametrize(
    ("alias", "canonical"),
    [
        ("L9", "L9"),
        ("l9", "L9"),
        (" L9(3^4) ", "L9"),
        ("L16", "L16"),
        ("L16(2^15)", "L16"),
        ("L16(2**15)", "L16"),
        ("L16(4^5)", "L16(4^5)"),
        ("l16_4^5", "L16(4^5)"),
        ("L16B", "L16(4^5)"),
        ("L18", "L18"),
        ("L18(2^1 3^7)", "L18"),
        ("L18(3^7 2^1)", "L18"),
        ("L18(2^1x3^7)", "L18"),
        ("L36(2^11 3^12)", "L36"),
        ("L50", "L50"),
        ("L64", "L64"),
        ("L64(2^63)", "L64"),
        ("L64(4^21)", "L64(4^21)"),
        ("L64b", "L64(4^21)"),
        ("L81(3^40)", "L81"),
    ],
)
def test_get_array_aliases(alias, canonical):
    assert get_array(alias).name == canonical
    assert get_array(alias) is get_array(canonical)  # cached


@pytest.mark.parametrize("bad", ["L7", "L9(2^4)", "L9B", "foo", "", "L16(4^5", "L25(5^6) x"])
def test_get_array_unknown_lists_available(bad):
    with pytest.raises(ArrayError, match=r"available: L4, L8, L9"):
        get_array(bad)


def test_tables_are_read_only():
    with pytest.raises(ValueError, match="read-only"):
        get_array("L9").table[0, 0] = 2


def test_to_pandas_and_repr():
    df = get_array("L9").to_pandas()
    assert df.shape == (9, 4)
    assert list(df.index) == list(range(1, 10))
    assert list(df.columns) == [1, 2, 3, 4]
    assert df.iloc[3].tolist() == [2, 1, 2, 3]
    assert get_array("L9").to_pandas(one_based=False).iloc[3].tolist() == [1, 0, 1, 2]
    text = repr(get_array("L18"))
    assert "L18" in text and "2^1 3^7" in text


def test_user_built_array():
    arr = OrthogonalArray("mine", np.array([[0, 0], [0, 1], [1, 0], [1, 1]]))
    assert arr.levels == (2, 2)
    assert arr == OrthogonalArray("mine", arr.table)
    check_orthogonal(arr)
    with pytest.raises(ArrayError):
        OrthogonalArray("bad", np.array([[0, -1]]))


@pytest.mark.parametrize(
    ("levels", "name", "columns"),
    [
        ([2, 2, 2], "L4", [0, 1, 2]),
        ([2] * 4, "L8", [0, 1, 2, 3]),
        ([3, 3], "L9", [0, 1]),
        ([3] * 4, "L9", [0, 1, 2, 3]),
        ([2] * 8, "L12", list(range(8))),
        ([4, 4, 4], "L16(4^5)", [0, 1, 2]),
        ([2, 3, 3], "L18", [0, 1, 2]),
        ([3] * 5, "L18", [1, 2, 3, 4, 5]),
        ([3, 2], "L18", [1, 0]),
        ([5] * 5, "L25", [0, 1, 2, 3, 4]),
        ([5] * 6, "L25", list(range(6))),
        ([3] * 8, "L27", list(range(8))),
        ([2, 2, 3, 3, 3, 3, 3, 3, 3, 3], "L36", [0, 1, *range(11, 19)]),
        ([5] * 7, "L50", list(range(1, 8))),
        ([2, 5], "L50", [0, 1]),
        ([4] * 6, "L64(4^21)", list(range(6))),
        ([3] * 14, "L81", list(range(14))),
    ],
)
def test_select_array_smallest(levels, name, columns):
    array, cols = select_array(levels)
    assert array.name == name
    assert cols == columns
    assert [array.levels[c] for c in cols] == levels


def test_select_array_nothing_fits():
    with pytest.raises(ArrayError, match="no standard orthogonal array"):
        select_array([7, 7])
    with pytest.raises(ArrayError, match="no standard orthogonal array"):
        select_array([3] * 41)


def test_select_array_named():
    array, cols = select_array([3, 3, 3], name="L27")
    assert array.name == "L27" and cols == [0, 1, 2]
    with pytest.raises(
        ArrayError, match="L9 has 4 three-level columns; the study has 5 factors with 3 levels"
    ):
        select_array([3] * 5, name="L9")
    with pytest.raises(ArrayError, match="L9 has 0 two-level columns"):
        select_array([2, 3], name="L9")
    with pytest.raises(ArrayError, match="unknown orthogonal array"):
        select_array([3], name="L10")


def test_select_array_explicit_columns():
    array, cols = select_array([3, 3, 3], name="L9", columns=[0, 1, 3])
    assert array.name == "L9" and cols == [0, 1, 3]
    _, cols = select_array([3, 2], name="L18", columns=(np.int64(4), 0))
    assert cols == [4, 0]
    with pytest.raises(ArrayError, match="both assigned to column 1"):
        select_array([3, 3], name="L9", columns=[1, 1])
    with pytest.raises(ArrayError, match="does not exist"):
        select_array([3, 3], name="L9", columns=[1, 4])
    with pytest.raises(ArrayError, match="factor 0 has 2 levels but column 1 of L18 has 3"):
        select_array([2], name="L18", columns=[1])
    with pytest.raises(ArrayError, match="2 columns given for 3 factors"):
        select_array([3, 3, 3], name="L9", columns=[0, 1])
    with pytest.raises(ArrayError, match="without an array name"):
        select_array([3, 3], columns=[0, 1])


@pytest.mark.parametrize("levels", [[], [1], [3, 0], [2.5], [True, 2]])
def test_select_array_invalid_levels(levels):
    with pytest.raises(ArrayError):
        select_array(levels)


def test_check_orthogonal_names_the_fault():
    t = np.array(get_array("L9").table)
    t[8, 3] = 1  # break balance of column 4
    with pytest.raises(ArrayError, match="column 4 is not balanced"):
        check_orthogonal(t)
    t = np.array(get_array("L4").table)
    t = np.column_stack([t, t[:, 0]])  # column 4 duplicates column 1
    with pytest.raises(ArrayError, match="columns 1 and 4 are not orthogonal: level pair"):
        check_orthogonal(t)
    # Swapping two cells in the same column keeps balance but breaks orthogonality.
    t = np.array(get_array("L9").table)
    t[[0, 3], 2] = t[[3, 0], 2]
    with pytest.raises(ArrayError, match="not orthogonal"):
        check_orthogonal(t)
    with pytest.raises(ArrayError):
        check_orthogonal(np.zeros((3,), dtype=int))
