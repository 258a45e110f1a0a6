"""``tsid init`` screens the candidates at their start values (issue 62, item 3).

Measured on vendor FMUs, ``init`` freed every parameter its metadata rules did not hold:
a Hopsan volume's study with parameters that act on nothing ran its arrays to their
limit (1498 simulations, where the hand study needs 41). Now ``2 p + 1`` simulations at
the start values decide: a parameter whose first levels move the outputs by less than
``chi2_1(0.95)`` noise² is held ("no effect"), and one whose change across its first
range those already free reproduce is held as acting only in combination with them,
naming which member is free.

The plant here is a lag whose gain is the product ``ka kb``, beside ``spare``, which acts
on nothing; its data are the FMU's own at ``tau = 0.8``, ``ka kb = 7.5``, with 1 % noise.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("pymoca")
pytest.importorskip("casadi")
if shutil.which("cc") is None and shutil.which("gcc") is None:  # pragma: no cover
    pytest.skip("no C compiler", allow_module_level=True)

from fmpy import simulate_fmu

from tsid_fmu import Study
from tsid_fmu.build import build_fmu
from tsid_fmu.errors import FMUError
from tsid_fmu.scaffold import init_study
from tsid_fmu.scaffold_screen import SIGNIFICANT, _judge

MODEL = """
model Screened "A lag whose gain is a product of two parameters, beside one that acts on nothing"
  parameter Real tau = 0.5 "Time constant";
  parameter Real ka = 2 "Gain, first factor";
  parameter Real kb = 3 "Gain, second factor";
  parameter Real spare = 1 "Acts on nothing";
  input Real u "Input";
  output Real y "Output";
  Real x(start = 0, fixed = true) "State";
equation
  tau * der(x) = ka * kb * u - x;
  y = x;
