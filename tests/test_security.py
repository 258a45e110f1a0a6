"""Issue 13, hostile files: no code from data files, no file contents in errors, checks.

Every attack the issue lists that a study or data file can carry is a test here:

* the ``derived`` expression that reached ``os.system`` through attribute access on a
  column (the data file's header supplied the names), and ``F_of.to_csv`` writing a
  file; a hypothesis strategy over expression trees lets nothing but our own
  ``DataError`` out and never creates a file;
* ``file = "/etc/passwd"``: the error listed the file's first line as column names;
  a non-numeric cell was quoted in the message; a hypothesis strategy over column
  names and cells checks that no message quotes a name that is not a header;
* validation gaps: ``min = nan``, ``significance_db = inf``, boolean and string
  levels, all-zero weights, ``1e308`` in an expression, a deeply nested TOML file,
  control characters in names (refused in study files, escaped in ``report.md``), an
  FMI 1.0 FMU with a damaged version string; files written with the umask's mode.

On the code before this change (commit 7e0d910), the tests of the messages
(``/etc/passwd``, the quoted cell, the hypothesis leak check), of names with control
characters, of ``report.md`` escaping and of the FMI 1.0 message fail; the others
failed on the code the issue was filed against (52cc304) and guard the lead's fixes.
"""

from __future__ import annotations

import ast
import os
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmu_factory import lag_case
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tsid_fmu.cli import main
from tsid_fmu.data import load_data
from tsid_fmu.data.expressions import FUNCTIONS, evaluate
from tsid_fmu.data.names import header_like
from tsid_fmu.errors import DataError, FMUError, StudyError
from tsid_fmu.fmu import fmu_info
from tsid_fmu.report.markdown import escape, markdown_report
from tsid_fmu.result import IdentificationResult
from tsid_fmu.study import load_study
from tsid_fmu.trail.files import atomic_write

DT = 0.01
ESC = "\x1b[2J\x1b[31m"


@pytest.fixture(scope="module")
def lag(tmp_path_factory) -> Path:
    return lag_case(tmp_path_factory.mktemp("lag"), DT)


def study_text(fmu: Path, data: str, *, extra: str = "", method: str = "",
               params: str = "tau = { levels = [0.1, 0.3, 0.6], min = 0 }\n") -> str:  # fmt: skip
    return (
        f'[study]\nfmu = "{fmu.as_posix()}"\n[data]\nfile = "{data}"\ninputs = {{ u = "u" }}\n'
        f'outputs = {{ y = "y" }}\n{extra}[method]\nmax_iterations = 1\n{method}'
        f"[parameters]\n{params}"
    )


