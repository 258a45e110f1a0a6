"""Issue 25, attacks that got through: each is a bad input, exit 2 with one line.

* a huge integer (``derived``, ``levels``, a resumed ``next_levels.toml``) was an
  ``OverflowError`` traceback and exit 70; it is now refused naming the key;
* a file that is not a table (a secrets file ``API_KEY="sk-..."``, ``/etc/os-release``)
  had its first line printed as column names;
* ``/dev/zero`` as data hung, reading forever;
* duplicated data columns were used silently (the first one) or renamed by pandas;
* a UTF-8 BOM (as Excel writes CSV) made the header "not a header".

Each test here failed on the code before its fix (checked by reverting the fix).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from fmu_factory import lag_case

from tsid_fmu.cli import main
from tsid_fmu.data import load_data
from tsid_fmu.errors import DataError, StudyError
from tsid_fmu.study.checks import check_bound, check_number

DT = 0.01
LEVELS = "0.1, 0.3, 0.6"


@pytest.fixture(scope="module")
def lag(tmp_path_factory) -> Path:
    return lag_case(tmp_path_factory.mktemp("lag"), DT)


def study_text(fmu: Path, *, data: str | None = None, extra: str = "", levels: str = LEVELS,
               iterations: int = 1) -> str:  # fmt: skip
    data = data or (fmu.parent / "good.csv").as_posix()
    return (
        f'[study]\nfmu = "{fmu.as_posix()}"\n[data]\nfile = "{data}"\ninputs = {{ u = "u" }}\n'
        f'outputs = {{ y = "y" }}\n{extra}[method]\nmax_iterations = {iterations}\n'
        f"[parameters]\ntau = {{ levels = [{levels}], min = 0 }}\n"
    )


def run(tmp_path: Path, text: str | None, capsys, *more: str, status: int = 2) -> str:
    """Run ``tsid identify`` (writing ``text`` as the study); return stderr, one line."""
    path = tmp_path / "study.toml"
    if text is not None:
        path.write_text(text)
    rc = main(["identify", str(path), "--out", str(tmp_path / "out"), "-q", "--no-plots", *more])
    err = capsys.readouterr().err
    assert rc == status, err
    if status == 2:
        assert err.startswith("tsid: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


# ------------------------------------------------------------------ 1. huge integers

BIG = "9" * 1500


def test_a_huge_integer_in_derived_is_bad_input(lag, tmp_path, capsys):
    err = run(tmp_path, study_text(lag, extra=f'derived = {{ z = "u * {BIG}" }}\n'), capsys)
    assert "derived channel 'z'" in err and "1500 digits" in err
    assert BIG not in err  # the long expression is shortened


@pytest.mark.parametrize(
    ("levels", "key"),
    [
        (f"0.1, 0.3, {'9' * 400}", r"parameters\.tau\.levels\[2\] is an integer of 400 digits"),
        (f"-{'9' * 400}, 0.3", r"parameters\.tau\.levels\[0\]"),
        (f"0.1, {2**63}", r"parameters\.tau\.levels\[1\] is an integer of 19 digits"),
        (f"0.1, {'9' * 5000}", r"an integer has too many digits"),
    ],
)
def test_a_huge_integer_in_levels_is_bad_input(lag, tmp_path, capsys, levels, key):
    err = run(tmp_path, study_text(lag, levels=levels), capsys)
    assert re.search(key, err), err
    assert "study.toml" in err


def test_a_huge_integer_in_a_resumed_next_levels_is_bad_input(lag, tmp_path, capsys):
    run(tmp_path, study_text(lag, iterations=3), capsys, "--pause-after", "1", status=3)
    (next_levels,) = (tmp_path / "out").glob("iteration_*/next_levels.toml")
    next_levels.write_text(f"[levels]\ntau = [0.2, 0.3, {'9' * 400}]\n")
    err = run(tmp_path, None, capsys, "--resume")
    assert "next_levels.toml: levels.tau[2] is an integer of 400 digits" in err


def test_the_value_checks_refuse_integers_no_float_holds():
    from tsid_fmu.study.checks import parse_toml  # new with the fix

    with pytest.raises(StudyError, match=r"x must be a number a float can hold.*400 digits"):
        check_number(10**399, "x")
    with pytest.raises(StudyError, match="min must be a number a float can hold"):
        check_bound(-(10**400), "min", 0.0)
    assert check_number(2**63, "x") == float(2**63)
    with pytest.raises(StudyError, match=r"s\.toml: a\.b\[1\]\.c is an integer"):
        parse_toml(f"[a]\nb = [{{ c = 1 }}, {{ c = {2**64} }}]\n", "s.toml")
    assert parse_toml(f"a = {2**63 - 1}\nb = {-(2**63)}\n", "s.toml") == {
        "a": 2**63 - 1,
        "b": -(2**63),
    }


def test_a_huge_integer_in_an_expression_is_a_data_error(tmp_path):
    (tmp_path / "d.csv").write_text("time,u\n0,1\n0.01,2\n")
    with pytest.raises(DataError, match=r"'big'.*an integer of 400 digits"):
        load_data(tmp_path / "d.csv", derived={"big": "9" * 400})
    data = load_data(tmp_path / "d.csv", derived={"ok": str(10**300)})
    assert data.column("ok")[0] == 1e300
