"""A choice among FMU files (``model = { fmus = [...] }``): two vendor-style variants
(built here with pythonfmu), the structure and the parameters identified through the
command line from data of an independent SciPy simulation.

``Linear.fmu``: ``tau v' = u - v`` (``tau`` only). ``Drag.fmu``: ``tau v' = u - v - q v
|v|`` (``tau`` and ``q``; at ``q = 0`` it is the linear one). The data come from the drag
model; the study must choose ``Drag`` and find ``q``, which ``Linear`` does not have.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import jsonschema
import pandas as pd
import pytest
from fmu_factory import build_c_fmu, pythonfmu_available
from test_structure_vendor import TRUTH, _data  # the same drag truth and data

from tsid_fmu import Study
from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.variants import Variants
from tsid_fmu.study.choice import ModelChoice

ROOT = Path(__file__).resolve().parents[1]

SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

DRAG = {drag}


class {name}(Fmi2Slave):
    """tau v' = u - v (- q v |v| in Drag), RK4 with 20 steps per communication step."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u, self.v, self.tau, self.q = 0.0, 0.0, 1.0, 0.5
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("v", causality=Fmi2Causality.output))
        for name in ("tau", "q") if DRAG else ("tau",):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))

    def _f(self, v):
        drag = self.q * v * abs(v) if DRAG else 0.0
        return (self.u - v - drag) / self.tau

    def do_step(self, current_time, step_size):
        h = step_size / 20
        for _ in range(20):
            k1 = self._f(self.v)
            k2 = self._f(self.v + 0.5 * h * k1)
            k3 = self._f(self.v + 0.5 * h * k2)
            k4 = self._f(self.v + h * k3)
            self.v += h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        return True