def run_cli(tmp_path: Path, text: str, capsys) -> str:
    """Run ``tsid identify``; assert exit 2, one line on stderr, no traceback."""
    path = tmp_path / "study.toml"
    path.write_text(text)
    rc = main(["identify", str(path), "--out", str(tmp_path / "out"), "-q", "--no-plots"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("tsid: error: ") and err.count("\n") == 1 and "Traceback" not in err
    return err


def files_under(folder: Path) -> set[Path]:
    return {p for p in folder.rglob("*")}


# ------------------------------------------------------------- code from data files

HOSTILE_HEADER = "time,F_of,F_or,__class__,__init__,__globals__,get,sys,modules,os,system\n"
ROWS = "".join(f"{i * DT:.2f},{i},{i / 2},0,0,0,0,0,0,0,0\n" for i in range(5))


def test_the_issue_attack_runs_no_shell_command(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "d.csv").write_text(HOSTILE_HEADER + ROWS)
    attack = (
        "F_of - F_or + 0 * F_of.__class__.__init__.__globals__.get('sys')"
        ".modules.get('os').system('touch pwned')"
    )
    before = files_under(tmp_path)
    with pytest.raises(DataError, match=r"derived channel 'F_o' = .*attribute"):
        load_data(tmp_path / "d.csv", derived={"F_o": attack})
    with pytest.raises(DataError, match=r"derived channel 'F_o' = .*attribute"):
        load_data(tmp_path / "d.csv", derived={"F_o": "F_of.to_csv('out.csv')"})
    assert files_under(tmp_path) == before  # neither pwned nor out.csv


@pytest.mark.parametrize(
    "expr",
    [
        "__import__('os').system('touch pwned')",
        "open('pwned', 'w')",
        "getattr(F_of, 'to_csv')('pwned')",
        "eval('1')",
        "(lambda: F_of)()",
        "[x for x in F_of]",
        "F_of[0]",
        "'pwned'",
        "b'pwned'",
        "f'{F_of}'",
        "F_of if F_of else F_or",
        "(x := F_of)",
        "F_of and F_or",
        "1j * F_of",
        "True + F_of",
        "der(F_of, window=5)",
        "der(F_of, F_or)",
        "abs(F_of, F_or)",
        "where(F_of, F_or)",
        "system(F_of)",
        "F_of @ F_or",
        "~F_of",
        "F_of in F_or",
        "*F_of",
        "{F_of: 1}",
        "-" * 5000 + "F_of",
        "-(" * 200 + "F_of" + ")" * 200,
        "F_of" + " + F_of" * 1000,
    ],
)
def test_expressions_outside_the_language_are_refused(tmp_path, monkeypatch, expr):
    monkeypatch.chdir(tmp_path)
    cols = {"F_of": np.arange(5.0), "F_or": np.ones(5)}
    before = files_under(tmp_path)
    with pytest.raises(DataError, match=r"derived channel 'F_o'"):
        evaluate(expr, cols, sample_time=DT, channel="F_o", source="d.csv")
    assert files_under(tmp_path) == before


def test_large_number_literals_are_numbers(tmp_path):
    (tmp_path / "d.csv").write_text("time,F_of\n0,1\n0.01,2\n0.02,3\n")
    data = load_data(tmp_path / "d.csv", derived={"big": "0 * F_of + 1e308", "neg": "-2e-308"})
    assert data.column("big").tolist() == [1e308] * 3
    assert data.column("neg")[0] == -2e-308


_NAMES = st.sampled_from(
    ["F_of", "F_or", "pi", "e", "os", "sys", "__class__", "__import__", "open", "eval",
     "exec", "getattr", "system", "to_csv", "__globals__", "der", "abs", "where", "x"]
)  # fmt: skip
_LITERALS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**30), 10**30),
    st.text(max_size=8),
    st.binary(max_size=4),
    st.booleans(),
    st.none(),
    st.complex_numbers(allow_nan=False, allow_infinity=False, max_magnitude=1e3),
).map(lambda v: ast.Constant(value=v))
_BINOPS = st.sampled_from([ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.Mod,
                           ast.FloorDiv, ast.BitAnd, ast.LShift, ast.MatMult])  # fmt: skip
_CMPOPS = st.sampled_from([ast.Lt, ast.Eq, ast.Gt, ast.In, ast.Is, ast.NotEq])


def _tree(children):
    name = _NAMES.map(lambda n: ast.Name(id=n, ctx=ast.Load()))
    return st.one_of(
        st.builds(lambda a, op, b: ast.BinOp(a, op(), b), children, _BINOPS, children),
        st.builds(lambda a: ast.UnaryOp(ast.USub(), a), children),
        st.builds(lambda a: ast.UnaryOp(ast.Not(), a), children),
        st.builds(lambda a, op, b: ast.Compare(a, [op()], [b]), children, _CMPOPS, children),
        st.builds(
            lambda f, args: ast.Call(ast.Name(id=f, ctx=ast.Load()), args, []),
            st.sampled_from([*FUNCTIONS, "open", "eval", "__import__", "getattr", "print"]),
            st.lists(children, max_size=3),
        ),
        st.builds(
            lambda f, a: ast.Call(f, [a], [ast.keyword("window", ast.Constant(5))]), name, children
        ),
        st.builds(lambda a, n: ast.Attribute(a, n, ast.Load()), children, _NAMES),
        st.builds(lambda a, b: ast.Subscript(a, b, ast.Load()), children, children),
        st.builds(lambda a: ast.Lambda(ast.arguments([], [], None, [], [], None, []), a), children),
        st.builds(lambda a, b, c: ast.IfExp(a, b, c), children, children, children),
        st.builds(lambda a: ast.List([a], ast.Load()), children),
        st.builds(lambda a, b: ast.BoolOp(ast.And(), [a, b]), children, children),
    )


