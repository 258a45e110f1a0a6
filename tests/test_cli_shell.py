"""Shell conventions of ``tsid`` (issue 26): bad usage is exit 2 with one line naming
the option or file, checked before any FMU is loaded; nothing is overwritten unasked."""

from __future__ import annotations

from pathlib import Path

import pytest

from tsid_fmu.cli import main

REPO = Path(__file__).resolve().parents[1]
SISO = REPO / "examples" / "lsea_siso"
FMU = REPO / "fmus" / "LSEA_SISO.fmu"


def _usage_error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Run ``tsid argv``; it must stop at argument parsing with exit 2; return stderr."""
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err.strip().splitlines()[-1]


def test_init_refuses_to_overwrite_a_file_unless_forced(tmp_path, capsys):
    study = tmp_path / "study.toml"
    study.write_text("# mine\n")
    argv = ["init", str(FMU), str(SISO / "measured.csv"), "-o", str(study)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(study) in err and "--force" in err
    assert study.read_text() == "# mine\n"
    assert main([*argv, "--force"]) == 0
    assert "[parameters]" in study.read_text()
    assert main(["init", str(FMU), str(SISO / "measured.csv"), "-o", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["-1", "nan", "inf", "abc", "None"])
def test_a_bad_timeout_is_named_at_parsing(value, capsys):
    # the study does not exist: the option is refused before anything is read
    line = _usage_error(["identify", "missing.toml", f"--timeout={value}"], capsys)
    assert "--timeout" in line and "seconds" in line and f"'{value}'" in line
    assert "None" not in line.replace(f"'{value}'", "")


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5"])
def test_workers_below_one_is_refused_at_parsing(value, capsys):
    line = _usage_error(["identify", "missing.toml", "--workers", value], capsys)
    assert "--workers" in line and f"'{value}'" in line


def test_zero_timeout_and_one_worker_still_parse():
    from tsid_fmu.cli import make_parser

    args = make_parser().parse_args(["identify", "s.toml", "--timeout", "0", "--workers", "1"])
    assert args.timeout == 0.0 and args.workers == 1


def test_simulate_with_a_missing_result_names_it(tmp_path, capsys):
    missing = tmp_path / "nowhere"
    assert main(["simulate", str(SISO / "study.toml"), "--result", str(missing)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(missing) in err and "no such file" in err
    assert "FileNotFoundError" not in err
    assert main(["simulate", str(SISO / "study.toml"), "--result", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path) in err and "no result.json" in err


def test_set_with_an_unknown_name_suggests_the_close_one(tmp_path, capsys):
    argv = ["simulate", str(SISO / "study.toml"), "--plot", str(tmp_path / "s.png")]
    assert main([*argv, "--set", "K_S=5000", "--set", "zzz=1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "'K_S' (did you mean 'K_s'?)" in err and "'zzz'" in err and "K_s, B_s" in err
    assert not (tmp_path / "s.png").exists()
