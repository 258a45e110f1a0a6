"""The AR(p) long-run covariance of the HAC intervals, and the profile threshold it sets.

The data come from NumPy/SciPy (AR processes, a linear model), no FMU.
"""

from __future__ import annotations

import importlib
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import linalg, optimize

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.evaluate import Evaluation, PreparedExperiment, Simulated
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty import long_run_covariance
from tsid_fmu.uncertainty.intervals import quantile, uncertainty
from tsid_fmu.uncertainty.longrun import fit_ar
from tsid_fmu.uncertainty.sensitivity import sensitivities

assess = importlib.import_module("tsid_fmu.uncertainty.assess")  # the package exports a function


def arma(rng: np.random.Generator, n: int, phi: list[float], burn: int = 2000) -> np.ndarray:
    """An AR(p) series with unit innovations, started far in the past."""
    e = rng.normal(size=n + burn)
    x = np.zeros(n + burn)
    for t in range(len(phi), n + burn):
        x[t] = e[t] + sum(c * x[t - k - 1] for k, c in enumerate(phi))
    return x[burn:]


def test_bic_picks_the_order_of_the_process():
    rng = np.random.default_rng(4)
    assert fit_ar(rng.normal(size=5000)).order == 0
    one = fit_ar(arma(rng, 5000, [0.6]))
    assert one.order == 1 and one.coefficients[0] == pytest.approx(0.6, abs=0.03)
    two = fit_ar(arma(rng, 5000, [0.5, 0.3]))
    assert two.order == 2
    assert two.coefficients == pytest.approx([0.5, 0.3], abs=0.04)


def test_the_long_run_variance_of_an_ar1_series_matches_theory():
    """A mean (constant Jacobian) of AR(1) noise, rho 0.8: its variance is
    ``(1 + rho) / (1 - rho) / n`` times the noise's, to 3 %."""
    rng = np.random.default_rng(2)
    rho, n = 0.8, 200_000
    x = arma(rng, n, [rho]) * math.sqrt(1 - rho**2)  # unit variance
    ones = np.ones((n, 1))
    found = long_run_covariance([(x - x.mean(), ones)], np.array([[1.0 / n]]))
    assert found.middle[0, 0] / n == pytest.approx((1 + rho) / (1 - rho), rel=0.03)


def test_the_middle_is_the_toeplitz_sandwich_of_each_series_model():
    """Two series of different lengths (two experiments): ``S`` is the sum of
    ``J^T Gamma J`` with each series' AR model, exactly (the FFT products)."""
    rng = np.random.default_rng(5)
    lengths = (300, 170)
    series = []
    for n in lengths:
        t = np.linspace(0, 1, n)
        jac = np.column_stack([np.exp(-3 * t), np.sin(7 * t), t])
        series.append((arma(rng, n, [0.7, -0.2]), jac))
    fisher = sum(j.T @ j for _, j in series)
    found = long_run_covariance(series, np.linalg.inv(fisher))
    expected = sum(
        j.T @ linalg.toeplitz(m.extend(j.shape[0])) @ j
        for (_, j), m in zip(series, found.models, strict=True)
    )
    assert found.middle == pytest.approx(expected, rel=1e-10, abs=1e-10)
    assert all(m.order >= 1 for m in found.models)


def test_on_white_residuals_the_middle_is_the_fisher_matrix():
    """White noise: order 0 and ``S = J^T J`` times the residual variance, corrected
    for the ``q`` degrees of freedom the fit takes (one moment step: ``1 + q / n``, to
    first order ``n / (n - q)``)."""
    rng = np.random.default_rng(6)
    n, t = 400, np.linspace(0, 1, 400)
    jac = np.column_stack([np.ones(n), t])
    noise = rng.normal(size=n)
    r = noise - jac @ np.linalg.lstsq(jac, noise, rcond=None)[0]
    r /= np.sqrt(np.mean(r**2))
    found = long_run_covariance([(r, jac)], np.linalg.inv(jac.T @ jac))
    assert found.models[0].order == 0
    assert found.middle == pytest.approx(jac.T @ jac * (1 + 2 / n), rel=1e-9)


# a linear model for the profile: a constant (which AR noise with positive correlation
# hides: large HAC inflation) and a fast alternating term (which it hardly touches)
N, RHO, SIGMA = 400, 0.7, 0.05
BASIS = np.column_stack([np.ones(N), np.where(np.arange(N) % 2, -1.0, 1.0)])
TRUTH = {"a": 1.0, "b": 0.5}


class LinearEvaluator:
    """Scores and simulates ``a + b (-1)^t`` against ``measured``."""

    n_replicates = 1

    def __init__(self, measured: np.ndarray) -> None:
        experiment = PreparedExperiment(
            name="lin",
            time=np.arange(N, dtype=float),
            input_names=(),
            output_names=("y",),
            inputs=None,
            measured=measured[:, None],
            weights=np.ones(1),
            scale=np.array([SIGMA]),
        )
        self.spec = SimpleNamespace(cost="sse", experiments=(experiment,))
        self.measured, self.nfev = measured, 0

    def model(self, x: dict[str, float]) -> np.ndarray:
        """The output at every sample."""
        return BASIS @ np.array([x["a"], x["b"]])

    def evaluate(self, sets: list, progress: object = None) -> Evaluation:
        """Cost and residuals of each set."""
        res = [(self.model(dict(s)) - self.measured) / SIGMA for s in sets]
        self.nfev += len(res)
        costs = np.array([[float(r @ r)] for r in res])
        return Evaluation(costs=costs, errors=[None] * len(res), nfev=len(res), residuals=res)

    def simulate(self, sets: list, *, count: bool = True) -> list:
        """Outputs of each set."""
        self.nfev += len(sets) if count else 0
        return [[Simulated("lin", self.model(s)[:, None], None)] for s in sets]


def test_each_parameter_profile_carries_its_own_inflation():
    """For a linear model the profile interval is the covariance one (``t se``), but for
    the bisection of its ends (at most 1/8 of the bracket wider). One threshold for all
    parameters (the median inflation) would make the constant's too narrow and the
    alternating term's too wide."""
    rng = np.random.default_rng(7)
    noise = SIGMA * arma(rng, N, [RHO]) * math.sqrt(1 - RHO**2)
    ev = LinearEvaluator(BASIS @ np.array([TRUTH["a"], TRUTH["b"]]) + noise)
    coef = optimize.lsq_linear(BASIS, ev.measured).x
    x = {"a": float(coef[0]), "b": float(coef[1])}
    space = Space(
        {"a": [0.5, 1.5], "b": [0.0, 1.0]}, {n: (-1e9, 1e9) for n in x}, LevelingOptions()
    )
    sens = sensitivities(ev, ev.spec, space, x)
    u = uncertainty(sens, space, x)
    assert u.relative["a"] / u.cramer_rao["a"] > 1.8  # the constant: strongly inflated
    assert u.relative["b"] == pytest.approx(u.cramer_rao["b"], rel=1e-9)  # at the floor
    cost = float(ev.evaluate([x]).costs[0, 0])
    assess._widen_by_profile(ev, ev.spec, space, sens, u, x=x, cost=cost)
    for name in x:
        wald = quantile(u.dof[name]) * u.std_error[name]
        low, high = u.profile[name]
        assert 0.5 * (high - low) / wald == pytest.approx(1.06, abs=0.07), name