EXPRESSION_TREES = st.recursive(
    st.one_of(_NAMES.map(lambda n: ast.Name(id=n, ctx=ast.Load())), _LITERALS),
    _tree,
    max_leaves=12,
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow,
          HealthCheck.function_scoped_fixture])  # fmt: skip
@given(tree=EXPRESSION_TREES)
def test_any_expression_tree_gives_a_result_or_our_error_and_no_file(tmp_path, tree):
    text = ast.unparse(ast.fix_missing_locations(ast.Expression(tree)))
    cols = {"F_of": np.linspace(-1, 1, 30), "F_or": np.ones(30), "x": np.arange(30.0)}
    cwd = os.getcwd()
    before = files_under(tmp_path)
    os.chdir(tmp_path)
    try:
        value = evaluate(text, cols, sample_time=DT, channel="c", source="d.csv")
    except DataError:
        pass
    else:
        assert value.shape == (30,) and value.dtype == np.float64
    finally:
        os.chdir(cwd)
    assert files_under(tmp_path) == before


# ------------------------------------------------------------- no data in errors

PASSWD = (
    "root:x:0:0:root:/root:/bin/bash\n"
    "daemon:x:1:1:daemon:/usr/sbin:/usr/sbin/nologin\n"
    "alice:x:1000:1000:Alice Secretname:/home/alice:/bin/zsh\n"
)


def test_a_system_file_as_data_shows_none_of_its_lines(lag, tmp_path, capsys):
    (tmp_path / "passwd").write_text(PASSWD)
    err = run_cli(tmp_path, study_text(lag, (tmp_path / "passwd").as_posix()), capsys)
    assert "passwd" in err and "time column 'time' not found" in err
    for secret in ("root", "/bin/bash", "daemon", "nologin", "Secretname"):
        assert secret not in err.replace(str(tmp_path), ""), err
    if Path("/etc/passwd").is_file():  # the issue's own attack, where the file exists
        err = run_cli(tmp_path, study_text(lag, "/etc/passwd"), capsys)
        assert "root" not in err and "/bin/" not in err, err


def test_a_non_numeric_cell_is_located_not_quoted(lag, tmp_path, capsys):
    (tmp_path / "d.csv").write_text("time,u,y\n0,1,0\n0.01,hunter2-token,0\n0.02,1,0\n")
    err = run_cli(tmp_path, study_text(lag, "d.csv"), capsys)
    assert re.search(r"d\.csv: column 'u' has a non-numeric value in row 2$", err), err
    assert "hunter2" not in err


def test_column_names_that_are_not_a_header_are_not_listed(tmp_path):
    path = tmp_path / "notes.csv"
    path.write_text("time,u,my PIN is 4711!\n0,1,2\n0.1,1,2\n")
    with pytest.raises(DataError) as info:
        load_data(path, time_column="t")
    assert "4711" not in str(info.value) and "3 column(s)" in str(info.value)
    with pytest.raises(DataError, match=r"column 3 is missing \(NaN\) in row 2"):
        load_data(_write(tmp_path, "time,u,$x\n0,1,2\n0.1,1,\n"))
    data = load_data(_write(tmp_path, "time,u,$x$\n0,1,2\n0.1,1,2\n"))
    with pytest.raises(DataError) as info:
        data.column("u2")
    assert "$x$" not in str(info.value)
    # a real header is still listed, with suggestions
    with pytest.raises(DataError, match=r"columns are time, u, y\. Did you mean 'y'"):
        load_data(_write(tmp_path, "time,u,y\n0,1,2\n0.1,1,2\n")).column("yy")


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / f"f{abs(hash(text))}.csv"
    path.write_text(text)
    return path


def test_mat_variable_names_are_checked_too(tmp_path):
    from scipy.io import savemat

    savemat(tmp_path / "d.mat", {"time": np.arange(4.0), "Xsecret_": np.ones(3)})
    with pytest.raises(DataError, match="different lengths: time=4, Xsecret_=3"):
        load_data(tmp_path / "d.mat")
    assert header_like("Xsecret_") and not header_like("$x") and not header_like("/root")
    assert header_like("Time (s)") and header_like("u[1]") and not header_like("0")
    assert not header_like("a" * 65) and not header_like("x\x1b[2J")


