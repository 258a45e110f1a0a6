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
longrun = importlib.import_module("tsid_fmu.uncertainty.longrun")


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


# -- the AR pieces against closed forms (killed mutants of docs/dev/mutation-survivors.md) ---


def _ar_gamma(phi: list[float], innovation: float, lags: int) -> np.ndarray:
    """Autocovariances of a stationary AR(p) by its MA(inf) sum (independent of longrun)."""
    p, psi = len(phi), np.zeros(4000)
    psi[0] = 1.0
    for k in range(1, psi.size):
        psi[k] = sum(phi[i] * psi[k - 1 - i] for i in range(min(p, k)))
    return np.array([innovation * psi[: psi.size - h] @ psi[h:] for h in range(lags + 1)])


@pytest.mark.parametrize("phi", [[0.5], [0.5, 0.3], [0.7, -0.2, 0.1]])
def test_an_ar_model_its_autocovariances_and_their_extension(phi):
    gamma = _ar_gamma(phi, 2.0, 8)
    assert longrun._from_coefficients(np.array(phi), 2.0) == pytest.approx(
        gamma[: len(phi) + 1], rel=1e-9
    )
    model = longrun._model(gamma[: len(phi) + 1])
    assert model.coefficients == pytest.approx(phi, rel=1e-9)
    assert model.innovation == pytest.approx(2.0, rel=1e-9)
    for n in (1, len(phi), len(phi) + 1, len(phi) + 2, 9):
        assert model.extend(n) == pytest.approx(gamma[:n], rel=1e-9), n


def test_levinson_on_an_ar1():
    coefficients, variances, reflections = longrun._levinson(np.array([1.0, 0.5, 0.25]))
    assert [list(c) for c in coefficients] == [[0.5], [0.5, 0.0]]
    assert list(variances) == [1.0, 0.75, 0.75] and list(reflections) == [0.5, 0.0]


def test_non_stationary_autocovariances_give_no_model():
    assert longrun._model(np.array([0.0, 0.0])) is None
    assert longrun._model(np.array([1.0, 1.5])) is None  # |reflection| > 1
    assert longrun._model(np.array([1.0, 1.0, 1.0])) is None  # a reflection of 1
    assert longrun._from_coefficients(np.array([1.5]), 1.0) is None  # gamma_0 < 0
    assert longrun._from_coefficients(np.array([1.0]), 1.0) is None  # singular


@pytest.mark.parametrize(
    ("n", "order"), [(0, 0), (1, 0), (2, 0), (3, 0), (5, 1), (10, 4), (21, 9), (100, 20)]
)
def test_the_highest_order_tried(n, order):
    assert longrun.max_order(n) == order


def test_autocovariances_are_the_uncentred_lagged_sums():
    r = np.array([0.3, -1.2, 0.7, 2.0, -0.4, 0.1, 0.9])
    direct = [r[: r.size - k] @ r[k:] / r.size for k in range(r.size)]
    assert longrun._autocovariances(r, r.size - 1) == pytest.approx(direct, abs=1e-12)


def test_fit_ar_with_a_fixed_order_and_without_data():
    rng = np.random.default_rng(7)
    x = arma(rng, 400, [0.6])
    assert fit_ar(x, order=3).order == 3  # fixed: no BIC
    assert fit_ar(x[:3], order=5).order <= 2  # at most n - 1
    for empty in (np.zeros(10), np.zeros(0)):
        m = fit_ar(empty)
        assert m.order == 0 and m.innovation == 0.0 and list(m.autocovariance) == [0.0]
    # an alternating series: a negative lag-1 autocovariance is no reason to give up
    m = fit_ar(np.where(np.arange(200) % 2, -1.0, 1.0))
    assert m.order >= 1 and m.rho1 < -0.9
    # an order-0 answer keeps the variance as its innovation
    w = fit_ar(rng.normal(size=2000))
    assert w.order == 0 and w.innovation == pytest.approx(np.mean(w.autocovariance[0]))


def test_the_delta_variance_of_an_ar1_model():
    """``2 d^2 / n`` from the innovation variance, plus ``(d d / d phi)^2`` times the
    Yule-Walker variance of ``phi`` (``sigma^2 / (gamma_0 n)``), with ``d`` the diagonal
    of ``F^-1 J^T Gamma J F^-1`` from a dense Toeplitz ``Gamma``."""
    n, phi, s2 = 120, 0.5, 1.5
    t = np.linspace(0.0, 1.0, n)
    jac = np.column_stack([1.0 + t, np.sin(5 * t)])
    inv = np.linalg.inv(jac.T @ jac)

    def diag(ph: float) -> np.ndarray:
        g = s2 * ph ** np.arange(n) / (1 - ph**2)
        return np.diag(inv @ jac.T @ linalg.toeplitz(g) @ jac @ inv)

    model = longrun._model(_ar_gamma([phi], s2, 1))
    series = longrun._Series(jac, inv)
    d = diag(phi)
    assert series.variance(series.kernel(model.extend(n))) == pytest.approx(d, rel=1e-9)
    slope = (diag(phi + 1e-6) - diag(phi - 1e-6)) / 2e-6
    expected = 2 * d**2 / n + slope**2 * s2 / (model.autocovariance[0] * n)
    assert longrun._delta_variance(series, model, d) == pytest.approx(expected, rel=1e-4)
    # white: the innovation term alone
    white = longrun.ArNoise(np.array([s2]), np.zeros(0), s2)
    assert longrun._delta_variance(series, white, d) == pytest.approx(2 * d**2 / n, rel=1e-12)


