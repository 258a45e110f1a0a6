"""Issue 25, attacks that got through: each is now one line and the right exit status.

* a huge integer (``derived``, ``levels``, a resumed ``next_levels.toml``, a data cell)
  was an ``OverflowError`` traceback and exit 70; it is bad input naming the key;
* a file that is not a table (a secrets file ``API_KEY="sk-..."``, ``/etc/os-release``)
  had its first line printed as column names;
* ``/dev/zero``, ``/dev/urandom`` or a named pipe as data or study file hung, reading
  forever; a file without line breaks was read whole while looking for the header;
* duplicated data columns were used silently (the first one) or renamed by pandas;
* a full temporary folder or a file-size limit while the FMU was extracted blamed the
  FMU (exit 2); it is an environment error, exit 4, naming ``TMPDIR``;
* HTML in a study name or unit went verbatim into ``report.md``; a UTF-8 BOM (Excel's
  CSV) made the header "not a header"; two-row data and extreme levels printed raw numpy
  RuntimeWarnings; files in an iteration folder that tsid did not write, and an edited
  ``study.toml`` copy, were accepted silently (now warnings).

Each test here failed on the code before its fix (checked by reverting the fix).
"""

from __future__ import annotations

import re
import shutil
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
        f'cost = "iae"\nweighting = "none"\nreplicates = 2\n'  # written for the SISO paper's
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


# ------------------------------------------------ 2. files that are not tables

NOT_TABLES = {
    "secret.env": 'API_KEY="sk-live-SECRET123"\nDB_PASSWORD="hunter2"\n',
    "os-release": 'PRETTY_NAME="Debian GNU/Linux 12 (bookworm)"\nNAME="Debian GNU/Linux"\n'
    'VERSION_ID="12"\nID=debian\n',
    "secret.csv": "API_KEY,sk-live-SECRET123\nDB_PASSWORD,hunter2\n",
    "notes.txt": "Meeting notes\nAsk Bob for the PIN\n",
}
LEAKS = ("API_KEY", "sk-live", "SECRET123", "hunter2", "PRETTY", "Debian", "bookworm", "Bob",
         "Meeting")  # fmt: skip


@pytest.mark.parametrize("name", sorted(NOT_TABLES))
def test_a_file_that_is_no_table_shows_none_of_its_lines(lag, tmp_path, capsys, name):
    (tmp_path / name).write_text(NOT_TABLES[name])
    err = run(tmp_path, study_text(lag, data=(tmp_path / name).as_posix()), capsys)
    shown = err.replace(str(tmp_path), "")
    assert not [s for s in LEAKS if s in shown], err
    with pytest.raises(DataError) as info:
        load_data(tmp_path / name).column("u")
    assert not [s for s in LEAKS if s in str(info.value).replace(str(tmp_path), "")]


def test_a_real_header_is_still_listed(tmp_path):
    (tmp_path / "d.csv").write_text("t,u_in,y_out\n0,1,0\n0.01,1,0\n")
    with pytest.raises(DataError, match=r"columns are t, u_in, y_out"):
        load_data(tmp_path / "d.csv")
    (tmp_path / "d.csv").write_text("t,u_in,y_out\n,,\n")  # no number, but nothing filled in
    with pytest.raises(DataError, match=r"columns are t, u_in, y_out"):
        load_data(tmp_path / "d.csv")
    (tmp_path / "d.csv").write_text("time;u\n0;1\n0.5;2\n")
    assert load_data(tmp_path / "d.csv").names == ["time", "u"]


# ------------------------------------------------ 3. devices, pipes, endless lines


@pytest.mark.slow
@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom", "fifo"])
def test_a_device_or_pipe_as_data_is_refused_at_once(lag, tmp_path, device):
    import os
    import subprocess
    import sys

    if device == "fifo":
        device = str(tmp_path / "data.csv")
        os.mkfifo(device)
    elif not Path(device).exists():
        pytest.skip(f"no {device} here")
    (tmp_path / "study.toml").write_text(study_text(lag, data=device))
    cmd = [sys.executable, "-m", "tsid_fmu", "identify", str(tmp_path / "study.toml"),
           "--out", str(tmp_path / "out"), "-q", "--no-plots"]  # fmt: skip
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        pytest.fail(f"reading {device} did not end")
    assert done.returncode == 2, done.stderr
    assert re.fullmatch(r"tsid: error: .*: not a file \((a device|a named pipe)\).*\n", done.stderr)
    with pytest.raises(DataError, match="not a file"):
        load_data(device)


