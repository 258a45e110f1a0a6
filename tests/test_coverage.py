"""Interval coverage measured over 400 noise seeds (``benchmarks/coverage.py``), no FMU.

A correct 95 % interval holds the truth on 370 to 390 of 400 independent seeds (the
band 92.5-97.5 %) with probability 0.984 (binomial); a 68 % interval does so with
probability below 1e-40, a 99 % one with 0.008. So the band tells 95 % intervals from
68 % ones (``se`` instead of ``1.96 se``, ``chi2`` at the 68 % level), which the
five-seed test of ``test_uncertainty.py`` cannot. The seeds are fixed: the figures are
deterministic (``python benchmarks/coverage.py`` prints them).
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.intervals import Z95, uncertainty
from tsid_fmu.uncertainty.profile import CHI2_95
from tsid_fmu.uncertainty.sensitivity import Sensitivities

intervals = importlib.import_module("tsid_fmu.uncertainty.intervals")
assess = importlib.import_module("tsid_fmu.uncertainty.assess")  # the package exports a function

SEEDS = 400
Z68 = 1.0  # +/- one standard error: a 68.3 % interval
CHI2_68 = float(stats.chi2.ppf(stats.norm.cdf(1.0) - stats.norm.cdf(-1.0), 1))  # = 1


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
    assert assess.Z95 == Z95 and assess.CHI2_95 == CHI2_95


def test_the_band_passes_95_percent_intervals_and_rejects_68_and_99_percent_ones():
    assert bench.pass_probability(SEEDS) > 0.98
    assert bench.pass_probability(SEEDS, 0.6827) < 1e-40
    assert bench.pass_probability(SEEDS, 0.99) < 0.01


def test_the_half_width_is_z95_standard_errors_in_a_known_case():
    """One parameter, constant sensitivity ``c``, residuals +/-1 (RMS 1): the Cramer-Rao
    standard error is ``1 / (c sqrt(n))`` in search units. The alternating residuals
    make the HAC estimate smaller, so the Cramer-Rao floor gives exactly that."""
    n, c = 100, 10.0
    r = np.where(np.arange(n) % 2, -1.0, 1.0)[:, None]
    sens = Sensitivities(["k"], [r], [np.full((n, 1, 1), c)], ["e"], [["y"]])
    space = Space({"k": [0.0, 2.0]}, {"k": (-math.inf, math.inf)}, LevelingOptions())
    u = uncertainty(sens, space, {"k": 1.5})
    se = 2.0 / (c * math.sqrt(n))  # search units times the width of the first levels
    assert u.std_error["k"] == pytest.approx(se, abs=1e-12)
    low, high = u.intervals["k"]
    assert low == pytest.approx(1.5 - Z95 * se, abs=1e-12)
    assert high == pytest.approx(1.5 + Z95 * se, abs=1e-12)


@pytest.mark.slow
def test_wald_intervals_cover_the_truth_95_percent_of_the_time(white, monkeypatch):
    found = bench.coverage(white, bench.wald)
    assert all(bench.in_band(share) for share in found.values()), found
    # the same check rejects 68 % intervals (se instead of Z95 se) and 99 % ones
    for z in (Z68, float(stats.norm.ppf(0.995))):
        monkeypatch.setattr(intervals, "Z95", z)
        wrong = bench.coverage(white, bench.wald)
        assert not any(bench.in_band(share) for share in wrong.values()), (z, wrong)


@pytest.mark.slow
def test_profile_intervals_cover_the_truth_95_percent_of_the_time(white, monkeypatch):
    found = bench.coverage(white, bench.profile)
    assert all(bench.in_band(share) for share in found.values()), found
    monkeypatch.setattr(assess, "CHI2_95", CHI2_68)  # the threshold of a 68 % interval
    wrong = bench.coverage(white, bench.profile)
    assert not any(bench.in_band(share) for share in wrong.values()), wrong


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="issue 27: on AR(1) noise (rho 0.5, 200 samples) the HAC intervals hold the "
    "truth on 82.0 % (a) and 88.25 % (b) of 400 seeds (the profile ones 87.75 / 87.0 %); "
    "the exact sandwich covariance gives 94.5 / 94.75 %: the Newey-West estimate is too "
    "small at this sample size",
)
def test_hac_intervals_cover_the_truth_95_percent_of_the_time_on_ar1_noise(coloured):
    found = bench.coverage(coloured, bench.wald)
    assert all(bench.in_band(share) for share in found.values()), found


@pytest.mark.slow
def test_on_these_seeds_the_exact_sandwich_covers_the_truth_95_percent_of_the_time(coloured):
    """The benchmark's AR(1) data and fits are sound: the sandwich with the noise's true
    covariance holds the truth on 94.5 / 94.75 % of the seeds; the HAC shortfall is the
    estimate's."""
    found = bench.coverage(coloured, lambda f: bench.reference(f, exact=True))
    assert all(bench.in_band(share) for share in found.values()), found


@pytest.mark.slow
def test_the_hac_widening_recovers_coverage_the_cramer_rao_intervals_lose(coloured, monkeypatch):
    """On AR(1) noise the HAC intervals hold the truth clearly more often than the
    white-noise (Cramer-Rao) ones: 82.0 / 88.25 % against 75.5 / 73.25 % on these seeds."""
    hac = bench.coverage(coloured, bench.wald)
    monkeypatch.setattr(intervals, "long_run_covariance", lambda g, bw: np.zeros((2, 2)))
    crb = bench.coverage(coloured, bench.wald)
    assert all(hac[n] >= crb[n] + 0.05 for n in hac), (hac, crb)
    assert all(hac[n] >= 0.8 for n in hac), hac  # no worse than measured today