def test_the_variance_of_several_series_is_their_sum():
    rng = np.random.default_rng(3)
    series = []
    for n in (150, 90):
        t = np.linspace(0, 1, n)
        series.append((arma(rng, n, [0.6]), np.column_stack([np.exp(-2 * t), t])))
    inv = np.linalg.inv(sum(j.T @ j for _, j in series))
    found = long_run_covariance(series, inv)
    parts = []
    for (_, j), m in zip(series, found.models, strict=True):
        g = linalg.toeplitz(m.extend(j.shape[0]))
        d = np.diag(inv @ j.T @ g @ j @ inv)
        parts.append(longrun._delta_variance(longrun._Series(j, inv), m, d))
    assert found.variance == pytest.approx(sum(parts), rel=1e-9)
    assert np.all(parts[0] > 0) and np.all(parts[1] > 0)


# -- more closed forms (killed mutants of docs/dev/mutation-survivors.md) ---------------------


def test_autocovariances_of_small_or_negatively_correlated_processes():
    """gamma_0 = s2 / (1 - phi^2) is positive for any stationary AR(1), however small s2
    and whatever the sign of phi (gamma_1 = phi gamma_0 is then negative); a zero
    innovation variance is no process."""
    for phi, s2 in ((-0.5, 0.1), (0.5, 1e-3), (-0.9, 2.0)):
        gamma = longrun._from_coefficients(np.array([phi]), s2)
        assert gamma == pytest.approx([s2 / (1 - phi**2), phi * s2 / (1 - phi**2)], rel=1e-12)
    assert longrun._from_coefficients(np.array([0.5]), 0.0) is None


def test_a_fixed_order_is_cut_to_the_series_length_less_one():
    r = np.array([0.3, -1.2, 0.7, 2.0, -0.4])
    assert fit_ar(r, order=10).order == 4
    assert fit_ar(r, order=4).order == 4 and fit_ar(r, order=2).order == 2
    assert fit_ar(np.array([0.8]), order=3).order == 0


def test_the_expected_residual_autocovariances_of_a_fit_are_the_dense_ones():
    """Residuals of a least-squares fit are ``(I - H) e`` with ``H = J F^-1 J^T``; under
    an AR(1) model of ``e`` (Toeplitz ``Gamma``) their expected lagged sums over ``n``
    are those of ``(I - H) Gamma (I - H)^T``."""
    n, phi, s2 = 30, 0.8, 1.0
    t = np.linspace(0.0, 1.0, n)
    jac = np.column_stack([1.0 + t, np.cos(3 * t)])
    inv = np.linalg.inv(jac.T @ jac)
    model = longrun._model(_ar_gamma([phi], s2, 1))
    series = longrun._Series(jac, inv)
    kernel = series.kernel(model.extend(n))
    outer = inv @ series.middle(kernel) @ inv
    found = series.expected(model, kernel, outer)
    rest = np.eye(n) - jac @ inv @ jac.T
    m = rest @ linalg.toeplitz(model.extend(n)) @ rest.T
    dense = [np.trace(m, offset=-lag) / n for lag in range(model.order + 1)]
    assert found == pytest.approx(dense, rel=1e-9)


def test_the_delta_method_slope_is_the_forward_difference_of_step():
    """As test_the_delta_variance_of_an_ar1_model, against the dense forward difference
    over STEP (which the code takes; a backward one differs by about 1e-5 here)."""
    n, phi, s2 = 120, 0.5, 1.5
    t = np.linspace(0.0, 1.0, n)
    jac = np.column_stack([1.0 + t, np.sin(5 * t)])
    inv = np.linalg.inv(jac.T @ jac)

    def diag(ph: float) -> np.ndarray:
        g = s2 * ph ** np.arange(n) / (1 - ph**2)
        return np.diag(inv @ jac.T @ linalg.toeplitz(g) @ jac @ inv)

    model = longrun._model(_ar_gamma([phi], s2, 1))
    d = diag(phi)
    slope = (diag(phi + longrun.STEP) - d) / longrun.STEP
    expected = 2 * d**2 / n + slope**2 * s2 / (model.autocovariance[0] * n)
    found = longrun._delta_variance(longrun._Series(jac, inv), model, d)
    assert found == pytest.approx(expected, rel=1e-8)
