"""The command line without surprises (issue 14): --version, build/info/simulate options,
tsid init round trips, headlines that agree with the exit status, progress with ETA."""

from __future__ import annotations

import argparse
import io
import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_pythonfmu, pythonfmu_available

from tsid_fmu import Method, Study, __version__
from tsid_fmu.cli import main, make_parser
from tsid_fmu.fmu import FMUSession
from tsid_fmu.report.console import ConsoleProgress
from tsid_fmu.scaffold import decade_levels

REPO = Path(__file__).resolve().parents[1]
SISO = REPO / "examples" / "lsea_siso"
MISO = REPO / "examples" / "lsea_miso"


def test_version_and_help_for_every_option(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out.strip() == f"tsid {__version__}"
    parser = make_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == {"identify", "simulate", "info", "init", "build", "screen", "design"}
    for name, p in sub.choices.items():
        for action in p._actions:
            if not isinstance(action, argparse._HelpAction):
                assert action.help, f"tsid {name} {action.dest} has no help"
    args = parser.parse_args(["build", "--out", "somewhere"])
    assert args.models == [] and args.out == "somewhere"
    args = parser.parse_args(["build", "LSEA_SISO", "--out", "d", "--fmi-version", "2"])
    assert args.models == ["LSEA_SISO"] and args.out == "d"


def test_info_all_lists_locals_with_causality(capsys):
    assert main(["info", str(REPO / "fmus" / "LSEA_SISO.fmu"), "--all"]) == 0
    out = capsys.readouterr().out
    rows = {
        line.split()[0]: line.split()[1] for line in out.split("All variables")[1].splitlines()[2:]
    }
    assert rows["x_m"] == "local" and rows["F_m"] == "input" and rows["K_s"] == "parameter"
    assert main(["info", str(REPO / "fmus" / "LSEA_SISO.fmu")]) == 0
    assert "All variables" not in capsys.readouterr().out


def test_simulate_keeps_the_fmu_start_values_and_writes_csv(tmp_path, capsys):
    csv = tmp_path / "sim.csv"
    rc = main(["simulate", str(SISO / "study.toml"), "--set", "K_s=5000",
               "--plot", str(tmp_path / "s.png"), "--csv", str(csv)])  # fmt: skip
    assert rc == 0
    out = capsys.readouterr().out
    assert "parameters: K_s=5000" in out and "simulated every experiment" in out
    sim = pd.read_csv(csv)
    assert list(sim.columns) == ["time", "F_o", "x_m"]
    data = pd.read_csv(SISO / "measured.csv")
    t, u = data["time"].to_numpy(), data[["F_m"]].to_numpy()
    # the FMU's own start values for every other parameter (V_z from the study file)
    with FMUSession(REPO / "fmus" / "LSEA_SISO.fmu", ["F_m"], ["F_o", "x_m"],
                    parameters=["K_s", "V_z"]) as s:  # fmt: skip
        ref = s.simulate(t, u, {"K_s": 5000.0, "V_z": 0.001})
    np.testing.assert_allclose(sim[["F_o", "x_m"]].to_numpy(), ref, rtol=1e-9, atol=1e-12)
    with FMUSession(REPO / "fmus" / "LSEA_SISO.fmu", ["F_m"], ["F_o", "x_m"],
                    parameters=["K_s", "M_m", "V_z"]) as s:  # fmt: skip
        mid = s.simulate(t, u, {"K_s": 5000.0, "M_m": 8.0, "V_z": 0.001})
    assert np.abs(mid - ref).max() > 1e-3  # the middle first level of M_m would differ


def test_decade_levels():
    assert decade_levels(8600.0) == [2720.0, 4836.0, 8600.0, 15290.0, 27200.0]
    assert decade_levels(-2.0) == [-6.325, -3.557, -2.0, -1.125, -0.6325]
    assert decade_levels(0.0) == [-1.0, -0.5, 0.0, 0.5, 1.0]


def _identify_one_iteration(study: Path, tmp_path: Path) -> dict:
    out = tmp_path / "run"
    rc = main(["identify", str(study), "--out", str(out), "--max-iterations", "1",
               "-q", "--no-plots", "--workers", "1"])  # fmt: skip
    assert rc in (0, 1)
    return json.loads((out / "result.json").read_text())


@pytest.mark.slow
def test_init_siso_round_trip(tmp_path, capsys):
    study = tmp_path / "s" / "study.toml"
    assert main(["init", str(REPO / "fmus" / "LSEA_SISO.fmu"),
                 str(SISO / "measured.csv"), "-o", str(study)]) == 0  # fmt: skip
    text = study.read_text()
    assert 'inputs = { F_m = "F_m" }' in text and 'outputs = { x_m = "x_m" }' in text
    assert "# FMU outputs without a column: F_o" in text
    assert "# data columns not used: F_of, F_or" in text
    assert (
        'K_s = { levels = [2720.0, 4836.0, 8600.0, 15290.0, 27200.0], min = 0, unit = "N/m" }'
        in text
    )
    assert "# fixedStepSize" in text and 'array = "L25"' in text
    assert 'cost = "sse"' in text and 'weighting = "noise"' in text and "replicates = 1" in text
    # init writes the defaults of Method() and of a study file without them
    written = tomllib.loads(text)["method"]
    keys = ("cost", "weighting", "replicates")
    assert {k: written[k] for k in keys} == {k: getattr(Method(), k) for k in keys}
    bare = text.replace('cost = "sse"', "").replace('weighting = "noise"', "")
    bare = bare.replace("replicates = 1", "")
    (study.parent / "bare.toml").write_text(bare)
    loaded = Study.from_toml(study.parent / "bare.toml").method
    assert {k: getattr(loaded, k) for k in keys} == {k: written[k] for k in keys}
    res = _identify_one_iteration(study, tmp_path)
    assert set(res["params"]) == {"F_cm", "F_vm", "M_m", "K_s", "B_s"}  # V_z: a numerical setting


@pytest.mark.slow
def test_init_miso_needs_the_derived_channels_and_then_runs(tmp_path, capsys):
    study = tmp_path / "study.toml"
    fmu, data = REPO / "fmus" / "LSEA_MISO.fmu", MISO / "force_only.csv"
    assert main(["init", str(fmu), str(data), "-o", str(study)]) == 2
    err = capsys.readouterr().err
    assert "no column matches an output of LSEA_MISO.fmu (F_o)" in err and "--derived" in err
    assert not study.exists()
    assert main(["init", str(fmu), str(data), "-o", str(study), "--derived", "F_o=F_of - F_or",
                 "--derived", "v_o=der(x_o)", "--derived", "a_o=der(x_o, 2)"]) == 0  # fmt: skip
    text = study.read_text()
    assert 'inputs = { F_m = "F_m", x_o = "x_o", v_o = "v_o", a_o = "a_o" }' in text
    # with x_o, v_o and a_o given, m2 and C_2 act on nothing these data hold: init's
    # screening holds them (they move the outputs by 0 noise²)
    for name in ("m2", "C_2"):
        line = next(x for x in text.splitlines() if x.startswith(f"# {name} = "))
        assert "no effect the data can see" in line and "by 0 noise²" in line
    res = _identify_one_iteration(study, tmp_path)
    assert set(res["params"]) == {"m1", "K_s", "C_d", "C_1"}


@pytest.mark.skipif(not pythonfmu_available(), reason="pythonfmu cannot build here")
def test_init_pythonfmu_round_trip_matches_columns_case_insensitively(tmp_path):
    fmu = build_pythonfmu(tmp_path)
    t = np.arange(0, 2.0 + 1e-9, 0.01)
    u = np.where(t < 1.0, 1.0, -0.5)
    y = np.zeros_like(t)
    for k in range(1, len(t)):
        y[k] = y[k - 1] + 0.01 * (u[k - 1] - y[k - 1]) / 0.4
    y += np.random.default_rng(1).normal(0, 0.005, y.shape)
    pd.DataFrame({"Time": t, "U": u, "Y": y}).to_csv(tmp_path / "lag.csv", index=False)
    study = tmp_path / "study.toml"
    assert main(["init", str(fmu), str(tmp_path / "lag.csv"), "-o", str(study)]) == 0
    text = study.read_text()
    assert 'time = "Time"' in text and 'inputs = { u = "U" }' in text
    assert 'outputs = { y = "Y" }' in text and "tau = { levels = [0.3162," in text
    res = _identify_one_iteration(study, tmp_path)
    assert set(res["params"]) == {"tau"}


@pytest.mark.slow
def test_identify_headline_agrees_with_the_exit_status(tmp_path, capsys):
    study = tmp_path / "study.toml"
    main(["init", str(REPO / "fmus" / "LSEA_SISO.fmu"), str(SISO / "measured.csv"),
          "-o", str(study)])  # fmt: skip
    capsys.readouterr()
    res = _identify_one_iteration(study, tmp_path)
    out = capsys.readouterr().out
    code = {0: 0, 1: 1, 2: 3}[res["status"]]
    start = {0: "converged: ", 1: "stopped", 2: "paused for review"}[res["status"]]
    verdict = [x for x in out.splitlines() if x.endswith(f"(exit status {code})")]
    assert len(verdict) == 1 and verdict[0].startswith(start), out
    assert "report: " in out and "report.html" in out
    # numbers are rounded (5 significant figures)
    table = out.split("\n\n")[0]
    assert all(len(tok.replace(".", "").lstrip("0")) <= 6 for tok in table.split()
               if tok.replace(".", "").isdigit())  # fmt: skip


def test_progress_shows_each_slow_run_with_the_time_left():
    now = [0.0]
    out = io.StringIO()
    progress = ConsoleProgress(out, clock=lambda: now[0])
    progress("iteration", {"stage": "taguchi", "iteration": 1})
    for done in (1, 2, 3):
        now[0] += 2.0
        progress("row", {"stage": "taguchi", "iteration": 1, "done": done, "total": 4})
    lines = out.getvalue().splitlines()
    assert lines[1] == "  run 1/4 done (2.0 s per run, about 6 s left)"
    assert lines[3] == "  run 3/4 done (2.0 s per run, about 2 s left)"
    fast = io.StringIO()
    progress = ConsoleProgress(fast, clock=lambda: now[0])
    progress("iteration", {"stage": "taguchi", "iteration": 2})
    now[0] += 0.05
    progress("row", {"stage": "taguchi", "iteration": 2, "done": 1, "total": 4})
    assert len(fast.getvalue().splitlines()) == 1  # fast runs: no line per run


def test_the_last_progress_line_counts_one_iteration_in_the_singular():
    out = io.StringIO()
    progress = ConsoleProgress(out, clock=lambda: 0.0)
    for nit in (1, 2):
        res = argparse.Namespace(message="converged", nit=nit, nfev=149)
        progress("done", {"result": res})
    assert out.getvalue().splitlines() == [
        "converged (1 Taguchi iteration, 0.0 s)",  # the message says the simulations
        "converged (2 Taguchi iterations, 0.0 s)",
    ]


def test_info_escapes_control_characters_from_the_model_description(tmp_path, capsys):
    import zipfile

    src = REPO / "fmus" / "LSEA_SISO.fmu"
    fmu = tmp_path / "odd.fmu"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(fmu, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                name = text.index('modelName="') + len('modelName="')
                text = text[:name] + "A&#10;B&#x9b;2J" + text[text.index('"', name) :]
                text = text.replace(
                    'description="Stiffness of the series spring"',
                    'description="stiff&#x202e;ness"',
                )
                data = text.encode()
            zout.writestr(item, data)
    assert main(["info", str(fmu)]) == 0
    out = capsys.readouterr().out
    assert "\x9b" not in out and "\u202e" not in out
    assert "Model name       A\\nB\\x9b2J" in out.splitlines()
    assert any(
        line.startswith("  K_s") and line.endswith("stiff\\u202eness") for line in out.splitlines()
    )
