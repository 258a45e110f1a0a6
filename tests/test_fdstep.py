"""Finite-difference steps chosen from the FMU's own noise (``tsid_fmu.numerics.fdstep``)."""

from __future__ import annotations

import math
import zlib

import numpy as np
import pytest
from spec_helpers import CurveEvaluator

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.numerics.fdstep import MAX_STEP, solver_noise, steps_for
from tsid_fmu.search.local import problem
from tsid_fmu.search.local.refine import refine_stage
from tsid_fmu.search.space import Space
from tsid_fmu.study.schema import Method

T = np.linspace(0.0, 4.0, 60)
TRUTH = {"a": 2.0, "k": 1.3, "c": 0.4}
SCALE = 0.01
MEASURED = 2.0 * np.exp(-1.3 * T) + 0.4 + np.random.default_rng(3).normal(0.0, SCALE, T.size)
JITTER = 1e-5
"""An adaptive solver's error: a different pseudo-random error for every parameter set,
0.1 % of the noise (a step sequence that changes with the parameters)."""


def _smooth(a: float, k: float, c: float) -> np.ndarray:
    return a * np.exp(-k * T) + c


def _solver(a: float, k: float, c: float) -> np.ndarray:
    """The curve as an FMU with its own adaptive solver returns it."""
    seed = zlib.crc32(np.array([a, k, c]).tobytes())
    return _smooth(a, k, c) + np.random.default_rng(seed).normal(0.0, JITTER, T.size)


def _refine() -> tuple[dict[str, float], float, int]:
    space = Space(
        {"a": [1.0, 1.5, 3.0], "k": [0.5, 1.0, 2.0], "c": [0.0, 0.5, 1.0]},
        {n: (0.0, math.inf) for n in TRUTH},
        LevelingOptions(),
    )
    ev = CurveEvaluator(_solver, MEASURED, SCALE)
    method = Method(cost="sse", refine="least_squares", refine_max_nfev=500)
    out = refine_stage("refinement", space, {"a": 1.8, "k": 1.1, "c": 0.5}, math.inf, ev, method)
    return out.x, out.cost, out.status


def _optimum() -> tuple[np.ndarray, float]:
    from scipy.optimize import least_squares

    fit = least_squares(lambda v: (_smooth(*v) - MEASURED) / SCALE, [2.0, 1.3, 0.4], xtol=1e-14)
    return fit.x, float(2 * fit.cost)


def test_ecnoise_measures_the_solvers_noise_and_not_the_derivative():
    space = Space(
        {"a": [1.0, 3.0], "k": [0.5, 2.0], "c": [0.0, 1.0]},
        {n: (0.0, math.inf) for n in TRUTH},
        LevelingOptions(),
    )
    ev = CurveEvaluator(_solver, MEASURED, SCALE)
    s = space.to_s(TRUTH)

    def residuals(points):
        return [ev.residuals(space.to_x(p)) for p in points]

    found = solver_noise(residuals, s, residuals([s])[0], 1e-5, space.s_upper)
    assert found == pytest.approx(JITTER / SCALE, rel=0.35)  # 4 runs of 60 samples
    assert ev.nfev == 0 and len(residuals([s])) == 1
    smooth = CurveEvaluator(_smooth, MEASURED, SCALE)
    quiet = solver_noise(
        lambda pts: [smooth.residuals(space.to_x(p)) for p in pts],
        s,
        smooth.residuals(space.to_x(s)),
        1e-5,
        space.s_upper,
    )
    assert quiet < 1e-3 * JITTER / SCALE  # round-off only


def test_a_column_the_noise_spoils_gets_a_wider_step_and_a_clean_one_keeps_its_own():
    steps = np.full(2, 1e-5)
    n, noise = 100, 1e-4
    jac = np.column_stack([np.full(n, 10.0), np.full(n, 0.01)])  # norms 100 and 0.1
    wider = steps_for(steps, jac, noise)
    need = 100 * math.sqrt(2 * n) * noise / 100.0  # 1.4e-3 for the first column
    assert wider[0] == pytest.approx(need)
    assert wider[1] == MAX_STEP  # capped
    assert np.array_equal(steps_for(steps, jac, 0.0), steps)  # no noise: no change
    assert steps_for(steps, jac * 1e9, noise)[0] == 1e-5  # never shrinks