end Screened;
"""
TAU, GAIN = 0.8, 7.5


@pytest.fixture(scope="module")
def plant(tmp_path_factory) -> tuple[Path, Path]:
    """The FMU and its measured data (the FMU's own at the truth, 1 % noise)."""
    d = tmp_path_factory.mktemp("screened")
    (d / "Screened.mo").write_text(MODEL)
    fmu = build_fmu(d / "Screened.mo", "Screened", d / "Screened.fmu", step_size=1e-3)
    t = np.arange(0.0, 10.0 + 1e-9, 0.01)
    u = np.sin(2 * np.pi * 0.3 * t) + 0.5 * np.sin(2 * np.pi * 1.1 * t + 1)
    sig = np.array(list(zip(t, u, strict=True)), dtype=[("time", float), ("u", float)])
    truth = {"tau": TAU, "ka": 2.5, "kb": GAIN / 2.5}
    r = simulate_fmu(str(fmu), start_values=truth, input=sig, output_interval=0.01, stop_time=10)
    y = np.interp(t, r["time"], r["y"])
    noise = 0.01 * np.std(y) * np.random.default_rng(1).standard_normal(t.size)
    pd.DataFrame({"time": t, "u": u, "y": y + noise}).to_csv(d / "data.csv", index=False)
    return fmu, d / "data.csv"


def _free(text: str) -> list[str]:
    block = text.split("\n[parameters]\n", 1)[1]
    return [line.split(" = ", 1)[0] for line in block.splitlines() if line and line[0] != "#"]


def _held(text: str, name: str) -> str:
    return next(line for line in text.splitlines() if line.startswith(f"# {name} = "))


def test_the_screening_holds_what_acts_on_nothing_and_one_member_of_a_product(plant, tmp_path):
    fmu, data = plant
    text = init_study(fmu, data, tmp_path / "study.toml", workers=1)
    assert _free(text) == ["tau", "ka"]
    assert "no effect the data can see" in _held(text, "spare")
    assert "acts only together with ka" in _held(text, "kb") and "ka is free" in _held(text, "kb")
    assert "# screened: 9 simulations at the start values; 2 of 4 candidates" in text
    assert Study.from_toml(tmp_path / "study.toml").parameter_names == ["tau", "ka"]


def test_the_screened_study_identifies_the_product(plant, tmp_path):
    """The held member keeps the FMU's value; the free one carries the product."""
    fmu, data = plant
    init_study(fmu, data, tmp_path / "study.toml", workers=1)
    out = tmp_path / "out"
    run = subprocess.run(
        [sys.executable, "-m", "tsid_fmu", "identify", str(tmp_path / "study.toml"),
         "--out", str(out), "-q", "--workers", "1"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    x = dict(zip(["tau", "ka"], json.loads((out / "result.json").read_text())["x"], strict=True))
    assert x["tau"] == pytest.approx(TAU, rel=0.01)
    assert x["ka"] * 3.0 == pytest.approx(GAIN, rel=0.01)  # kb held at the FMU's 3


def test_no_screen_frees_every_candidate(plant, tmp_path):
    fmu, data = plant
    text = init_study(fmu, data, tmp_path / "study.toml", screen=False)
    assert _free(text) == ["tau", "ka", "kb", "spare"]
    assert "# screened:" not in text and "# not screened:" not in text


def test_a_screening_that_cannot_run_frees_every_candidate_and_says_why(
    plant, tmp_path, monkeypatch
):
    import tsid_fmu.screening.run as run

    def broken(study, runner):
        raise FMUError("Screened.fmu: cannot load the shared library")

    monkeypatch.setattr(run, "study_evaluator", broken)
    fmu, data = plant
    text = init_study(fmu, data, tmp_path / "study.toml")
    assert _free(text) == ["tau", "ka", "kb", "spare"]
    assert "# not screened: Screened.fmu: cannot load the shared library" in text


def test_the_cli_shows_the_screening_off_a_terminal(plant, tmp_path):
    fmu, data = plant
    run = subprocess.run(
        [sys.executable, "-m", "tsid_fmu", "init", str(fmu), str(data), "-o",
         str(tmp_path / "s.toml"), "--workers", "1"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "screening the parameters: 9/9 simulations (done)" in run.stderr
    assert "(screened: 9 simulations" in run.stdout
    quiet = subprocess.run(
        [sys.executable, "-m", "tsid_fmu", "init", str(fmu), str(data), "-o",
         str(tmp_path / "q.toml"), "-q", "--no-screen"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert quiet.returncode == 0 and quiet.stderr == ""
    assert _free((tmp_path / "q.toml").read_text()) == ["tau", "ka", "kb", "spare"]


# the rule itself, on residuals made by hand (noise units)
R0 = np.zeros(50)
E1 = np.eye(50)[0] * 10.0
E2 = np.eye(50)[1] * 10.0


def test_the_rule_holds_below_the_significant_change_only():
    small = np.full(50, np.sqrt(0.99 * SIGNIFICANT / 50))  # just below it
    big = np.full(50, np.sqrt(1.01 * SIGNIFICANT / 50))  # just above it
    effect, held = _judge(["a", "b"], R0, [-small, small, -big, big])
    assert effect["a"] == pytest.approx(0.99 * SIGNIFICANT)
    assert list(held) == ["a"] and "no effect" in held["a"]


def test_the_rule_holds_a_member_only_where_the_free_ones_reproduce_it():
    # b is a times 0.5 (a product's other factor), c is independent, d nearly a's copy
    # with an own part of 2 noise² (held) and e with one of 5 (free)
    tilt2 = np.eye(50)[2] * np.sqrt(2.0)
    tilt5 = np.eye(50)[3] * np.sqrt(5.0)
    half = 0.5 * E1
    ends = [-E1, E1, -half, half, -E2, E2, -half - tilt2 / 2, half + tilt2 / 2,
            -half - tilt5 / 2, half + tilt5 / 2]  # fmt: skip
    _, held = _judge(["a", "b", "c", "d", "e"], R0, ends)
    assert set(held) == {"b", "d"}
    assert "acts only together with" in held["b"] and "a is free" in held["b"]


def test_a_run_that_fails_at_an_end_keeps_the_parameter_free():
    effect, held = _judge(["a", "b"], R0, [None, E1, -E1, E1])
    assert effect["a"] == np.inf and held == {}  # no secant of a: b is not compared with it


def test_the_tutorial_siso_init_screens_eleven_and_frees_all_five(tmp_path):
    """docs/tutorial/first-identification.md: "11 simulations here ... all five stay free"."""
    root = Path(__file__).resolve().parents[1]
    text = init_study(
        root / "fmus" / "LSEA_SISO.fmu",
        root / "examples" / "lsea_siso" / "measured.csv",
        tmp_path / "study.toml",
        workers=1,
    )
    assert "# screened: 11 simulations at the start values; 5 of 5 candidates" in text
    assert _free(text) == ["F_cm", "F_vm", "M_m", "K_s", "B_s"]
    page = (root / "docs" / "tutorial" / "first-identification.md").read_text()
    assert "(11 simulations here)" in page and "all five stay free" in page
