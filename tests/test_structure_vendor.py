"""A vendor-style FMU with an Integer switch (built here with pythonfmu), its structure and
parameters identified through the command line (``tsid identify study.toml``) from data
of an independent SciPy simulation.

The FMU: ``tau v' = u - v - law * q v |v|``: ``law = 0`` linear damping, ``law = 1``
adds quadratic drag (``q`` acts only there; ``law = 1`` nests ``law = 0`` at ``q = 0``).
The data come from ``law = 1``; the study must choose it, with ``tau`` and ``q``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jsonschema
import numpy as np
import pandas as pd
import pytest
from fmu_factory import pythonfmu_available
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
TRUTH = {"tau": 0.4, "q": 0.8, "law": 1}

SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real


class Drag(Fmi2Slave):
    """tau v' = u - v - law q v |v| (RK4, 20 steps per communication step)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u, self.v, self.tau, self.q, self.law = 0.0, 0.0, 1.0, 0.5, 0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("v", causality=Fmi2Causality.output))
        for name in ("tau", "q"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))
        self.register_variable(Integer("law", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed))

    def _f(self, v):
        drag = self.q * v * abs(v) if self.law == 1 else 0.0
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
[study]
fmu = "Drag.fmu"
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
law = { choices = [0, 1] }
"""


def _data(folder: Path) -> None:
    """The truth simulated by SciPy (input held over each sample), plus noise."""
    t = np.arange(0.0, 3.0 + 1e-9, 0.01)
    u = np.where((t % 1.0) < 0.5, 2.0, -1.0)
    v, out = 0.0, [0.0]
    for k in range(len(t) - 1):

        def f(_, y, uk=u[k]):
            return [(uk - y[0] - TRUTH["q"] * y[0] * abs(y[0])) / TRUTH["tau"]]

        v = solve_ivp(f, (t[k], t[k + 1]), [v], rtol=1e-11, atol=1e-13).y[0, -1]
        out.append(v)
    y = np.array(out) + np.random.default_rng(5).normal(0.0, 0.01, t.size)
    pd.DataFrame({"time": t, "u": u, "v": y}).to_csv(folder / "d.csv", index=False)


@pytest.mark.slow
@pytest.mark.skipif(not pythonfmu_available(), reason="pythonfmu cannot build here")
def test_the_cli_chooses_the_integer_switch_of_a_vendor_fmu(tmp_path):
    script = tmp_path / "drag_slave.py"
    script.write_text(textwrap.dedent(SLAVE))
    built = subprocess.run(
        [sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(tmp_path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert built.returncode == 0, built.stderr
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
    jsonschema.validate(summary, schema)  # the structure entry as the schema describes it
    structure = summary["structure"]
    assert structure["chosen"] == "law=1" and structure["choices"] == {"law": "1"}
    assert summary["parameters"]["law"]["value"] == 1.0
    assert summary["parameters"]["tau"]["value"] == pytest.approx(TRUTH["tau"], rel=0.02)
    assert summary["parameters"]["q"]["value"] == pytest.approx(TRUTH["q"], rel=0.05)
    rows = {r["structure"]: r for r in structure["table"]}
    assert rows["law=0"]["k"] == 1 and rows["law=1"]["k"] == 2  # q acts only with law=1
    assert rows["law=1"]["BIC"] < rows["law=0"]["BIC"] and rows["law=1"]["chosen"]
    text = (out / "report.html").read_text(encoding="utf-8")
    assert "Discrete factors: response per level" in text and "law=0" in text
    from tsid_fmu import load

    back = load(out)  # result.json read back with its structures
    assert back.params["law"] == 1.0 and back.structures == structure["table"]
    assert back.structure["chosen"] == "law=1" and not back.warnings
    again = subprocess.run(
        [sys.executable, "-m", "tsid_fmu", "simulate", str(tmp_path / "study.toml"),
         "--result", str(out), "--plot", str(tmp_path / "fit.png")],
        capture_output=True, text=True, check=False, env=env, timeout=300,
    )  # fmt: skip
    assert again.returncode == 0, again.stderr  # the chosen law is set as identified
    assert "law=1" in again.stdout and "simulated every experiment" in again.stdout
