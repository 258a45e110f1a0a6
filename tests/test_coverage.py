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
from tsid_fmu.uncertainty import profile as intervals_profile
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
    freedom: 95.5 / 95.0 % (96.75 / 96.75 % when the end was the outer end of its
    bracket; 87.75 / 87.0 % with Newey-West)."""
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


# -- a known case of every field (killed mutants of docs/dev/mutation-survivors.md) ----------
# Alternating residuals make the HAC estimate smaller than the Cramer-Rao bound, so the
# floor gives the standard errors exactly: the inverse of F = J^T J on the seen block.


def _known_case() -> tuple[Sensitivities, Space, dict, np.ndarray]:
    """Two correlated log parameters, a linear one orthogonal to them, one unseen.

    Two experiments, three outputs with residual RMS 2, 0.5 and 1; each output's
    sensitivities are its RMS times ``base`` (so every whitened output is ``base``).
    """
    n = 200
    t = np.linspace(0.0, 1.0, n)
    alt = np.where(np.arange(n) % 2, -1.0, 1.0)
    a_col, b_col = 1.0 + t, 1.0 - 0.5 * t
    q, _ = np.linalg.qr(np.column_stack([a_col, b_col]))
    g = 2.5 * np.cos(6 * np.pi * t)
    base = np.column_stack([a_col, b_col, g - q @ (q.T @ g), np.zeros(n)])
    rms = ([2.0, 0.5], [1.0])
    res = [alt[:, None] * np.array(s) for s in rms]
    jac = [base[:, None, :] * np.array(s)[None, :, None] for s in rms]
    sens = Sensitivities(["a", "b", "d", "c"], res, jac, ["e1", "e2"], [["y", "z"], ["w"]])
    wide = (-math.inf, math.inf)
    space = Space(
        {"a": [1.0, 100.0], "b": [10.0, 1000.0], "d": [0.0, 2.0], "c": [0.0, 1.0]},
        {"a": (1e-6, 1e6), "b": (1e-6, 1e6), "d": wide, "c": wide},
        LevelingOptions(),
    )
    return sens, space, {"a": 10.0, "b": 100.0, "d": 1.0, "c": 0.0}, 3 * base.T @ base


def test_every_field_of_a_known_case():
    sens, space, x, fisher = _known_case()
    u = uncertainty(sens, space, x)
    n, p = 3 * 200, 3
    se = np.sqrt(np.diag(np.linalg.inv(fisher[:p, :p])))  # search units
    t = stats.t.ppf(0.975, n - p)
    assert u.inflation == 1.0  # the floor holds on every parameter
    assert u.noise == {"e1": [2.0, 0.5], "e2": [1.0]}
    assert u.dof == {k: n - p for k in x}
    for j, k in enumerate("ab"):  # log10, two decades per search unit
        std = x[k] * math.log(10) * 2 * se[j]
        assert u.std_error[k] == pytest.approx(std, rel=1e-9)
        assert u.relative[k] == pytest.approx(100 * std / x[k], rel=1e-9)
        assert u.cramer_rao[k] == pytest.approx(100 * std / x[k], rel=1e-9)
        low, high = u.intervals[k]
        assert low == pytest.approx(x[k] * 10 ** (-2 * t * se[j]), rel=1e-9)
        assert high == pytest.approx(x[k] * 10 ** (2 * t * se[j]), rel=1e-9)
    assert u.std_error["d"] == pytest.approx(2 * se[2], rel=1e-9)
    assert u.intervals["d"] == pytest.approx([1 - 2 * t * se[2], 1 + 2 * t * se[2]], rel=1e-9)
    # the unseen parameter: no standard error, an open interval, no correlation
    assert u.std_error["c"] == math.inf and u.relative["c"] == math.inf
    assert u.cramer_rao["c"] == math.inf and u.intervals["c"] == [None, None]
    assert u.condition > 1e15
    assert set(u.whiteness) == {"e1", "e2"} and set(u.whiteness["e1"]) == {"y", "z"}
    for w in (u.whiteness["e1"]["y"], u.whiteness["e2"]["w"]):
        assert set(w) == {"p_value", "rho1", "white", "ar_order"}
        assert w["white"] is False and w["rho1"] < -0.9 and w["ar_order"] >= 1
    # correlations: the covariance normalised, zero for the unseen parameter
    cov = np.where(np.isfinite(u.cov), u.cov, 0.0)
    for i, k in enumerate("abd"):
        for m, h in enumerate("abd"):
            r = cov[i, m] / math.sqrt(cov[i, i] * cov[m, m])
            assert u.correlation[k][h] == pytest.approx(r, rel=1e-9, abs=1e-15)
        assert u.correlation[k]["c"] == 0.0 and u.correlation["c"][k] == 0.0
    assert u.correlation["c"]["c"] == 0.0


def test_the_combinations_of_a_known_case():
    sens, space, x, fisher = _known_case()
    u = uncertainty(sens, space, x)
    values, vectors = np.linalg.eigh(fisher)
    order = np.argsort(values)[::-1]  # best determined first
    assert len(u.combinations) == 4
    labels = ["lg a", "lg b", "d", "c"]
    for combo, k in zip(u.combinations, order, strict=True):
        v = vectors[:, k]
        u_dir = v * space.width / np.linalg.norm(v * space.width)
        terms = {labels[j]: abs(round(c, 3)) for j, c in enumerate(u_dir) if abs(c) >= 0.05}
        assert {h: abs(c) for h, c in combo["terms"].items()} == terms
        if values[k] < 1e-9 * values.max():  # the unseen one
            assert combo["std_error"] == math.inf and combo["determined"] is False
            assert math.isnan(combo["percent"])
            continue
        hac, crb = u.bounds_of  # its own HAC variance, at least its own Cramer-Rao bound
        se = math.sqrt(max(float(v @ hac @ v), float(v @ crb @ v)))
        assert combo["std_error"] == pytest.approx(se, rel=1e-9)
        assert combo["determined"] is (se < 0.5)
        if set(terms) <= {"lg a", "lg b"}:  # relative: 100 ln10 per log10 unit
            norm = np.linalg.norm(v * space.width)
            assert combo["percent"] == pytest.approx(100 * math.log(10) * se * norm, rel=1e-9)
        else:  # a linear member counts by its own relative change, width / |x|
            names = [space.names[labels.index(h)] for h in terms]
            if any(x[n] == 0 for n in names):
                assert math.isnan(combo["percent"])
                continue
            rel = [space.local_scale(j, x[n]) / abs(x[n]) if x[n] else 0.0
                   for j, n in enumerate(space.names)]  # fmt: skip
            norm = np.linalg.norm(v * np.array(rel))
            assert combo["percent"] == pytest.approx(100 * se * norm, rel=1e-9)
    assert [set(c["terms"]) for c in u.combinations][-1] == {"c"}
    assert sum(c["determined"] for c in u.combinations) == 3


def test_an_output_fitted_exactly_is_whitened_by_one():
    """Zero residuals (RMS 0) would divide by zero: the output counts with RMS 1."""
    n, c = 100, 10.0
    sens = Sensitivities(["k"], [np.zeros((n, 1))], [np.full((n, 1, 1), c)], ["e"], [["y"]])
    space = Space({"k": [0.0, 2.0]}, {"k": (-math.inf, math.inf)}, LevelingOptions())
    u = uncertainty(sens, space, {"k": 1.5})
    assert u.std_error["k"] == pytest.approx(2.0 / (c * math.sqrt(n)), rel=1e-12)
    assert u.noise == {"e": [0.0]}


def test_the_interval_ends_at_one_search_unit_past_the_bounds():
    """First levels 0..2 (s = -0.5 at 0), bounds 0..4 (s = -0.5 .. 1.5): an end beyond a
    bound by at most one search unit is clipped to it, farther it is open (None); a
    half-width over 2 * UNDETERMINED opens both ends."""
    space = Space({"k": [0.0, 2.0]}, {"k": (0.0, 4.0)}, LevelingOptions())
    assert intervals._interval(space, 0, 0.0, 1.0) == [0.0, 3.0]
    assert intervals._interval(space, 0, -0.5, 1.0) == [0.0, 2.0]  # low_s = -1.5
    assert intervals._interval(space, 0, -0.9, 1.0) == [None, pytest.approx(1.2)]
    assert intervals._interval(space, 0, 1.5, 1.0) == [2.0, 4.0]  # high_s = 2.5
    assert intervals._interval(space, 0, 1.9, 1.0)[1] is None
    for half in (1.25, 1.5, math.nan, math.inf):
        assert intervals._interval(space, 0, 0.0, half) == [None, None]


def test_fewer_than_one_degree_of_freedom_count_as_one():
    assert quantile(0.5) == quantile(1.0) == pytest.approx(stats.t.ppf(0.975, 1), abs=1e-12)


# -- the profile on a linear problem, where it is known exactly --------------------------


class _Linear:
    """Cost residuals ``A s - y`` of a linear model in the search coordinates."""

    def __init__(self, space: Space, a: np.ndarray, y: np.ndarray):
        self.space, self.a, self.y, self.calls = space, a, y, 0

    def evaluate(self, rows):
        self.calls += len(rows)
        res = [self.a @ self.space.to_s(x) - self.y for x in rows]
        costs = np.array([[float(r @ r)] for r in res])
        return type("Ev", (), {"residuals": res, "costs": costs})()


def _linear_profile(bounds=(-math.inf, math.inf), thresholds=None, p_bounds=None):
    n = 50
    t = np.linspace(0.0, 1.0, n)
    a = np.column_stack([1.0 + t, 1.0 - 0.5 * t])
    y = a @ np.array([0.3, -0.2]) + 0.01 * np.sin(40 * t)
    both = {"p": p_bounds or bounds, "q": bounds}
    space = Space({"p": [0.0, 2.0], "q": [0.0, 2.0]}, both, LevelingOptions())
    s0 = np.linalg.lstsq(a, y, rcond=None)[0]
    ev = _Linear(space, a, y)
    r0 = a @ s0 - y
    problem = intervals_profile.ProfileProblem(
        ev, space, s0, float(r0 @ r0), a, 0.01, thresholds=thresholds or {}
    )
    return problem, np.linalg.inv(a.T @ a), space


def test_profile_ends_are_the_exact_ones_of_a_linear_problem():
    """Re-fitting the other parameter exactly, the cost rises by ``d^2 / C_jj`` at an
    offset ``d``: the ends lie at ``sqrt(limit C_jj)``. The doublings and three
    bisections bracket each end, and the interpolation in the bracket, linear in the
    root of the rise, finds it exactly (returning the bracket's outer end, as before,
    put it up to an eighth of the last doubling too far out)."""
    problem, c, space = _linear_profile(thresholds={"q": 0.04})
    exact = {"p": math.sqrt(0.01 * c[0, 0]), "q": math.sqrt(0.04 * c[1, 1])}
    steps = {"p": exact["p"] / 3, "q": exact["q"] / 3}
    out = intervals_profile.profile_intervals(problem, steps)
    for j, k in enumerate("pq"):
        x0 = space.value(j, problem.s0[j])
        low, high = out[k]
        for off in (x0 - low, high - x0):  # parameter units: 2 per search unit
            assert off == pytest.approx(2 * exact[k], rel=1e-9), (k, off)
    assert problem.unresolved == set()
    # three doublings and three bisections a side, each re-fit two simulations: the
    # first (exact, from the Jacobian) and one that gains less than 1 % of the limit;
    # the doubling past the end checked once: re-linearised (a run a column, two) and
    # re-fitted again (two)
    assert problem.evaluator.calls == 2 * 2 * (6 * 2 + 2 + 2)


def test_a_first_step_past_both_ends_leaves_the_parameter_unresolved():
    problem, c, _ = _linear_profile()
    out = intervals_profile.profile_intervals(problem, {"p": 10.0, "q": math.nan})
    assert problem.unresolved == {"p"}
    assert out["p"][1] - out["p"][0] <= 2 * 2 * 10.0 / 8 + 1e-12  # within the bisections
    # q's step is the smallest one, MIN_STEP, far below its ends: resolved
    exact = math.sqrt(0.01 * c[1, 1])
    assert out["q"][1] - problem.space.value(1, problem.s0[1]) == pytest.approx(2 * exact)


def test_a_profile_end_beyond_a_bound_by_more_than_a_unit_is_open():
    """Bounds 0.5..1.5 (s = -0.25..0.25): the rise never reaches a huge threshold, and
    the doublings stop once past one search unit beyond a bound: both ends open."""
    problem, _, _ = _linear_profile(bounds=(0.5, 1.5), thresholds={"p": 1e9, "q": 1e9})
    out = intervals_profile.profile_intervals(problem, {"p": 0.01, "q": 0.01})
    assert out == {"p": [None, None], "q": [None, None]}
    assert problem.unresolved == set()  # open ends are known, not unresolved


def test_each_side_stops_at_its_own_bound():
    """p at 1.6 (s = 0.3) with bounds 1.5..4 (s = 0.25..1.5) and its exact ends one search
    unit away: the lower end is open (past s = -0.75 before the rise), the upper one is
    bracketed by s = 0.3 + (0.975, 1.05) (doublings 0.3, 0.6, 1.2, bisections 0.9, 1.05,
    0.975) and found at s = 0.3 + 1 in it."""
    problem, c, space = _linear_profile(p_bounds=(1.5, 4.0))
    problem.thresholds = {"p": 1.0 / c[0, 0]}
    out = intervals_profile.profile_intervals(problem, {"p": 0.3})
    assert out["p"][0] is None
    assert out["p"][1] == pytest.approx(space.value(0, problem.s0[0] + 1.0), rel=1e-12)


def test_an_end_never_reached_within_the_doublings_is_open_and_known():
    """MIN_STEP doubled nine times is 0.512 search units: a threshold the cost never
    rises by within that leaves both ends open, and known to be."""
    problem, _, _ = _linear_profile(thresholds={"p": 1e9, "q": 1e9})
    out = intervals_profile.profile_intervals(problem, {})  # no steps: MIN_STEP
    assert out == {"p": [None, None], "q": [None, None]} and problem.unresolved == set()


def test_a_single_parameter_profile():
    n = 40
    t = np.linspace(0.0, 1.0, n)
    a = (1.0 + t)[:, None]
    y = 0.3 * a[:, 0] + 0.01 * np.cos(30 * t)
    space = Space({"p": [0.0, 2.0]}, {"p": (-math.inf, math.inf)}, LevelingOptions())
    s0 = np.linalg.lstsq(a, y, rcond=None)[0]
    r0 = a @ s0 - y
    problem = intervals_profile.ProfileProblem(
        _Linear(space, a, y), space, s0, float(r0 @ r0), a, 0.01
    )
    exact = math.sqrt(0.01 / float(a[:, 0] @ a[:, 0]))
    low, high = intervals_profile.profile_intervals(problem, {"p": exact / 3})["p"]
    for off in (space.value(0, s0[0]) - low, high - space.value(0, s0[0])):
        assert off == pytest.approx(2 * exact, rel=1e-9)


# -- scale groups: ratios the data fix better than the parameters -------------------------


def _groups(sigma: dict, corr: dict, names: list[str], linear: tuple = ()):
    """``scale_groups`` of log parameters (two decades of first levels) with these
    relative standard errors (percent) and correlations."""
    levels = {n: ([0.0, 2.0] if n in linear else [1.0, 100.0]) for n in names}  # width 2
    space = Space(levels, {n: (-math.inf, math.inf) for n in names}, LevelingOptions())
    w = 2 * math.log(10) * 100  # percent per search unit
    sd = np.array([min(sigma[n], 1e3) / w for n in names])  # "open": a finite covariance
    r = np.eye(len(names))
    for (a, b), c in corr.items():
        r[names.index(a), names.index(b)] = r[names.index(b), names.index(a)] = c
    u = intervals.Uncertainty(values=dict.fromkeys(names, 1.0), relative=dict(sigma))
    u.cov = np.outer(sd, sd) * r
    return intervals.scale_groups(u, space)


def _ratio(sa: float, sb: float, rho: float) -> float:
    return math.sqrt(sa * sa + sb * sb - 2 * rho * sa * sb)


def test_a_ratio_four_times_better_than_both_parameters_groups_them():
    sigma = {"m": 20.0, "k": 24.0, "c": 5.0, "lin": 20.0, "tiny": 0.9, "open": math.inf}
    corr = {("m", "k"): 0.999, ("m", "lin"): 0.999, ("m", "tiny"): 0.999, ("m", "open"): 0.9}
    names = list(sigma)
    found = _groups(sigma, corr, names, linear=("lin",))
    pct = _ratio(20.0, 24.0, 0.999)  # 4.1, and 4 * 4.1 < 20
    assert found == [
        {
            "parameters": ["m", "k"],
            "ratios": {"m/k": pytest.approx(pct, rel=1e-9)},
            "scale_percent": 20.0,
        }
    ]
    # the gain is needed against the better-known parameter too
    assert _groups({"m": 20.0, "k": 24.0}, {("m", "k"): 0.99}, ["m", "k"]) == []


def test_groups_join_through_shared_members():
    sigma = {"a": 30.0, "b": 31.0, "c": 32.0, "d": 10.0}
    corr = {("a", "b"): 0.999, ("b", "c"): 0.999, ("a", "c"): 0.5}
    (group,) = _groups(sigma, corr, list(sigma))
    assert group["parameters"] == ["a", "b", "c"] and group["scale_percent"] == 30.0
    assert set(group["ratios"]) == {"a/b", "b/c"}
    assert group["ratios"]["b/c"] == pytest.approx(_ratio(31.0, 32.0, 0.999), rel=1e-9)


def test_no_covariance_no_groups():
    space = Space({"m": [1.0, 100.0]}, {"m": (0.0, math.inf)}, LevelingOptions())
    assert intervals.scale_groups(intervals.Uncertainty(values={"m": 1.0}), space) == []


def test_above_the_floor_the_hac_sandwich_and_its_satterthwaite_dof_set_the_interval():
    """AR(1) residuals (rho 0.8): the HAC variance F^-1 S F^-1 exceeds the Cramer-Rao one,
    its degrees of freedom are 2 V^2 / var(V) (var(V) from the AR model's delta method,
    tests/test_longrun.py), and the interval is +/- t(dof) HAC standard errors."""
    n = 300
    t = np.linspace(0.0, 1.0, n)
    e = np.random.default_rng(1).normal(size=n + 200)
    r = np.zeros(n + 200)
    for i in range(1, r.size):
        r[i] = 0.8 * r[i - 1] + e[i]
    r = r[200:]
    jac = 5.0 * np.column_stack([1.0 + t, np.sin(4 * t)])
    sens = Sensitivities(["a", "b"], [r[:, None]], [jac[:, None, :]], ["e"], [["y"]])
    wide = (-math.inf, math.inf)
    space = Space({"a": [0.0, 2.0], "b": [0.0, 2.0]}, {"a": wide, "b": wide}, LevelingOptions())
    u = uncertainty(sens, space, {"a": 1.0, "b": 1.0})
    whitened = jac / math.sqrt(np.mean(r**2))
    inv = np.linalg.inv(whitened.T @ whitened)
    found = intervals.long_run_covariance([(r / math.sqrt(np.mean(r**2)), whitened)], inv)
    hac = np.diag(inv @ found.middle @ inv)
    dof = 2 * hac**2 / found.variance
    ratio = np.sqrt(hac / np.diag(inv))
    assert np.all(ratio > 2) and u.inflation == pytest.approx(np.median(ratio), rel=1e-9)
    for j, k in enumerate("ab"):
        assert u.dof[k] == pytest.approx(dof[j], rel=1e-9) and 5 < u.dof[k] < 50
        assert u.std_error[k] == pytest.approx(2 * math.sqrt(hac[j]), rel=1e-9)
        assert u.cramer_rao[k] == pytest.approx(100 * 2 * math.sqrt(inv[j, j]), rel=1e-9)
        half = quantile(dof[j]) * 2 * math.sqrt(hac[j])
        assert u.intervals[k] == pytest.approx([1.0 - half, 1.0 + half], rel=1e-9)


def test_separate_groups_and_the_scale_of_the_best_known_member():
    sigma = {"z": 5.0, "a": 30.0, "b": 29.0, "c": 12.0, "d": 11.0}  # z on its own first
    corr = {("a", "b"): 0.999, ("c", "d"): 0.999}
    found = _groups(sigma, corr, list(sigma))
    assert [g["parameters"] for g in found] == [["a", "b"], ["c", "d"]]
    assert [g["scale_percent"] for g in found] == [29.0, 11.0]  # the better-known one
    assert [list(g["ratios"]) for g in found] == [["a/b"], ["c/d"]]


def test_only_parameters_known_worse_than_one_percent_are_grouped():
    assert _groups({"a": 1.0, "b": 1.0}, {("a", "b"): 0.999}, ["a", "b"]) == []
    assert len(_groups({"a": 1.5, "b": 1.5}, {("a", "b"): 0.999}, ["a", "b"])) == 1
