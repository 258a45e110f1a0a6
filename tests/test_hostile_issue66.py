"""Hostile input of issue 66: ``--set`` names, FMU paths tsid cannot read, CSV dialects.

Each ends in one line naming what is at fault (exit 2), or in the right result.
"""

from __future__ import annotations

import builtins
import os
import zipfile
from pathlib import Path

import pytest

from tsid_fmu.cli import main
from tsid_fmu.cli_values import parse_assignments
from tsid_fmu.errors import FMUError, StudyError
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.scaffold import init_study

REPO = Path(__file__).resolve().parents[1]
SISO = REPO / "examples" / "lsea_siso"
FMU = REPO / "fmus" / "LSEA_SISO.fmu"

# -- 23: --set NAME=VALUE with names holding '=' or spaces at their ends ----------------


@pytest.mark.parametrize(
    ("item", "name", "value"),
    [
        ("K_s=5000", "K_s", "5000"),
        (" K_s = 5000 ", "K_s", "5000"),
        ("a=b=5", "a=b", "5"),
        ("x==1", "x=", "1"),
        ('" x "=1', " x ", "1"),
        ('"a=b "=2.5', "a=b ", "2.5"),
        ('"q\\"uote\\u0041"=3', 'q"uoteA', "3"),
        ("model=Drag", "model", "Drag"),
    ],
)
def test_set_splits_at_the_last_equals_and_takes_a_quoted_name_as_it_is(item, name, value):
    assert parse_assignments([item], "--set", last=True) == {name: value}


@pytest.mark.parametrize("item", ["=5", "a=", "K_s", '""=1', '"a"b"=1', '"a" # c"=1'])
def test_set_refuses_what_is_no_assignment(item):
    with pytest.raises(StudyError, match="--set"):
        parse_assignments([item], "--set", last=True)


