"""A DC motor measured by its speed only: a structural symmetry in two directions.

Model (the FMU, a pythonfmu slave, RK4 with ten sub-steps per sample):
``L di/dt = V - R i - Kt w`` and ``J dw/dt = Kt i - b w``, from rest. From the voltage to
the speed the transfer function is ``Kt / (J L s^2 + (J R + b L) s + (b R + Kt^2))``:
three coefficients for five parameters, so two directions of the parameters leave the
speed unchanged and no input removes them (issue 65, case B). The data determine the
three coefficients (:func:`coefficients`): ``J L / Kt``, ``(J R + b L) / Kt`` and
``(b R + Kt^2) / Kt``.

Data: the same equations solved by SciPy's ``solve_ivp`` (``rtol`` 1e-10) with the
voltage held over each 5 ms sample (12 V and -6 V square wave at 1 Hz plus a 3 V sine
at 11 rad/s, 3 s), and Gaussian noise of 1 % of the speed's spread (seeded).

Used by ``benchmarks/design.py --case motor`` and ``tests/test_design_symmetry.py``.
"""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

TRUTH = {"R": 2.0, "L": 0.1, "Kt": 0.5, "J": 0.02, "b": 0.05}
"""The motor the data are made with (SI units)."""

SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class Motor(Fmi2Slave):
    """L i' = V - R i - Kt w, J w' = Kt i - b w (RK4, ten sub-steps per step)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.V, self.w, self.i = 0.0, 0.0, 0.0
        self.R, self.L, self.Kt, self.J, self.b = 1.0, 0.1, 0.1, 0.01, 0.01
        self.register_variable(Real("V", causality=Fmi2Causality.input))
        self.register_variable(Real("w", causality=Fmi2Causality.output))
        for name in ("R", "L", "Kt", "J", "b"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))

    def _f(self, i, w):
        return ((self.V - self.R * i - self.Kt * w) / self.L,
                (self.Kt * i - self.b * w) / self.J)

    def do_step(self, current_time, step_size):
        h = step_size / 10
        for _ in range(10):
            i, w = self.i, self.w
            a1, b1 = self._f(i, w)
            a2, b2 = self._f(i + 0.5 * h * a1, w + 0.5 * h * b1)
            a3, b3 = self._f(i + 0.5 * h * a2, w + 0.5 * h * b2)
            a4, b4 = self._f(i + h * a3, w + h * b3)
            self.i += h * (a1 + 2 * a2 + 2 * a3 + a4) / 6
            self.w += h * (b1 + 2 * b2 + 2 * b3 + b4) / 6
        return True
'''

STUDY = """\
[study]
fmu = "Motor.fmu"
[data]
file = "d.csv"
inputs = {{ V = "V" }}
outputs = {{ w = "w" }}
[method]
fidelity = false
seed = {seed}
[parameters]
R = {{ levels = [0.5, 2.0, 8.0], min = 0 }}
L = {{ levels = [0.02, 0.1, 0.5], min = 0 }}
Kt = {{ levels = [0.1, 0.5, 2.0], min = 0 }}
J = {{ levels = [0.005, 0.02, 0.08], min = 0 }}
b = {{ levels = [0.01, 0.05, 0.2], min = 0 }}
[design]
inputs = {{ V = [-12.0, 12.0] }}
"""
"""The study a user would write: a decade around a guess of each parameter."""


def coefficients(p: dict[str, float]) -> dict[str, float]:
    """The three coefficients the speed determines, of the transfer function over ``Kt``."""
    return {
        "J L / Kt": p["J"] * p["L"] / p["Kt"],
        "(J R + b L) / Kt": (p["J"] * p["R"] + p["b"] * p["L"]) / p["Kt"],
        "(b R + Kt^2) / Kt": (p["b"] * p["R"] + p["Kt"] ** 2) / p["Kt"],
    }


def value_of(combo: dict, p: dict[str, float]) -> float:
    """A combination the design names (its ``form`` and ``coefficients``) at ``p``."""
    c = combo["coefficients"]
    if combo["form"] == "product":
        return math.prod(p[n] ** e for n, e in c.items())
    if combo["form"] == "sum of products":
        return sum(math.prod(p[n] ** e for n, e in term.items()) for term in c)
    return sum(w * p[n] for n, w in c.items())


def speed(t: np.ndarray, v: np.ndarray, p: dict[str, float]) -> np.ndarray:
    """The speed at ``t`` for the voltage ``v`` held over each sample, from rest."""
    state, out = np.zeros(2), [0.0]
    for k in range(len(t) - 1):

        def f(_, s, vk=v[k]):
            i, w = s
            return [(vk - p["R"] * i - p["Kt"] * w) / p["L"], (p["Kt"] * i - p["b"] * w) / p["J"]]

        state = solve_ivp(f, (t[k], t[k + 1]), state, rtol=1e-10, atol=1e-12).y[:, -1]
        out.append(state[1])
    return np.array(out)


def build_slave(folder: Path, source: str, stem: str) -> Path:
    """Build the pythonfmu slave ``source`` (its class named ``stem``) into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    script = folder / f"{stem.lower()}_slave.py"
    script.write_text(textwrap.dedent(source))
    subprocess.run(
        [sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(folder)],
        check=True, capture_output=True,
    )  # fmt: skip
    return folder / f"{stem}.fmu"


def build(folder: Path) -> Path:
    """Build ``Motor.fmu`` into ``folder`` with pythonfmu; return its path."""
    return build_slave(folder, SLAVE, "Motor")


def write_case(folder: Path, seed: int = 1) -> Path:
    """Write the data of noise ``seed`` and the study into ``folder``; return the study."""
    t = np.arange(0.0, 3.0 + 1e-9, 0.005)
    v = np.where((t % 1.0) < 0.5, 12.0, -6.0) + 3.0 * np.sin(11 * t)
    w = speed(t, v, TRUTH)
    w = w + np.random.default_rng(seed).normal(0.0, 0.01 * np.std(w), w.shape)
    pd.DataFrame({"time": t, "V": v, "w": w}).to_csv(folder / "d.csv", index=False)
    study = folder / "study.toml"
    study.write_text(STUDY.format(seed=seed))
    return study