SECRET = "SECRET"
_HEADER_TEXT = st.text(
    alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\r\n\x00"),
    max_size=12,
)


@st.composite
def hostile_tables(draw) -> tuple[list[str], list[list[str]], str]:
    names = draw(st.lists(_HEADER_TEXT, min_size=1, max_size=5))
    bad = draw(st.sampled_from(["$", "!", "\x1b", "@", "=", "\\", '"', ",", ";", "<", "\t"]))
    hostile = draw(st.sampled_from([f"{bad}{SECRET}", f"{SECRET}{bad}", f"x{bad}{SECRET}"]))
    names.insert(draw(st.integers(0, len(names))), hostile)
    cells = st.sampled_from(["0", "1.5", "", "nan", "inf", f"{SECRET}cell", "x"])
    rows = draw(st.lists(st.lists(cells, min_size=len(names), max_size=len(names)), max_size=4))
    time_column = draw(st.sampled_from(["time", names[0], hostile]))
    return names, rows, time_column


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow,
          HealthCheck.function_scoped_fixture])  # fmt: skip
@given(table=hostile_tables(), derived=st.sampled_from([None, {"d": "time + q"}]))
def test_no_message_quotes_a_name_or_cell_that_is_not_a_header(tmp_path, table, derived):
    import csv

    names, rows, time_column = table
    folder = tmp_path / f"h{abs(hash((tuple(names), str(rows))))}"
    folder.mkdir(exist_ok=True)
    path = folder / "data.csv"
    with open(path, "w", newline="", encoding="utf-8") as fh:
        csv.writer(fh, quoting=csv.QUOTE_ALL).writerows([names, *rows])
    before = files_under(folder)
    try:
        load_data(path, time_column=time_column, derived=derived).column("missing_one")
    except DataError as exc:
        # the study's own time column name may be quoted; nothing the file holds may
        message = str(exc).replace(str(path), "").replace(repr(time_column), "")
        assert SECRET not in message, message
    assert files_under(folder) == before


# ------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("params", "extra", "method", "message"),
    [
        ("tau = { levels = [0.1, 0.3], min = nan }\n", "", "", r"min must be a number, got nan"),
        ("tau = { levels = [0.1, 0.3], max = nan }\n", "", "", r"max must be a number, got nan"),
        ("tau = { levels = [true, false] }\n", "", "", r"levels must be a number, got True"),
        ('tau = { levels = ["1e2", "3"] }\n', "", "", r"levels must be a number, got '1e2'"),
        ("tau = { levels = [0.1, 0.3] }\n", "", "[leveling]\nsignificance_db = inf\n",
         r"significance_db must be >= 0 \(and finite\), got inf"),
        ("tau = { levels = [0.1, 0.3] }\n", "", "[leveling]\ntolerance = nan\n", r"tolerance"),
        ("tau = { levels = [0.1, 0.3] }\n", "weights = { y = 0 }\n", "",
         r"every output has weight 0"),
        ("tau = { levels = [0.1, 0.3] }\n", "", "input_noise = inf\n", r"input_noise"),
        ("tau = { levels = [0.1, 0.3] }\n", 'name = "lab\\u001b[2J"\n', "",
         r"name must be printable text, got 'lab\\x1b\[2J'"),
    ],
)  # fmt: skip
def test_numbers_ranges_and_names_are_checked(lag, tmp_path, capsys, params, extra, method,
                                               message):  # fmt: skip
    (tmp_path / "good.csv").write_bytes((lag.parent / "good.csv").read_bytes())
    err = run_cli(tmp_path, study_text(lag, "good.csv", extra=extra, method=method,
                                       params=params), capsys)  # fmt: skip
    assert re.search(message, err), err


def test_a_study_name_with_control_characters_is_refused(lag, tmp_path):
    text = study_text(lag, "good.csv").replace("[study]\n", '[study]\nname = "a\\u001b[31m"\n')
    (tmp_path / "s.toml").write_text(text)
    (tmp_path / "good.csv").write_bytes((lag.parent / "good.csv").read_bytes())
    with pytest.raises(StudyError, match=r"\[study\] name must be printable text"):
        load_study(tmp_path / "s.toml")