'''

STUDY = """\
[data]
file = "d.csv"
inputs = { u = "u" }
outputs = { v = "v" }
noise = { v = 0.01 }
[method]
cost = "sse"
weighting = "noise"
replicates = 1
start = "centre"
fidelity = false
[parameters]
tau = { levels = [0.2, 0.5, 1.0], min = 0.01 }
q = { levels = [0.1, 0.4, 1.0], min = 0, max = 5 }
model = { fmus = ["Linear.fmu", "Drag.fmu"] }
"""


def _build(folder: Path, name: str, drag: bool) -> None:
    script = folder / f"{name.lower()}_slave.py"
    script.write_text(textwrap.dedent(SLAVE.format(name=name, drag=drag)))
    built = subprocess.run(
        [sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(folder)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert built.returncode == 0, built.stderr


def test_variants_route_a_set_by_its_number_and_keep_what_the_variant_has():
    v = Variants(
        "model", (Path("a.fmu"), Path("b.fmu")), (frozenset({"tau"}), frozenset({"tau", "q"}))
    )
    assert v.index({"model": 1.0}) == 1 and v.index({"model": 0}) == 0
    for bad in ({"model": 2.0}, {"model": 0.5}, {}):
        with pytest.raises(StudyError, match="names no FMU variant"):
            v.index(bad)
    values = {"tau": 0.4, "q": 0.8, "model": 0.0, "delay(u)": 0.1}
    assert v.keep(0, values) == {"tau": 0.4, "delay(u)": 0.1}  # neither q nor the number
    assert v.keep(1, values) == {"tau": 0.4, "q": 0.8, "delay(u)": 0.1}


def test_a_choice_among_fmu_files_is_read_checked_and_written_back(tmp_path):
    for name in ("LagA", "LagB"):
        build_c_fmu(tmp_path, name)
    pd.DataFrame({"time": [0.0, 0.1, 0.2], "u": [1.0, 1.0, 1.0], "y": [0, 0.1, 0.2]}).to_csv(
        tmp_path / "d.csv", index=False
    )
    text = """\
[data]
file = "d.csv"
inputs = { u = "u" }
outputs = { y = "y" }
[parameters]
tau = { levels = [0.5, 1.0, 2.0], min = 0.01 }
variant = { fmus = ["LagA.fmu", "LagB.fmu"] }
"""
    (tmp_path / "s.toml").write_text("[study]\n" + text)
    study = Study.from_toml(tmp_path / "s.toml")  # no [study] fmu: the first variant's
    model = study.choices[0]
    assert isinstance(model, ModelChoice) and study.variants is model
    assert model.labels == ["LagA", "LagB"] and model.values == [0.0, 1.0]
    assert study.fmu == (tmp_path / "LagA.fmu").resolve()
    assert Study.from_toml(study.to_toml(tmp_path / "back" / "s.toml")) == study
    # the file, the name and the clash are named in the messages
    (tmp_path / "s.toml").write_text("[study]\n" + text.replace("LagB.fmu", "Nope.fmu"))
    with pytest.raises(StudyError, match=r"\[parameters\] variant.*Nope\.fmu"):
        Study.from_toml(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text("[study]\n" + text.replace("variant = {", "gain = {"))
    with pytest.raises(StudyError, match="has a variable named 'gain'"):
        Study.from_toml(tmp_path / "s.toml")
    fixed = Study(study.fmu, study.parameters, study.experiments, variants=model,
                  start_values={"variant": 1})  # fmt: skip
    assert fixed.simulated_fmu == (tmp_path / "LagB.fmu").resolve()
    with pytest.raises(StudyError, match="must be one of \\[0, 1\\]"):
        Study(study.fmu, study.parameters, study.experiments, variants=model,
              start_values={"variant": 2})  # fmt: skip


@pytest.mark.slow
@pytest.mark.skipif(not pythonfmu_available(), reason="pythonfmu cannot build here")
def test_the_cli_chooses_among_fmu_files(tmp_path):
    _build(tmp_path, "Linear", False)
    _build(tmp_path, "Drag", True)
    _data(tmp_path)
    (tmp_path / "study.toml").write_text(STUDY)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = tmp_path / "out"
    run = subprocess.run(
        [sys.executable, "-m", "tsid_fmu", "identify", str(tmp_path / "study.toml"),
         "--out", str(out), "--json", "-q", "--workers", "1"],
        capture_output=True, text=True, check=False, env=env, timeout=900,
    )  # fmt: skip
    assert run.returncode in (0, 1), run.stderr
    summary = json.loads(run.stdout)
    schema = json.loads((ROOT / "tsid_fmu" / "schemas" / "result-summary.schema.json").read_text())
    jsonschema.validate(summary, schema)
    structure = summary["structure"]
    assert structure["chosen"] == "model=Drag" and structure["choices"] == {"model": "Drag"}
    assert summary["parameters"]["tau"]["value"] == pytest.approx(TRUTH["tau"], rel=0.02)
    assert summary["parameters"]["q"]["value"] == pytest.approx(TRUTH["q"], rel=0.05)
    rows = {r["structure"]: r for r in structure["table"]}
    assert rows["model=Linear"]["k"] == 1 and rows["model=Drag"]["k"] == 2  # q only in Drag
    assert rows["model=Drag"]["BIC"] < rows["model=Linear"]["BIC"] and rows["model=Drag"]["chosen"]
    with zipfile.ZipFile(out / "model.ssp") as ssp:  # the chosen file travels on
        names = ssp.namelist()
        ssv = ssp.read("resources/Drag.ssv").decode()
    assert "resources/Drag.fmu" in names and not any("Linear" in n for n in names)
    assert 'name="q"' in ssv and 'name="model"' not in ssv  # the number is no FMU value
    assert json.loads((out / "result.json").read_text())["fmu"].endswith("Drag.fmu")
    from tsid_fmu import load

    back = load(out)  # the folder read back, its study with the choice among the files
    assert back.params["model"] == 1.0 and back.structure["chosen"] == "model=Drag"
    again = subprocess.run(
        [sys.executable, "-m", "tsid_fmu", "simulate", str(tmp_path / "study.toml"),
         "--result", str(out), "--plot", str(tmp_path / "fit.png")],
        capture_output=True, text=True, check=False, env=env, timeout=300,
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert "model=Drag" in again.stdout and "simulated every experiment" in again.stdout