def test_a_file_without_a_line_break_is_read_no_further_than_its_head(tmp_path, monkeypatch):
    from tsid_fmu.data import textfile

    monkeypatch.setattr(textfile, "HEAD_BYTES", 1000)
    (tmp_path / "blob.csv").write_bytes(b"\0" * 5000)
    (tmp_path / "long.csv").write_bytes(b"time" + b",u" * 3000 + b"\n0" + b",1" * 3000 + b"\n")
    with pytest.raises(DataError, match=r"blob\.csv: no header line in its first 1000 bytes"):
        load_data(tmp_path / "blob.csv")
    with pytest.raises(DataError, match=r"long\.csv: no header line in its first 1000 bytes"):
        load_data(tmp_path / "long.csv")


# ------------------------------------------------ 9. duplicate columns, 11. BOM


@pytest.mark.parametrize(
    ("header", "message"),
    [
        ("time,F_m,u,y,F_m", r"columns 2 and 5 are both named 'F_m'"),
        ("time,u,y,y", r"columns 3 and 4 are both named 'y'"),
        ("time,u, y,y ", r"columns 3 and 4 are both named 'y'"),
        ("time;u;y;u", r"columns 2 and 4 are both named 'u'"),
        ("time,u,y,$x,$x", r"columns 4 and 5 are both named alike"),
        ("\ufefftime,time,u,y", r"columns 1 and 2 are both named 'time'"),
    ],
)
def test_a_column_named_twice_is_refused_naming_both(lag, tmp_path, capsys, header, message):
    n = header.count(",") + header.count(";") + 1
    sep = ";" if ";" in header else ","
    rows = "".join(sep.join([f"{i * DT:g}"] + ["1"] * (n - 1)) + "\n" for i in range(101))
    (tmp_path / "d.csv").write_text(header + "\n" + rows, encoding="utf-8")
    err = run(tmp_path, study_text(lag, data=(tmp_path / "d.csv").as_posix()), capsys)
    assert re.search(message, err), err
    assert ".1" not in err.replace(str(tmp_path), "")


def test_a_frame_with_a_column_named_twice_is_refused():
    import pandas as pd

    frame = pd.DataFrame([[0.0, 1.0, 2.0], [0.1, 1.0, 2.0]], columns=["time", "u", "u"])
    from tsid_fmu.data import MeasuredData

    with pytest.raises(DataError, match=r"<frame>: columns 2 and 3 are both named 'u'"):
        MeasuredData.from_frame(frame)


def test_a_spreadsheet_with_a_column_named_twice_is_refused(tmp_path):
    import pandas as pd

    pytest.importorskip("openpyxl")  # the test extra installs it
    frame = pd.DataFrame([[0.0, 1.0, 2.0, 3.0], [0.1, 1.0, 2.0, 3.0]])
    frame.columns = ["time", "F_m", "y", "F_m"]  # pandas would read it as F_m, F_m.1
    frame.to_excel(tmp_path / "d.xlsx", index=False)
    with pytest.raises(DataError, match=r"d\.xlsx: columns 2 and 4 are both named 'F_m'"):
        load_data(tmp_path / "d.xlsx")
    frame.columns = ["time", "F_m", "y", "F_o"]
    frame.to_excel(tmp_path / "ok.xlsx", index=False)
    assert list(load_data(tmp_path / "ok.xlsx").frame.columns)[:2] == ["time", "F_m"]


