"""A symmetry in two directions (issue 65, item 1 and case B): a DC motor measured by
its speed only, whose speed fixes three coefficients of five parameters.

The data: ``benchmarks/problems/motor_speed.py`` (SciPy's ``solve_ivp``, never the FMU).
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from fmu_factory import pythonfmu_available

from tsid_fmu import Study, identify
from tsid_fmu.design import design


def _load(path: Path):
    """Import a benchmark module by its path: with ``benchmarks/`` on ``sys.path``, its
    ``coverage.py`` hid the coverage package from numba in later tests."""
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


motor = _load(Path(__file__).resolve().parents[1] / "benchmarks" / "problems" / "motor_speed.py")

NAMES = ("R", "L", "Kt", "J", "b")


@pytest.fixture(scope="module")
def studied(tmp_path_factory):
    """The motor's study identified on noise seed 1, and its design."""
    if not pythonfmu_available():
        pytest.skip("pythonfmu cannot build here")
    tmp = tmp_path_factory.mktemp("motor")
    motor.build(tmp)
    study = Study.from_toml(motor.write_case(tmp, seed=1))
    # worker processes: a pythonfmu FMU loaded into this process can crash it when it is
    # unloaded (its embedded interpreter)
    result = identify(study, tmp / "out", plots=False, workers=2, timeout=0)
    return result, design(result, workers=2)


def _gradient(f, p: dict[str, float]) -> np.ndarray:
    """d f / d ln p_j at ``p`` (central differences)."""
    out = []
    for n in NAMES:
        up, down = dict(p), dict(p)
        up[n], down[n] = p[n] * 1.0001, p[n] / 1.0001
        out.append((f(up) - f(down)) / (2 * math.log(1.0001)))
    return np.array(out)


def test_the_study_leaves_every_parameter_open(studied):
    result, _ = studied
    assert all(None in result.intervals[n] for n in NAMES)
    assert sum(not c["determined"] for c in result.uncertainty.combinations) == 2


def test_the_design_calls_it_structural_and_proposes_nothing(studied):
    """Each weak direction is followed with the re-fit held off the other: the re-fit
    had slid along it (J to 48.5, then 1e300), so the first was "not flat" and a PRBS
    was proposed whose own prediction determined nothing more."""
    _, found = studied
    assert found.proposal is None and found.after is None
    (structural,) = found.structural
    assert sorted(structural.members) == sorted(NAMES) and len(structural.terms) == 2
    assert structural.tried is None  # no candidate moved it, not only the best one
    assert "fix 2 of them" in found.verdict


def test_a_proposal_whose_own_prediction_closes_nothing_is_withdrawn():
    """The safety net below the flat test: the study's open parameters all open in the
    prediction too (as the PRBS above predicted) is no proposal; one closed is one."""
    from types import SimpleNamespace

    run = sys.modules["tsid_fmu.design.run"]
    free, abc = (-math.inf, math.inf), ["a", "b", "c"]
    bounds = {"a": free, "b": free, "c": free}
    result = SimpleNamespace(intervals={"a": [None, 2.0], "b": [None, None], "c": [1.0, 3.0]})
    still = {"a": [None, 1.0], "b": [None, None], "c": [1.5, 2.5]}
    assert run._left_open(result, still, abc, bounds) == ["a", "b"]
    assert run._left_open(result, {**still, "b": [0.1, 9.0]}, abc, bounds) == []
    assert run._left_open(result, None, abc, bounds) == []
    closed = SimpleNamespace(intervals={"c": [1.0, 3.0]})
    assert run._left_open(closed, {"c": [1.5, 2.5]}, ["c"], bounds) == []  # nothing open
    # open only at its bound 0 (an offset at 0): closed, so never "left open"
    assert run._left_open(result, still, abc, {**bounds, "a": (0.0, math.inf)}) == ["b"]


def test_what_the_data_fix_is_the_three_coefficients_and_holds_the_truth(studied):
    """Three combinations, the transfer function's three coefficients (over ``Kt`` and
    ``J L``): the monomial ``L Kt^-1 J`` and the sums ``b / J + R / L`` and ``Kt + R b /
    Kt``; each interval holds its value at the truth, far along the symmetry from the
    answer. Named locally (linear combinations at the answer) they had excluded it on
    seven noise seeds of ten."""
    _, found = studied
    (structural,) = found.structural
    fixed = structural.fixed
    assert len(fixed) == 3
    assert fixed[0]["form"] == "product" and fixed[0]["coefficients"] == {
        "L": 1.0, "Kt": -1.0, "J": 1.0}  # fmt: skip
    assert [f["name"] for f in fixed[1:]] == ["J^-1 b + R L^-1", "Kt + R Kt^-1 b"]
    for combo in fixed:
        low, high = combo["interval"]
        assert low <= motor.value_of(combo, motor.TRUTH) <= high, combo
    named = np.array([_gradient(lambda p, c=c: math.log(abs(motor.value_of(c, p))), motor.TRUTH)
                      for c in fixed])  # fmt: skip
    truth = np.array([_gradient(lambda p, k=k: math.log(motor.coefficients(p)[k]), motor.TRUTH)
                      for k in motor.coefficients(motor.TRUTH)])  # fmt: skip
    # the same span: each coefficient's gradient is a combination of the named ones
    for g in truth:
        coef = np.linalg.lstsq(named.T, g, rcond=None)[0]
        assert np.linalg.norm(named.T @ coef - g) < 0.02 * np.linalg.norm(g)
