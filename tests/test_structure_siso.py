"""The SISO plant's friction law chosen from independent data (``benchmarks/structure.py
--quick``: one noise seed per true law).

Data from ``examples/lsea_siso/friction_laws.py`` (not the FMU); model
``fmus/LSEA_SISO_Friction.fmu``. Each true law must be chosen, or the candidates reported
indistinguishable; the parameters within the chosen law must reach SciPy's least-squares
optimum at that law (cost within 1.001x).
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

LAW1_LOCAL_MINIMUM = (
    "measured (benchmarks/structure.py --quick, seed 1): the mixed arrays fix friction=3, "
    "which nests law 1, and the simpler candidate's refinement stops far from its optimum "
    "(BIC 3.46e5 above), so 3 is chosen; the naive route picks 1"
)
LAW2_LOCAL_MINIMUM = (
    "measured (benchmarks/structure.py --quick, seed 1): the candidate friction=2, refined "
    "from levels centred on the mixed arrays' best point in it, stops in a local minimum "
    "(cost 64929 against 16925 for friction=3, which nests it), so BIC picks 3; the naive "
    "study of law 2 from the Table I centre reaches the optimum and picks 2"
)

LAW3_MISSED = (
    "measured (benchmarks/structure.py --quick, seed 1): the structure route chose "
    "friction=1 (LRT against 2, p = 0.88) on Stribeck data, where the naive law-3 study "
    "picks 3 by BIC"
)


def _bench():
    path = ROOT / "benchmarks" / "structure.py"
    spec = importlib.util.spec_from_file_location("bench_structure_siso", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


@pytest.mark.slow
@pytest.mark.parametrize(
    "law",
    [
        pytest.param(1, marks=pytest.mark.xfail(reason=LAW1_LOCAL_MINIMUM, strict=True)),
        pytest.param(2, marks=pytest.mark.xfail(reason=LAW2_LOCAL_MINIMUM, strict=True)),
        pytest.param(3, marks=pytest.mark.xfail(reason=LAW3_MISSED, strict=True)),
    ],
)
def test_quick_structure_benchmark_chooses_the_true_friction_law(law):
    r = _bench().one(law, 1, workers=1)
    assert r["chosen"] == law or r["tied"], r
    assert r["ratio"] <= 1.001, r
    if r["chosen"] == law:
        assert math.isfinite(r["error"])