def test_a_byte_order_mark_is_not_part_of_the_header(lag, tmp_path, capsys):
    good = (lag.parent / "good.csv").read_text()
    (tmp_path / "excel.csv").write_bytes(b"\xef\xbb\xbf" + good.encode())
    data = load_data(tmp_path / "excel.csv")
    assert data.names == ["time", "u", "y"]
    (tmp_path / "t.csv").write_bytes(b"\xef\xbb\xbft,u\n0,1\n0.1,2\n")
    with pytest.raises(DataError, match=r"time column 'time' not found; columns are t, u\."):
        load_data(tmp_path / "t.csv")
    text = study_text(lag, data=(tmp_path / "excel.csv").as_posix())
    # runs: to its iteration limit, where the probe check shows the answer stationary
    run(tmp_path, text, capsys, status=0)


# ------------------------------------------------ 10. the machine's fault, not the FMU's


@pytest.mark.slow
def test_a_file_size_limit_while_extracting_is_an_environment_error(lag, tmp_path):
    import os
    import resource
    import subprocess
    import sys

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (6000, 6000))  # less than the FMU's library

    (tmp_path / "study.toml").write_text(study_text(lag))
    (tmp_path / "tmp").mkdir()
    env = {**os.environ, "TMPDIR": str(tmp_path / "tmp")}
    cmd = [sys.executable, "-m", "tsid_fmu", "identify", str(tmp_path / "study.toml"),
           "--out", str(tmp_path / "out"), "-q", "--no-plots", "--workers", "1"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env,
                          preexec_fn=limit)  # fmt: skip
    assert done.returncode == 4, done.stderr
    assert re.fullmatch(r"tsid: error: cannot extract Lag\.fmu: writing .*TMPDIR.*\n", done.stderr)
    assert "File too large" in done.stderr and str(tmp_path / "tmp") in done.stderr


def test_a_full_temporary_folder_is_an_environment_error(lag, tmp_path, capsys, monkeypatch):
    from collections import namedtuple

    from tsid_fmu.errors import FMUError, TsidError
    from tsid_fmu.fmu import archive, safe_extract

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(archive.shutil, "disk_usage", lambda p: usage(10**6, 10**6 - 100, 100))
    with pytest.raises(TsidError, match=r"it needs [\d,]+ bytes but only 100 are free") as info:
        safe_extract(lag, tmp_path / "x")
    assert not isinstance(info.value, FMUError)
    # a copy this process has not extracted yet (each FMU file is extracted once)
    fresh = tmp_path / "fresh" / lag.name
    fresh.parent.mkdir()
    shutil.copy(lag, fresh)
    shutil.copy(lag.parent / "good.csv", fresh.parent)
    # in this process (--workers 1 --timeout 0), where the patched disk_usage holds
    err = run(tmp_path, study_text(fresh), capsys, "--workers", "1", "--timeout", "0", status=4)
    assert re.fullmatch(
        r"tsid: error: cannot extract Lag\.fmu: .*only 100 are free.*TMPDIR.*\n", err
    )


# ------------------------------------------------ 11. smaller ones

SCRIPT = "<script>alert(1)</script>"
IMG = "<img src=x onerror=alert(2)>"


def test_html_in_a_study_name_or_unit_is_escaped_in_report_md(lag, tmp_path, capsys):
    text = study_text(lag).replace("[study]\n", f'[study]\nname = "{SCRIPT} & co"\n')
    text = text.replace("min = 0 }", f'min = 0, unit = "{IMG}" }}')
    run(tmp_path, text, capsys, status=0)  # the probe check shows the answer stationary
    report = (tmp_path / "out" / "report.md").read_text()
    assert "<script" not in report and "<img" not in report
    # a "<" that would open a tag is escaped; ">" and a bare "&" read as written
    assert "&lt;script>alert(1)&lt;/script> & co" in report
    assert "&lt;img src=x onerror=alert(2)>" in report


def test_two_row_data_give_no_numpy_warnings(lag, tmp_path, capsys):
    import warnings

    (tmp_path / "two.csv").write_text("time,u,y\n0,1,0\n0.01,1,0.03\n")
    text = study_text(lag, data=(tmp_path / "two.csv").as_posix())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run(tmp_path, text, capsys, "--workers", "1", status=1)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], caught
    assert "RuntimeWarning" not in capsys.readouterr().err
    log = tmp_path / "out" / "warnings.log"  # where -q puts the warnings (issue 62)
    assert not log.exists() or "RuntimeWarning" not in log.read_text(encoding="utf-8")


