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


def _schema() -> dict:
    import json
    from importlib.resources import files

    return json.loads((files("tsid_fmu") / "schemas" / "result-summary.schema.json").read_text())


def test_identify_json_prints_the_summary_that_the_schema_describes(tmp_path, capsys):
    import json

    import jsonschema
    from fmu_factory import lag_study

    study = lag_study(tmp_path, replicates=1).to_toml(tmp_path / "lag.toml")
    out = tmp_path / "out"
    rc = main(["identify", str(study), "--out", str(out), "--json", "-q", "--no-plots",
               "--workers", "1", "--max-iterations", "2"])  # fmt: skip
    summary = json.loads(capsys.readouterr().out)  # nothing but the JSON on stdout
    jsonschema.validate(summary, _schema())
    saved = json.loads((out / "result.json").read_text())
    assert summary["exit_status"] == rc == saved["status"]
    assert {k: v["value"] for k, v in summary["parameters"].items()} == saved["params"]
    assert summary["parameters"]["tau"]["unit"] == "s"
    assert summary["parameters"]["tau"]["interval"] == saved["intervals"]["tau"]
    for key in ("fun", "nfev", "nit", "status", "success", "message"):
        assert summary[key] == saved[key], key
    assert [s["name"] for s in summary["stages"]] == [s["name"] for s in saved["stages"]]
    assert summary["out_dir"] == str(out)


def test_the_summary_of_a_result_without_intervals_still_fits_the_schema():
    import json
    import math

    import jsonschema

    from tsid_fmu import IdentificationResult

    res = IdentificationResult(
        params={"a": math.nan, "b": 2.0}, fun=math.inf, nfev=0, success=False, status=1, message="m"
    )
    summary = res.summary()
    json.dumps(summary, allow_nan=False)
    jsonschema.validate(summary, _schema())
    assert summary["parameters"]["a"] == {
        "value": None,
        "interval": [None, None],
        "unit": "",
        "weak": None,
        "determined": "not computed",  # no interval was computed: never "not determined"
    }
    assert summary["fun"] is None and summary["out_dir"] is None
    bad = {**summary, "surprise": 1}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, _schema())


def test_the_schema_is_shipped_with_the_package():
    import tomllib

    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert "schemas/*.json" in project["tool"]["setuptools"]["package-data"]["tsid_fmu"]
    assert any(
        r.startswith("jsonschema") for r in project["project"]["optional-dependencies"]["test"]
    )
    assert _schema()["title"] == "tsid identify --json"
