"""A vendor-style FMU with an Integer switch whose richer law nests the other at a bound.

The FMU (``tests/test_structure_vendor.py``'s pythonfmu slave): ``tau v' = u - v - law q
v |v|``. ``law = 0`` is linear damping and ``q`` has no effect there; ``law = 1`` adds
quadratic drag, and at ``q = 0`` (its bound ``min = 0``) it is ``law = 0``. So a study
choosing the law meets both cases of issue 65:

- data of ``law = 0``: the chosen structure leaves ``q`` without a value, and the design
  must work from that result (a structure whose parameter vanishes);
- the nesting test between the laws counts ``q`` as a parameter ``law = 1`` may move,
  wherever its fit put it (a nesting at a bound).

Data: SciPy's ``solve_ivp`` (``rtol`` 1e-11) with the input held over each 10 ms
sample, and Gaussian noise of 0.01 (seeded): a square wave of 2 and -1 at 1 Hz, 3 s.
Used by ``benchmarks/design.py --case drag``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from test_structure_vendor import SLAVE, STUDY  # the test's FMU and study

from problems.motor_speed import build_slave

TRUTHS = {0: {"tau": 0.4, "q": 0.0, "law": 0}, 1: {"tau": 0.4, "q": 0.8, "law": 1}}
"""The truth of each law the data are made with."""
NOISE = 0.01
"""The speed sensor's noise (the study states it)."""
DESIGN = '[design]\ninputs = { u = [-2.0, 2.0] }\nbands = 1\nkinds = ["chirp"]\n'
"""The rig's limits for ``tsid design``."""


def response(t: np.ndarray, u: np.ndarray, truth: dict[str, float]) -> np.ndarray:
    """The speed for ``u`` held over each sample, from rest."""
    v, out = 0.0, [0.0]
    q = truth["q"] if truth["law"] == 1 else 0.0
    for k in range(len(t) - 1):

        def f(_, y, uk=u[k]):
            return [(uk - y[0] - q * y[0] * abs(y[0])) / truth["tau"]]

        v = solve_ivp(f, (t[k], t[k + 1]), [v], rtol=1e-11, atol=1e-13).y[0, -1]
        out.append(v)
    return np.array(out)


def build(folder: Path) -> Path:
    """Build ``Drag.fmu`` into ``folder`` with pythonfmu; return its path."""
    return build_slave(folder, SLAVE, "Drag")


def write_case(folder: Path, law: int, seed: int) -> Path:
    """Write data of ``law`` with noise ``seed`` and the study into ``folder``."""
    t = np.arange(0.0, 3.0 + 1e-9, 0.01)
    u = np.where((t % 1.0) < 0.5, 2.0, -1.0)
    y = response(t, u, TRUTHS[law]) + np.random.default_rng(seed).normal(0.0, NOISE, t.size)
    pd.DataFrame({"time": t, "u": u, "v": y}).to_csv(folder / "d.csv", index=False)
    study = folder / "study.toml"
    study.write_text(
        STUDY + '[design]\ninputs = { u = [-2.0, 2.0] }\nbands = 1\nkinds = ["chirp"]\n'
    )
    return study