def test_levels_about_extreme_logs_give_no_numpy_warnings():
    import numpy as np

    from tsid_fmu.doe.leveling import _levels_about
    from tsid_fmu.doe.options import LevelingOptions

    with np.errstate(all="raise"):  # a warning would be an exception here
        levels = _levels_about(
            np.float64(-200.0), np.float64(150.0), 3, True, (0.0, np.inf), LevelingOptions()
        )
    assert len(levels) == 3 and all(np.isfinite(levels))


@pytest.mark.slow
def test_files_tsid_did_not_write_in_the_trail_are_warned_about(lag, tmp_path, capsys):
    (tmp_path / "study.toml").write_text(study_text(lag, iterations=3))
    out = tmp_path / "out"
    cmd = ["identify", str(tmp_path / "study.toml"), "--out", str(out), "-q"]
    assert main([*cmd, "--pause-after", "1"]) == 3  # with the figures the report draws
    assert {"fit.svg", "main_effects.svg"} <= {p.name for p in (out / "iteration_01").iterdir()}
    assert main([*cmd, "--pause-after", "1", "--resume"]) == 3
    assert "warning" not in capsys.readouterr().out  # tsid's own files are no surprise
    (out / "iteration_01" / "notes.txt").write_text("my notes\n")
    (out / "iteration_01" / "study.toml").write_text("# a copy\n")
    (out / "study.toml").write_text((out / "study.toml").read_text() + "# edited\n")
    rc = main(["identify", str(tmp_path / "study.toml"), "--out", str(out), "-q", "--no-plots",
               "--resume"])  # fmt: skip
    captured = capsys.readouterr()
    assert rc in (0, 1), captured.err
    assert re.search(
        r"warning: .*iteration_01: 'notes\.txt', 'study\.toml' not written by tsid-fmu; ignored",
        captured.out,
    ), captured.out
    assert re.search(r"warning: .*out/study\.toml differs from .*study\.toml", captured.out)
    assert "not written by tsid-fmu" in (out / "report.md").read_text()


def test_a_huge_integer_cell_in_the_data_is_located_not_a_crash(lag, tmp_path, capsys):
    (tmp_path / "d.csv").write_text(f"time,u,y\n0,1,0\n0.01,{'9' * 400},0\n0.02,1,0\n")
    with pytest.raises(DataError, match=r"column 'u' is inf in row 2$"):
        load_data(tmp_path / "d.csv")
    err = run(tmp_path, study_text(lag, data=(tmp_path / "d.csv").as_posix()), capsys)
    assert "column 'u' is inf in row 2" in err and "999" not in err
    (tmp_path / "d.csv").write_text(f"time,u,y\n0,1,0\n0.01,1_000,0\n0.02,-{'9' * 400},0\n")
    with pytest.raises(DataError, match=r"column 'u' has a non-numeric value in row 2$"):
        load_data(tmp_path / "d.csv")


@pytest.mark.slow
@pytest.mark.parametrize("device", ["/dev/zero", "fifo"])
def test_a_device_or_pipe_as_study_file_is_refused_at_once(tmp_path, device):
    import os
    import subprocess
    import sys

    if device == "fifo":
        device = str(tmp_path / "study.toml")
        os.mkfifo(device)
    cmd = [sys.executable, "-m", "tsid_fmu", "simulate", device]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        pytest.fail(f"reading {device} did not end")
    assert done.returncode == 2, done.stderr
    assert done.stderr == f"tsid: error: {device}: the study file is not a regular file\n"


def test_a_study_file_with_a_bom_or_old_mac_line_ends_loads(lag, tmp_path):
    from tsid_fmu.study import load_study

    text = study_text(lag)
    (tmp_path / "bom.toml").write_bytes(b"\xef\xbb\xbf" + text.encode())
    (tmp_path / "cr.toml").write_bytes(text.replace("\n", "\r").encode())
    assert load_study(tmp_path / "bom.toml").parameter_names == ["tau"]
    assert load_study(tmp_path / "cr.toml").parameter_names == ["tau"]