def test_the_refinement_finds_the_optimum_of_an_fmu_whose_solver_adds_noise(monkeypatch):
    best, best_cost = _optimum()
    x, cost, status = _refine()
    assert status == 0
    assert np.array([x[n] for n in TRUTH]) == pytest.approx(best, rel=2e-3)
    assert cost <= best_cost * 1.001
    # without the rule, forward differences of 1e-5 see the noise, not the slope: the
    # refinement stops far off (measured: cost 298 against 68, exit status 1)
    monkeypatch.setattr(problem, "steps_for", lambda steps, jac, noise: steps)
    x, cost, status = _refine()
    assert status != 0 and cost > 2 * best_cost


def test_forward_jacobian_runs_one_batch_and_steps_back_before_an_upper_bound():
    """The one forward-difference Jacobian (issue 61): a linear map's columns exactly,
    in one batch, the step at an upper bound taken backwards."""
    from tsid_fmu.numerics.fdstep import forward_jacobian

    a = np.array([[1.0, 2.0], [3.0, -1.0], [0.5, 4.0]])
    batches = []

    def run(points):
        batches.append(len(points))
        return [a @ p for p in points]

    z = np.array([0.2, 1.0])
    steps = np.array([1e-3, 1e-3])
    jac = forward_jacobian(run, z, a @ z, steps, upper=np.array([1.0, 1.0]))
    assert batches == [2]
    assert np.allclose(jac, a, rtol=1e-9)
    seen = []
    forward_jacobian(
        lambda pts: seen.extend(pts) or [a @ p for p in pts],
        z,
        a @ z,
        steps,
        upper=np.array([1.0, 1.0]),
    )
    assert seen[1][1] < 1.0 and seen[0][0] > z[0]  # backwards at the bound, forwards below
    one = forward_jacobian(run, z, a @ z, steps, which=np.array([1]))
    assert one.shape == (3, 1) and np.allclose(one[:, 0], a[:, 1])


def test_the_noise_is_kept_by_its_evaluator_not_by_a_module_cache():
    """The FMU's noise was a module-global weak-key cache (issue 61); it is now the
    evaluator's own ``fd_noise``: measured once per evaluator, never shared."""
    import weakref

    from tsid_fmu.numerics import fdstep

    assert not any(isinstance(v, weakref.WeakKeyDictionary) for v in vars(fdstep).values())
    first = CurveEvaluator(_smooth, MEASURED, SCALE)
    second = CurveEvaluator(_smooth, MEASURED, SCALE)
    calls = []

    def measure(value):
        return lambda: calls.append(value) or value

    assert fdstep.known_noise(first) == 0.0
    assert fdstep.noise_of(first, measure(0.25)) == 0.25
    assert fdstep.noise_of(first, measure(9.0)) == 0.25  # measured once
    assert fdstep.known_noise(first) == 0.25 and first.fd_noise.value == 0.25
    assert fdstep.known_noise(second) == 0.0
    assert fdstep.noise_of(second, measure(0.5)) == 0.5
    assert calls == [0.25, 0.5]


def test_every_forward_difference_of_the_package_goes_through_the_kernel():
    """Six hand-written forward differences (issue 61) became calls of
    ``forward_jacobian``; their idiom, ``(c - r0) / h`` over a batch, is not written
    again anywhere else."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "tsid_fmu"
    idiom = re.compile(r"\(c - r0?\) / h")
    found = [
        p.relative_to(root).as_posix()
        for p in root.rglob("*.py")
        if idiom.search(p.read_text(encoding="utf-8")) and p.name != "fdstep.py"
    ]
    assert found == []
