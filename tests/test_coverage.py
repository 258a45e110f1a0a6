"""Interval coverage measured over 400 noise seeds (``benchmarks/coverage.py``), no FMU.

A correct 95 % interval holds the truth on 370 to 390 of 400 independent seeds (the
band 92.5-97.5 %) with probability 0.984 (binomial); a 68 % interval does so with
probability below 1e-40, a 99 % one with 0.008. So the band tells 95 % intervals from
68 % ones (``t`` at the 68 % level: about ``se`` instead of ``1.96 se``, the profile's
threshold at the 68 % level), which the five-seed test of ``test_uncertainty.py``
cannot. The seeds are fixed: the figures are deterministic (``python
benchmarks/coverage.py`` prints them).
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import linalg, stats

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.intervals import Z95, quantile, uncertainty
from tsid_fmu.uncertainty.longrun import LongRun, fit_ar
from tsid_fmu.uncertainty.profile import CHI2_95
from tsid_fmu.uncertainty.sensitivity import Sensitivities, sensitivities

intervals = importlib.import_module("tsid_fmu.uncertainty.intervals")

SEEDS = 400
LEVEL_68 = float(stats.norm.cdf(1.0) - stats.norm.cdf(-1.0))  # +/- one standard error


def _benchmark():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "coverage.py"
    spec = importlib.util.spec_from_file_location("interval_coverage", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


bench = _benchmark()


@pytest.fixture(scope="module")
def white():
    return [bench.fit(seed) for seed in range(SEEDS)]


@pytest.fixture(scope="module")
def coloured():
    return [bench.fit(seed, bench.RHO) for seed in range(SEEDS)]


def test_the_constants_are_the_95_percent_quantiles():
    assert Z95 == pytest.approx(stats.norm.ppf(0.975), abs=1e-12)
    assert CHI2_95 == pytest.approx(stats.chi2.ppf(0.95, 1), abs=1e-12)
    assert intervals.LEVEL == 0.95
    for dof in (3, 30, 198):
        assert quantile(dof) == pytest.approx(stats.t.ppf(0.975, dof), abs=1e-12)
    # many degrees of freedom: the normal quantile, and its square the chi-square one
    assert quantile(1e12) == pytest.approx(Z95, abs=1e-9)
    assert quantile(1e12) ** 2 == pytest.approx(CHI2_95, abs=1e-8)


def test_the_band_passes_95_percent_intervals_and_rejects_68_and_99_percent_ones():
    assert bench.pass_probability(SEEDS) > 0.98
    assert bench.pass_probability(SEEDS, 0.6827) < 1e-40
    assert bench.pass_probability(SEEDS, 0.99) < 0.01


def test_the_half_width_is_t_standard_errors_in_a_known_case():
    """One parameter, constant sensitivity ``c``, residuals +/-1 (RMS 1): the Cramer-Rao
    standard error is ``1 / (c sqrt(n))`` in search units. The alternating residuals
    make the HAC estimate smaller, so the Cramer-Rao floor gives exactly that, known
    from ``n - 1`` degrees of freedom."""
    n, c = 100, 10.0
    r = np.where(np.arange(n) % 2, -1.0, 1.0)[:, None]
    sens = Sensitivities(["k"], [r], [np.full((n, 1, 1), c)], ["e"], [["y"]])
    space = Space({"k": [0.0, 2.0]}, {"k": (-math.inf, math.inf)}, LevelingOptions())
    u = uncertainty(sens, space, {"k": 1.5})
    se = 2.0 / (c * math.sqrt(n))  # search units times the width of the first levels
    assert u.std_error["k"] == pytest.approx(se, abs=1e-12)
    assert u.dof["k"] == n - 1
    t = stats.t.ppf(0.975, n - 1)
    low, high = u.intervals["k"]
    assert low == pytest.approx(1.5 - t * se, abs=1e-12)
    assert high == pytest.approx(1.5 + t * se, abs=1e-12)


@pytest.mark.slow
def test_wald_intervals_cover_the_truth_95_percent_of_the_time(white, monkeypatch):
    found = bench.coverage(white, bench.wald)
    assert all(bench.in_band(share) for share in found.values()), found
    # the same check rejects 68 % intervals (about se instead of 1.96 se) and 99 % ones
    for level in (LEVEL_68, 0.99):
        monkeypatch.setattr(intervals, "LEVEL", level)
        wrong = bench.coverage(white, bench.wald)
        assert not any(bench.in_band(share) for share in wrong.values()), (level, wrong)


@pytest.mark.slow
def test_profile_intervals_cover_the_truth_95_percent_of_the_time(white, monkeypatch):
    found = bench.coverage(white, bench.profile)
    assert all(bench.in_band(share) for share in found.values()), found
    monkeypatch.setattr(intervals, "LEVEL", LEVEL_68)  # the threshold of a 68 % interval
    wrong = bench.coverage(white, bench.profile)
    assert not any(bench.in_band(share) for share in wrong.values()), wrong


@pytest.mark.slow
def test_hac_intervals_cover_the_truth_95_percent_of_the_time_on_ar1_noise(coloured, monkeypatch):
    """Issue 27: with Newey-West (Bartlett kernel, Andrews' bandwidth) these were 82.0 /
    88.25 %; the AR(p) long-run covariance corrected for the fit, with Satterthwaite
    degrees of freedom, gives 95.25 / 95.0 %."""
    found = bench.coverage(coloured, bench.wald)
    assert all(bench.in_band(share) for share in found.values()), found
    monkeypatch.setattr(intervals, "LEVEL", LEVEL_68)
    wrong = bench.coverage(coloured, bench.wald)
    assert not any(bench.in_band(share) for share in wrong.values()), wrong


@pytest.mark.slow
def test_profile_intervals_cover_the_truth_95_percent_of_the_time_on_ar1_noise(
    coloured, monkeypatch
):
    """The profile threshold carries each parameter's HAC inflation and degrees of
    freedom: 96.75 / 96.75 % (87.75 / 87.0 % with Newey-West)."""
    found = bench.coverage(coloured, bench.profile)
    assert all(bench.in_band(share) for share in found.values()), found
    monkeypatch.setattr(intervals, "LEVEL", LEVEL_68)
    wrong = bench.coverage(coloured, bench.profile)
    assert not any(bench.in_band(share) for share in wrong.values()), wrong


@pytest.mark.slow
def test_on_these_seeds_the_exact_sandwich_covers_the_truth_95_percent_of_the_time(coloured):
    """The benchmark's AR(1) data and fits are sound: the sandwich with the noise's true
    covariance holds the truth on 94.5 / 94.75 % of the seeds; the HAC shortfall is the
    estimate's."""
    found = bench.coverage(coloured, lambda f: bench.reference(f, "exact"))
    assert all(bench.in_band(share) for share in found.values()), found


@pytest.mark.slow
def test_the_hac_widening_recovers_coverage_the_cramer_rao_intervals_lose(coloured, monkeypatch):
    """On AR(1) noise the Cramer-Rao intervals (a long-run covariance equal to the
    Fisher matrix: white residuals) hold the truth on 75.5 / 73.25 % of the seeds; the
    band rejects them."""

    def white(series, inverse):
        middle = sum(jac.T @ jac for _, jac in series)
        q = inverse.shape[0]
        return LongRun(middle, np.zeros(q), [fit_ar(r, order=0) for r, _ in series])

    monkeypatch.setattr(intervals, "long_run_covariance", white)
    crb = bench.coverage(coloured, bench.wald)
    assert not any(bench.in_band(share) for share in crb.values()), crb


def _variance_ratios(fits: list) -> tuple[np.ndarray, np.ndarray]:
    """Per fit and parameter: the HAC variance over the exact sandwich's, and the dof."""
    ratios, dofs = [], []
    for f in fits:
        sens = sensitivities(f.evaluator, f.evaluator.spec, f.space, f.x)
        u = uncertainty(sens, f.space, f.x)
        jac = sens.jacobian[0][:, 0, :]
        inv = np.linalg.inv(jac.T @ jac)
        noise = bench.SIGMA**2 * linalg.toeplitz(f.rho ** np.arange(bench.N))
        exact = inv @ jac.T @ noise @ jac @ inv
        ratios.append(np.diag(u.cov) / np.diag(exact))
        dofs.append([u.dof[n] for n in f.space.names])
    return np.array(ratios), np.array(dofs)


@pytest.mark.slow
def test_the_hac_variance_is_unbiased_and_its_dof_match_its_scatter(coloured):
    """Over the seeds the HAC variance averages the exact sandwich's (1.025 / 1.027;
    without the correction for what the fit absorbs, 0.956), and the Satterthwaite
    degrees of freedom (median about 30) match the scatter of the variance
    (``2 / var(log ratio)``: 28.5 / 27.0; white-noise dof would be 198)."""
    ratios, dofs = _variance_ratios(coloured)
    assert np.all(np.abs(ratios.mean(axis=0) - 1) < 0.035), ratios.mean(axis=0)
    scatter = 2 / np.log(ratios).var(axis=0)
    assert np.all(np.abs(np.median(dofs, axis=0) / scatter - 1) < 0.3), (dofs, scatter)