def test_set_names_a_parameter_with_equals_in_the_cli(tmp_path, capsys):
    """``a=b=5`` was read as ``a`` set to ``b=5``: "not a number"."""
    argv = ["simulate", str(SISO / "study.toml"), "--plot", str(tmp_path / "s.png")]
    assert main([*argv, "--set", "K=s=5000"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a parameter of the study: 'K=s'" in err


def test_derived_still_splits_at_the_first_equals():
    assert parse_assignments(["F=a == b"], "--derived") == {"F": "a == b"}


# -- 24: an FMU path that is a folder, a pipe or cannot be read -------------------------


def _init_err(capsys, fmu: Path, tmp_path: Path) -> str:
    code = main(["init", str(fmu), str(SISO / "measured.csv"), "-o", str(tmp_path / "s.toml")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    return err


def test_an_unpacked_fmu_folder_is_called_a_folder(tmp_path, capsys):
    folder = tmp_path / "Plant.fmu"
    with zipfile.ZipFile(FMU) as archive:
        archive.extract("modelDescription.xml", folder)
    err = _init_err(capsys, folder, tmp_path)
    assert f"{folder} is a folder: give the .fmu archive" in err
    assert "unpacked FMU" in err and "not found" not in err


def test_a_pipe_is_not_read_as_an_fmu(tmp_path, capsys):
    """A FIFO would block ``zipfile.is_zipfile`` until a writer came."""
    fifo = tmp_path / "plant.fmu"
    os.mkfifo(fifo)
    err = _init_err(capsys, fifo, tmp_path)
    assert "is not a regular file" in err and str(fifo) in err


def test_an_fmu_without_read_permission_says_so(tmp_path, capsys, monkeypatch):
    """Tests run as root, who reads any file: opening the FMU is made to fail as it would."""
    locked = tmp_path / "locked.fmu"
    locked.write_bytes(FMU.read_bytes())
    real_open = builtins.open

    def denying(file, *args, **kwargs):
        if os.fspath(file) == os.fspath(locked):
            raise PermissionError(13, "Permission denied", os.fspath(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", denying)
    err = _init_err(capsys, locked, tmp_path)
    assert f"cannot read FMU file {locked}: permission denied" in err
    assert "ZIP archive" not in err
    with pytest.raises(FMUError, match="permission denied"):
        read_fmu_description(locked)


def test_a_missing_fmu_is_still_not_found(tmp_path, capsys):
    err = _init_err(capsys, tmp_path / "none.fmu", tmp_path)
    assert "FMU file not found" in err


def test_init_study_refuses_a_folder_in_python(tmp_path):
    with pytest.raises(FMUError, match="is a folder"):
        init_study(tmp_path, SISO / "measured.csv", tmp_path / "s.toml")


# -- 25: a European CSV: ';' between cells, decimal commas -------------------------------


def _european(path: Path, point: bool = False, bom: bool = False) -> Path:
    import numpy as np

    t = np.arange(0.0, 1.0, 0.01)
    rows = ["time;F_m;x_m"] + [f"{a:.3f};{np.sin(a):.6f};{-1.5e-3 * a:.4e}" for a in t]
    text = "\n".join(rows) + "\n"
    path.write_text(("\ufeff" if bom else "") + (text if point else text.replace(".", ",")))
    return path


@pytest.mark.parametrize("bom", [False, True])
def test_a_european_csv_is_read_with_its_decimal_commas(tmp_path, bom):
    """It was "its first line does not look like a header of column names"."""
    import numpy as np

    from tsid_fmu.data.measured import load_data

    data = load_data(_european(tmp_path / "eu.csv", bom=bom))
    assert data.names == ["time", "F_m", "x_m"]
    assert data.sample_time == pytest.approx(0.01)
    assert data.column("F_m")[1] == pytest.approx(np.sin(0.01), abs=1e-6)
    assert data.column("x_m")[-1] == pytest.approx(-1.5e-3 * 0.99, rel=1e-3)


def test_a_semicolon_csv_with_decimal_points_is_read_as_before(tmp_path):
    from tsid_fmu.data.measured import load_data

    data = load_data(_european(tmp_path / "pt.csv", point=True))
    assert data.column("time")[1] == pytest.approx(0.01)


def test_init_on_a_european_csv_writes_a_study(tmp_path, capsys):
    data = _european(tmp_path / "eu.csv")
    assert main(["init", str(FMU), str(data), "-o", str(tmp_path / "s.toml")]) == 0
    assert "x_m" in (tmp_path / "s.toml").read_text()


# -- 12: memory of a long CSV, for init and for the reader -------------------------------

_MEASURE = """
import resource, sys
from tsid_fmu.data.measured import load_data
from tsid_fmu.scaffold import init_study
import pandas, numpy
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
if sys.argv[1] == "init":
    init_study(sys.argv[3], sys.argv[2], sys.argv[4])
else:
    load_data(sys.argv[2])
print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024)
"""


@pytest.fixture(scope="module")
def long_csv(tmp_path_factory) -> Path:
    """500 000 rows of 5 columns: 20 MB of float64, 40 MB of text."""
    import numpy as np
    import pandas as pd

    n = 500_000
    t = np.arange(n) * 1e-3
    frame = pd.DataFrame({"time": t, "F_m": np.sin(t), "F_o": np.cos(t), "x_m": t, "x_o": -t})
    path = tmp_path_factory.mktemp("long") / "long.csv"
    frame.to_csv(path, index=False)
    return path


def _peak_mib(*argv: str) -> float:
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run(
        [sys.executable, "-c", _MEASURE, *argv], capture_output=True, text=True, env=env,
        timeout=300, check=True,
    )  # fmt: skip
    return float(done.stdout.split()[-1])


def test_init_on_a_long_csv_reads_the_time_column_only(long_csv, tmp_path):
    """The python engine's reader had taken 280 MiB over the imports' for this file."""
    out = tmp_path / "s.toml"
    grown = _peak_mib("init", str(long_csv), str(FMU), str(out))
    assert grown < 40, f"{grown:.0f} MiB"
    assert "windows = [[49.9999, 499.999]]" in out.read_text()  # the whole record's


def test_the_reader_holds_a_long_csv_in_a_few_copies_of_its_floats(long_csv):
    """20 MB of float64: it took 280 MiB over the imports' (per-cell Python objects)."""
    grown = _peak_mib("load", str(long_csv))
    assert grown < 120, f"{grown:.0f} MiB"


# -- 20: what an FMU printed, with ESC, OSC, BEL and NUL, in the error line and the HTML --

FMU_PRINTED = "The FMU printed: \x1b]0;owned\x07\x1b[2J\x00 done\x7f\x9b"


def test_the_error_line_escapes_control_characters(capsys, monkeypatch):
    import tsid_fmu.cli as cli
    from tsid_fmu.errors import SimulationError

    def failing(args):
        raise SimulationError(f"fmi2DoStep returned Error at t=0.35. {FMU_PRINTED}")

    monkeypatch.setattr(cli, "_cmd_info", failing)
    assert main(["info", str(FMU)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.rstrip("\n").isprintable()
    assert "\\x1b]0;owned\\x07\\x1b[2J\\x00 done\\x7f\\x9b" in err


def test_a_path_with_an_escape_sequence_is_escaped_in_the_error_line(tmp_path, capsys):
    err = _init_err(capsys, tmp_path / "a\x1b]0;owned\x07b.fmu", tmp_path)
    assert err.rstrip("\n").isprintable() and "a\\x1b]0;owned\\x07b.fmu" in err


def test_report_html_escapes_control_characters():
    from tsid_fmu.report.html_tables import esc, table

    assert esc(FMU_PRINTED) == "The FMU printed: \\x1b]0;owned\\x07\\x1b[2J\\x00 done\\x7f\\x9b"
    assert esc("a <b>\n\tc") == "a &lt;b&gt;\n\tc"  # line breaks and tabs stay
    html = table(["run", "reason"], [[1, FMU_PRINTED]])
    assert not any(c in html for c in "\x1b\x07\x00\x7f\x9b")


def test_read_options_only_the_python_engine_takes_still_work(tmp_path):
    """The C parser refuses ``skipfooter``: such a study keeps the python engine."""
    from tsid_fmu.data.measured import load_data

    path = tmp_path / "footer.csv"
    path.write_text("time,y\n0,1\n0.1,2\n0.2,3\nend of record\n")
    data = load_data(path, read_options={"skipfooter": 1})
    assert list(data.column("y")) == [1.0, 2.0, 3.0]