def test_a_deeply_nested_study_file_is_one_line(tmp_path, capsys):
    path = tmp_path / "deep.toml"
    path.write_text("a = " + "[" * 50_000 + "]" * 50_000 + "\n")
    assert main(["identify", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nested too deeply" in err and "deep.toml" in err
    assert not (tmp_path / "o").exists()


def test_control_characters_are_escaped_in_the_report():
    result = IdentificationResult(
        params={"tau": 0.3}, fun=0.1, nfev=9, success=True, status=0, message=f"done{ESC}",
        warnings=[f"the FMU said {ESC}hello\nnext line"],
        validation={f"exp{ESC}": {"error": f"fmi2DoStep {ESC}failed"}},
        weak={"tau": f"reason{ESC}"},
    )  # fmt: skip
    text = markdown_report(result)
    assert "\x1b" not in text and "\\x1b[2J\\x1b[31m" in text
    assert "hello\\nnext line" in text
    assert escape("ok \u202eevil") == "ok \\u202eevil"


# ------------------------------------------------------------- FMUs and files


def _fmi1_fmu(tmp_path: Path, version: str | None, states: bool) -> Path:
    attrs = f'fmiVersion="{version}" ' if version is not None else ""
    attrs += 'numberOfContinuousStates="1" ' if states else ""
    xml = (
        '<?xml version="1.0"?>\n<fmiModelDescription '
        f'{attrs}modelName="M" modelIdentifier="M" guid="{{x}}" numberOfEventIndicators="0">'
        "<ModelVariables/></fmiModelDescription>\n"
    )
    path = tmp_path / f"fmi1_{version}_{states}.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", xml)
    return path


@pytest.mark.parametrize(
    ("version", "states", "message"),
    [
        ("1.0", False, r"an FMI 1\.0 FMU \(fmiVersion '1\.0'\)"),
        ("1.0", True, r"an FMI 1\.0 FMU \(fmiVersion '1\.0'\)"),
        ("1.O", True, r"an FMI 1\.0 FMU \(it has numberOfContinuousStates\) with a damaged "
                      r"fmiVersion '1\.O'"),
        (None, True, r"an FMI 1\.0 FMU .* damaged fmiVersion None"),
        (None, False, r"has no fmiVersion"),
        ("2.1", False, r"FMI version '2\.1' is not supported"),
    ],
)  # fmt: skip
def test_fmi1_and_damaged_versions_are_named(tmp_path, capsys, version, states, message):
    fmu = _fmi1_fmu(tmp_path, version, states)
    with pytest.raises(FMUError, match=message):
        fmu_info(fmu)
    assert main(["info", str(fmu)]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err) and "NoneType" not in err and "int()" not in err, err
    from tsid_fmu.fmu.variables import read_description

    folder = tmp_path / f"x{version}{states}"
    zipfile.ZipFile(fmu).extractall(folder)
    with pytest.raises(FMUError, match=message):
        read_description(folder / "modelDescription.xml", fmu)


@pytest.mark.parametrize("umask", [0o022, 0o002, 0o077])
def test_files_get_the_umask_default_mode(tmp_path, umask):
    old = os.umask(umask)
    try:
        atomic_write(tmp_path / "f.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "f.txt").stat().st_mode & 0o777 == 0o666 & ~umask


def test_strict_json_turns_every_value_into_json_data():
    """One converter serves the trail, the fingerprint and result.to_dict."""
    import dataclasses
    import json
    import math
    from pathlib import Path

    import numpy as np

    from tsid_fmu.trail.files import strict

    @dataclasses.dataclass
    class Part:
        value: float
        where: Path

    data = {1: (np.float64(2.5), np.arange(2)), "p": Part(math.inf, Path("a/b")), "n": math.nan}
    assert strict(data) == {"1": [2.5, [0, 1]], "p": {"value": None, "where": "a/b"}, "n": None}
    as_text = strict(data, nonfinite=repr)
    assert as_text["p"]["value"] == "inf" and as_text["n"] == "nan"
    json.dumps(strict(data), allow_nan=False)  # strict JSON indeed
