"""Edge cases of the intervals (uncertainty/intervals.py, profile.py), no FMU.

Each case is worked from the definitions: the covariance is the pseudo-inverse of the
whitened Fisher matrix on its eigenvalues above 1e-14 of the largest (the rest are
directions the data do not see: infinite variance for every parameter in them), never
below the Cramer-Rao bound; the degrees of freedom are Satterthwaite's, within 1 and
``n - p``; the profile re-fit is a chord Gauss-Newton iteration of at most
``CHORD_STEPS + 1`` simulations that stops when a step gains less than 1 % of the
threshold, its Jacobian corrected by each step's secant and re-linearised to check a
bracket's outer end. They kill the open mutants of docs/dev/mutation-survivors.md in those files.
"""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.evaluate.protocol import Evaluation
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty import profile
from tsid_fmu.uncertainty.intervals import Uncertainty, quantile, uncertainty
from tsid_fmu.uncertainty.longrun import LongRun
from tsid_fmu.uncertainty.sensitivity import Sensitivities

intervals = importlib.import_module("tsid_fmu.uncertainty.intervals")

WIDE = (-math.inf, math.inf)


def _alternating(n: int) -> np.ndarray:
    """Residuals of RMS exactly 1 whose HAC variance is below the Cramer-Rao bound, so
    the floor gives the standard errors: ``sqrt(diag(F^+))``."""
    return np.where(np.arange(n) % 2, -1.0, 1.0)


def _case(columns: np.ndarray, residuals: np.ndarray | None = None):
    """One experiment, one output, linear parameters of first levels 0..2 (a search unit
    is 2), at x = 1 each."""
    n, p = columns.shape
    r = _alternating(n) if residuals is None else residuals
    names = [f"k{j}" for j in range(p)]
    sens = Sensitivities(names, [r[:, None]], [columns[:, None, :]], ["e"], [["y"]])
    levels = {k: [0.0, 2.0] for k in names}
    space = Space(levels, dict.fromkeys(names, WIDE), LevelingOptions())
    return sens, space, dict.fromkeys(names, 1.0)


def test_a_fisher_matrix_below_one_is_inverted_as_it_is():
    """Small sensitivities: every eigenvalue of F below 1. The standard errors (the
    floor: ``sqrt(diag(F^-1))``), the condition number and the combinations' errors
    (along each eigenvector ``v``, the larger of ``v^T H v`` of the HAC covariance and
    its own bound ``v^T F^-1 v = 1 / lambda``) come from F itself."""
    n = 200
    t = np.linspace(0.0, 1.0, n)
    cols = 0.005 * np.column_stack([1.0 + t, 1.0 - 0.5 * t])
    sens, space, x = _case(cols)
    u = uncertainty(sens, space, x)
    fisher = cols.T @ cols
    values, vectors = np.linalg.eigh(fisher)
    assert values.max() < 0.05
    assert u.values == x
    se = np.sqrt(np.diag(np.linalg.inv(fisher)))
    assert [u.std_error[k] for k in x] == pytest.approx(2 * se, rel=1e-9)
    assert u.condition == pytest.approx(values.max() / values.min(), rel=1e-9)
    hac, crb = u.bounds_of
    assert crb == pytest.approx(np.linalg.inv(fisher), rel=1e-9)
    for combo, k in zip(u.combinations, np.argsort(values)[::-1], strict=True):
        v = vectors[:, k]
        own = max(float(v @ hac @ v), 1.0 / values[k])
        assert combo["std_error"] == pytest.approx(math.sqrt(own), rel=1e-9)
        assert combo["determined"] is (combo["std_error"] < 0.5)


@pytest.mark.parametrize(("small", "seen"), [(3e-7, False), (3.0000001e-7, True)])
def test_an_eigenvalue_at_1e_14_of_the_largest_is_not_seen(small, seen):
    """F = diag(9, small^2); 1e-14 * 9 equals 3e-7 squared in floating point exactly:
    that eigenvalue is at the cut, and the cut is strict."""
    cols = np.zeros((20, 2))
    cols[0, 0], cols[1, 1] = 3.0, small
    assert (1e-14 * 9.0 == 3e-7 * 3e-7) and (cols.T @ cols)[1, 1] == small * small
    u = uncertainty(*_case(cols))
    assert math.isfinite(u.std_error["k0"])
    assert math.isfinite(u.std_error["k1"]) is seen
    if seen:  # at least the Cramer-Rao bound 1 / small (2 per search unit)
        assert u.std_error["k1"] >= 2 / small * (1 - 1e-12)


def test_parameters_seen_only_through_their_sum_are_both_unseen():
    """Two equal columns: the null direction (1, -1) / sqrt 2 has one negative weight;
    both parameters have no standard error, no Cramer-Rao bound, open intervals, and no
    parameter is left to measure the inflation by (it stays 1)."""
    t = np.linspace(0.0, 1.0, 50)
    g = 1.0 + t
    u = uncertainty(*_case(np.column_stack([g, g])))
    for k in ("k0", "k1"):
        assert u.std_error[k] == math.inf and u.cramer_rao[k] == math.inf
        assert u.intervals[k] == [None, None]
    assert u.inflation == 1.0


def test_a_null_direction_adds_no_variance_to_a_parameter_it_barely_moves():
    """Columns g and c g with c = 1000.5: the null direction (c, -1) / |(c, -1)| moves k1
    by a weight whose square is below 1e-6, so k1 counts as seen, with the variance of
    the one seen direction only: ``(c^2 / (1 + c^2)) / lambda``."""
    n, c = 50, 1000.5
    g = 1.0 + np.linspace(0.0, 1.0, n)
    u = uncertainty(*_case(np.column_stack([g, c * g])))
    lam = float(g @ g) * (1 + c * c)
    assert u.std_error["k0"] == math.inf
    assert u.std_error["k1"] == pytest.approx(2 * math.sqrt(c * c / (1 + c * c) / lam), rel=1e-6)


def test_a_non_finite_jacobian_has_no_uncertainty():
    cols = np.column_stack([np.ones(10), np.arange(10.0)])
    cols[3, 1] = np.nan
    assert uncertainty(*_case(cols)) is None


def _ar1(n: int, seed: int = 1) -> np.ndarray:
    e = np.random.default_rng(seed).normal(size=n + 200)
    r = np.zeros(n + 200)
    for i in range(1, r.size):
        r[i] = 0.8 * r[i - 1] + e[i]
    return r[200:]


@pytest.mark.parametrize(("scale", "dof"), [(1e8, 1.0), (1e-8, 298.0)])
def test_satterthwaite_dof_are_kept_within_1_and_n_minus_p(monkeypatch, scale, dof):
    """AR(1) residuals put the HAC variance above the floor, so its degrees of freedom
    ``2 V^2 / var(V)`` count; a variance of V scaled far up (or down) takes them below
    one (above n - p = 298), where they are clipped."""
    real = intervals.long_run_covariance

    def scaled(series, inverse):
        found = real(series, inverse)
        return LongRun(found.middle, found.variance * scale, found.models)

    monkeypatch.setattr(intervals, "long_run_covariance", scaled)
    t = np.linspace(0.0, 1.0, 300)
    cols = 5.0 * np.column_stack([1.0 + t, np.sin(4 * t)])
    u = uncertainty(*_case(cols, _ar1(300)))
    assert u.inflation > 2  # above the floor
    assert u.dof == {"k0": dof, "k1": dof}
    half = quantile(dof) * u.std_error["k0"]
    assert u.intervals["k0"] == pytest.approx([1.0 - half, 1.0 + half], rel=1e-9)


def test_to_dict_writes_non_finite_numbers_as_none_and_keeps_lists():
    u = Uncertainty(values={"a": 1.0}, std_error={"a": math.inf}, condition=math.nan)
    u.intervals = {"a": [0.5, 2.0], "b": [None, math.inf]}
    d = u.to_dict()
    assert d["std_error"] == {"a": None} and d["condition"] is None
    assert d["intervals"] == {"a": [0.5, 2.0], "b": [None, None]}
    assert d["values"] == {"a": 1.0} and d["inflation"] == 1.0


# -- the profile's re-fit --------------------------------------------------------------


class _Linear:
    """Residuals ``A s - y``; ``asked`` keeps every coordinate vector simulated."""

    def __init__(self, space: Space, a: np.ndarray, y: np.ndarray, residuals: bool = True):
        self.space, self.a, self.y, self.residuals, self.asked = space, a, y, residuals, []

    def evaluate(self, rows, progress=None):
        s = [self.space.to_s(x) for x in rows]
        self.asked += s
        res = [self.a @ v - self.y for v in s]
        costs = np.array([[float(r @ r)] for r in res])
        return Evaluation(costs, [None] * len(rows), len(rows), res if self.residuals else None)


def _chord(bounds=WIDE, scale=2.0):
    """A linear problem whose Jacobian is given with its second column ``scale`` times
    its size: each chord step multiplies the error of q's re-fit by ``1 - 1 / scale``
    (halves it for the default 2)."""
    n = 40
    t = np.linspace(0.0, 1.0, n)
    a = np.column_stack([1.0 + t, 1.0 - 0.5 * t])
    y = a @ np.array([0.3, -0.2]) + 0.01 * np.sin(30 * t)
    space = Space({"p": [0.0, 2.0], "q": [0.0, 2.0]}, {"p": WIDE, "q": bounds}, LevelingOptions())
    s0 = np.linalg.lstsq(a, y, rcond=None)[0]
    r0 = a @ s0 - y
    jac = a * np.array([1.0, scale])
    problem = profile.ProfileProblem(_Linear(space, a, y), space, s0, float(r0 @ r0), jac, 1.0)
    return problem, a, y, profile._Secant(problem, 0)


def _no_secant(monkeypatch):
    """Keep every profile's Jacobian as it was given: no secant update, no check."""
    monkeypatch.setattr(profile._Secant, "update", _keep_last)
    monkeypatch.setattr(profile, "CHECKS", 0)


def _keep_last(self, s, r):
    self.s, self.r = s.copy(), np.asarray(r, dtype=float)


def test_the_re_fit_takes_chord_steps_until_one_gains_under_1_percent_of_the_limit(
    monkeypatch,
):
    """With the given Jacobian kept: moving p by delta, q's exact re-fit moves by
    x* = -(a1.a0 / a1.a1) delta; the chord starts at half of it and halves the error
    each step, so the k-th simulation (k = 0, 1, ...) costs P + |a1|^2 (x* / 2^(k+1))^2
    above the exact profile cost P. With the first excess at 100 limits, the gains (3/4
    of each excess) stay above 1 % of the limit: all CHORD_STEPS + 1 = 7 simulations
    run."""
    _no_secant(monkeypatch)
    problem, a, y, secant = _chord()
    a0, a1 = a[:, 0], a[:, 1]
    limit = 0.1
    shift = -(a1 @ a0) / (a1 @ a1)
    delta = math.sqrt(100 * limit / (a1 @ a1)) / abs(0.5 * shift)  # first excess 100 limit
    best = profile._refit(problem, 0, delta, secant, limit)
    assert len(problem.evaluator.asked) == profile.CHORD_STEPS + 1 == 7
    exact = problem.s0 + np.array([delta, shift * delta])
    r = a @ exact - y
    excess = (a1 @ a1) * (shift * delta / 2**7) ** 2
    assert best == pytest.approx(float(r @ r) + excess, rel=1e-9)
    # a first excess of 2 limits: the sixth simulation's gain, 3/4 * 2 / 4^4 limits, is
    # under 1 % of the limit and ends the re-fit
    problem.evaluator.asked = []
    profile._refit(problem, 0, delta / math.sqrt(50), profile._Secant(problem, 0), limit)
    assert len(problem.evaluator.asked) == 6


def test_each_re_fit_step_corrects_the_jacobian_by_its_secant():
    """The same re-fit with the secant rule: the first chord step (along q only) halves
    q's error and its secant gives q's column exactly, so the second lands on the exact
    re-fit and the third gains nothing: 4 simulations, the exact profile cost. The next
    offset starts from that re-fit with the corrected Jacobian: exact at once."""
    problem, a, y, secant = _chord()
    a0, a1 = a[:, 0], a[:, 1]
    shift = -(a1 @ a0) / (a1 @ a1)
    delta = math.sqrt(100 * 0.1 / (a1 @ a1)) / abs(0.5 * shift)
    best = profile._refit(problem, 0, delta, secant, 0.1)
    assert len(problem.evaluator.asked) == 4
    r = a @ (problem.s0 + np.array([delta, shift * delta])) - y
    assert best == pytest.approx(float(r @ r), rel=1e-9)
    assert secant.jac[:, 1] == pytest.approx(a1, rel=1e-9)
    problem.evaluator.asked = []
    best = profile._refit(problem, 0, 2 * delta, secant, 0.1)
    r = a @ (problem.s0 + np.array([2 * delta, 2 * shift * delta])) - y
    assert len(problem.evaluator.asked) == 2 and best == pytest.approx(float(r @ r), rel=1e-9)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_re_fit_goes_on_from_the_bound_it_clipped_to(sign):
    """q's column given at 0.6 of its true size: the chord's first point overshoots q's
    exact re-fit x* to 1/0.6 x*. A bound at 1.3 x* clips it there; the next step,
    (1/0.6)(0.3 x*) = 0.5 x*, goes on from the bound to 0.8 x*. (Left beyond the bound,
    the next point would be 1.17 x*, clipped to the bound again.) p moving up sends q
    down: the lower bound, and the upper one when p moves down."""
    problem, a, _, _ = _chord(scale=0.6)
    s1 = problem.s0[1]
    delta = sign * 0.5
    shift = -(a[:, 1] @ a[:, 0]) / (a[:, 1] @ a[:, 1]) * delta
    at = 1.0 + 2 * (s1 + 1.3 * shift)  # the bound, in values (1 + 2 s)
    bounds = (at, math.inf) if shift < 0 else (-math.inf, at)
    assert bool(shift < 0) == (sign > 0)
    problem, _, _, secant = _chord(scale=0.6, bounds=bounds)
    profile._refit(problem, 0, delta, secant, 1e-9)  # a fresh secant: the given Jacobian
    asked_q = [s[1] for s in problem.evaluator.asked]
    assert asked_q[0] == pytest.approx(s1 + 1.3 * shift, abs=1e-12)
    assert asked_q[1] == pytest.approx(s1 + 0.8 * shift, rel=1e-9)


def test_a_failed_simulation_in_the_profile_has_no_residuals():
    problem, _, _, _ = _chord()
    problem.evaluator.residuals = False
    cost, r = problem.cost(problem.s0)
    assert r is None and cost == pytest.approx(problem.cost0, rel=1e-12)


# -- thresholds met exactly (equivalent verdicts of docs/dev/mutation-survivors.md re-checked:
# each boundary can be built exactly, so each strict or non-strict rule is pinned)


def test_a_combination_known_to_exactly_half_a_unit_is_not_determined():
    """F = 4 (four samples of sensitivity 1): the standard error is 0.5 search units
    exactly, UNDETERMINED, and determined means below it."""
    u = uncertainty(*_case(np.ones((4, 1))))
    assert u.combinations[0]["std_error"] == 0.5 and u.combinations[0]["determined"] is False


def test_the_degrees_of_freedom_are_at_least_one_with_as_many_samples_as_parameters_plus_one():
    """Three samples, two parameters: n - p = 1 degree of freedom, not more."""
    cols = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    u = uncertainty(*_case(cols))
    assert u.dof == {"k0": 1.0, "k1": 1.0}


def test_a_ratio_exactly_ratio_gain_times_better_is_not_grouped():
    """The ratio's relative error times RATIO_GAIN equal to the weaker parameter's (the
    same floating-point expression as scale_groups): not grouped; a little more: grouped."""
    space = Space({"m": [1.0, 100.0], "k": [1.0, 100.0]}, {"m": WIDE, "k": WIDE}, LevelingOptions())
    w = space.width * math.log(10.0) * 100.0
    cov = np.array([[1e-3, 0.99e-3], [0.99e-3, 1e-3]])
    var = cov[0, 0] * w[0] ** 2 + cov[1, 1] * w[1] ** 2 - 2 * cov[0, 1] * w[0] * w[1]
    at = math.sqrt(max(var, 0.0)) * intervals.RATIO_GAIN
    assert at > 1.0

    def groups(weaker: float) -> list:
        u = Uncertainty(values={"m": 1.0, "k": 1.0}, relative={"m": weaker, "k": 2 * weaker})
        u.cov = cov
        return intervals.scale_groups(u, space)

    assert groups(at) == []
    assert [g["parameters"] for g in groups(at * (1 + 1e-12))] == [["m", "k"]]


def _exact():
    """The linear problem with the exact Jacobian: each re-fit is exact, so the rise at
    an offset d of p is ``c d^2`` and does not depend on the limit."""
    problem, _, _, secant = _chord(scale=1.0)
    return problem, secant


def test_a_step_or_bisection_point_rising_exactly_by_the_limit_is_the_end(monkeypatch):
    """Steps 1/8, 1/4, ... and bisection points (exact in binary): a limit equal to the
    rise at the first step, or at the first bisection point 3/16 of the bracket (1/8,
    1/4), makes that point the end (the root of the rise reaches the limit's there)."""
    problem, secant = _exact()
    limit = profile._refit(problem, 0, 0.125, secant, 1.0) - problem.cost0
    assert profile._end(problem, 0, 1.0, 0.125, limit) == (0.125, True)
    # the rise the search itself finds at 3/16 (its re-fits go on from the last one's
    # point, so a re-fit from the answer may differ from it in the last bit)
    rises = {}
    refit = profile._refit

    def recorded(problem, j, delta, secant, limit):
        rises[delta] = refit(problem, j, delta, secant, limit) - problem.cost0
        return rises[delta] + problem.cost0

    monkeypatch.setattr(profile, "_refit", recorded)
    profile._end(_exact()[0], 0, 1.0, 0.125, 2.25 * limit)  # about the rise at 3/16
    assert profile._end(_exact()[0], 0, 1.0, 0.125, rises[0.1875]) == (0.1875, True)


def test_the_end_is_interpolated_in_its_bracket_linearly_in_the_root_of_the_rise():
    """A rise c d^2 gives the exact crossing sqrt(limit / c); any rise stays within the
    bracket; a failed simulation at the outer end (infinite rise) leaves the outer end,
    and a rise below zero inside (a better fit found) counts as zero."""
    for c, d_in, d_out in ((4.0, 0.5, 0.75), (0.3, 1.0, 2.0)):
        limit = c * 0.6**2 if c == 4.0 else c * 1.7**2
        end = profile._crossing(d_in, c * d_in**2, d_out, c * d_out**2, limit)
        assert end == pytest.approx(math.sqrt(limit / c), rel=1e-12)
    # a quartic rise: the crossing of its root's chord, inside the bracket
    end = profile._crossing(1.0, 1.0, 2.0, 16.0, 4.0)
    assert end == pytest.approx(1.0 + (2.0 - 1.0) / (4.0 - 1.0))
    assert profile._crossing(1.0, 0.5, 2.0, math.inf, 1.0) == 2.0
    assert profile._crossing(1.0, -0.25, 2.0, 4.0, 1.0) == 1.5


def test_an_unresolved_end_is_the_outer_end_of_its_bracket():
    """A first step of 10 search units, past the end: the bisections of (0, 10) give the
    bracket (0, 1.25) with no point inside, and the end returned is 1.25, an upper bound."""
    problem, _ = _exact()
    assert profile._end(problem, 0, 1.0, 10.0, 0.01) == (1.25, False)


class _Scripted:
    """Returns the given costs in turn (one row a call), with zero residuals."""

    def __init__(self, costs, n):
        self.costs, self.n, self.calls = list(costs), n, 0

    def evaluate(self, rows, progress=None):
        cost = self.costs[self.calls]
        self.calls += 1
        return Evaluation(np.array([[cost]]), [None], 1, [np.zeros(self.n)])


def test_a_re_fit_step_that_gains_exactly_1_percent_of_the_limit_goes_on():
    """Limit 100: a gain of exactly 1 (10 -> 9) is not below 1 % of it, the re-fit takes
    another step; a gain of 0.5 then ends it."""
    problem, _, _, _ = _chord()
    n = problem.jacobian.shape[0]
    problem.evaluator = _Scripted([10.0, 9.0, 8.5, 8.0], n)
    assert profile._refit(problem, 0, 0.1, profile._Secant(problem, 0), 100.0) == 8.5
    assert problem.evaluator.calls == 3


@pytest.mark.parametrize("sign", [-1.0, 1.0])
def test_a_step_ending_exactly_one_unit_past_a_bound_is_still_taken(sign):
    """p at s = 0.5 with bounds 0..4 (s = -0.5..1.5) and a limit never reached: the
    doublings 1/8 .. 2 end exactly one search unit past a bound on either side (s =
    -1.5, 2.5), a step still taken, as with bounds a hair wider; a hair narrower, that
    step is skipped (two simulations fewer). Either way the end is open."""
    n = 40
    t = np.linspace(0.0, 1.0, n)
    a = np.column_stack([1.0 + t, 1.0 - 0.5 * t])
    s0 = np.array([0.5, -0.25])

    def sims(bounds: tuple[float, float]) -> int:
        space = Space(
            {"p": [0.0, 2.0], "q": [0.0, 2.0]}, {"p": bounds, "q": WIDE}, LevelingOptions()
        )
        problem = profile.ProfileProblem(_Linear(space, a, a @ s0), space, s0, 0.0, a, 1.0)
        end = profile._end(problem, 0, sign, 0.125, 1e9)
        assert end == (math.inf, True)
        return len(problem.evaluator.asked)

    exact, wider, narrower = sims((0.0, 4.0)), sims((-1e-9, 4 + 1e-9)), sims((1e-9, 4 - 1e-9))
    assert exact == wider and narrower == exact - 2


def test_an_end_within_the_first_step_keeps_the_outer_end_of_its_bracket():
    """A first step of 1/8 past the end (a limit equal to the rise at 0.1): the bracket
    (3/32, 7/64) lies within the first step, below what the simulations may resolve, and
    its outer end 7/64 is the end returned (interpolated, it would be 0.1)."""
    problem, secant = _exact()
    limit = profile._refit(problem, 0, 0.1, secant, 1.0) - problem.cost0
    assert profile._end(problem, 0, 1.0, 0.125, limit) == (0.109375, True)
    # a bisection point rising exactly by the limit is inside: the bracket goes on to
    # (1/16, 5/64), whose outer end is returned
    limit = profile._refit(problem, 0, 0.0625, profile._Secant(problem, 0), 1.0) - problem.cost0
    assert profile._end(problem, 0, 1.0, 0.125, limit) == (0.078125, True)


@pytest.mark.parametrize("without", ["", "secant", "checks", "both"])
def test_an_end_the_given_jacobian_overstates_is_found_by_the_secant_or_the_check(
    monkeypatch, without
):
    """q's column given at 20 times its size (as a Jacobian far off away from the answer,
    where a model has events): each chord step with it moves q a twentieth of the way,
    and the rise it reports stays far above the profile's. The exact profile rises by
    c d^2 (c the Schur complement of q). The secant corrects q's column after one step,
    and the check re-linearises at the first doubling past the limit: either finds the
    exact end, 0.5 search units. With neither, the end is found well short of it."""
    problem, a, _, _ = _chord(scale=20.0)
    a0, a1 = a[:, 0], a[:, 1]
    c = a0 @ a0 - (a0 @ a1) ** 2 / (a1 @ a1)
    limit = c * 0.5**2
    if without in ("secant", "both"):
        monkeypatch.setattr(profile._Secant, "update", _keep_last)
    if without in ("checks", "both"):
        monkeypatch.setattr(profile, "CHECKS", 0)
    off, found = profile._end(problem, 0, 1.0, 0.05, limit)
    assert found
    if without == "both":
        assert off < 0.4
    else:
        assert off == pytest.approx(0.5, rel=1e-6)


class _Events(_Linear):
    """The linear residuals plus events: a step of ``eps`` along a fixed shape each time
    q crosses a multiple of ``pi w`` (a square wave), as dry friction's stick-slip
    timing moves the residuals in small jumps."""

    def __init__(self, space, a, y, eps, w):
        super().__init__(space, a, y)
        self.eps, self.w = eps, w
        self.shape = np.cos(np.linspace(0.0, 7.0, a.shape[0]))

    def evaluate(self, rows, progress=None):
        ev = super().evaluate(rows, progress)
        for r, s in zip(ev.residuals, self.asked[-len(rows) :], strict=True):
            r += self.eps * np.sign(np.sin(s[1] / self.w)) * self.shape
        ev.costs[:, 0] = [float(r @ r) for r in ev.residuals]
        return ev


@pytest.mark.parametrize("w", [1e-3, 2e-5])
def test_the_check_re_linearises_with_a_step_shorter_than_the_events(monkeypatch, w):
    """The 20-times-off Jacobian of the test above, the secant off, and events in q
    spaced 3e-3 and 6e-5 search units apart: a forward difference across one adds
    2 eps / h to q's column. With CHECK_STEP the check sees the smooth part and the end
    is within 1 % of the events-free one, 0.5. With the sensitivities' step of 2e-3 it
    was found 14 % short at the wider spacing, with 1e-4 34 % short at the narrower."""
    problem, a, y, _ = _chord(scale=20.0)
    problem.evaluator = _Events(problem.space, a, y, 3e-3, w)
    a0, a1 = a[:, 0], a[:, 1]
    limit = (a0 @ a0 - (a0 @ a1) ** 2 / (a1 @ a1)) * 0.5**2
    monkeypatch.setattr(profile._Secant, "update", _keep_last)
    off, _ = profile._end(problem, 0, 1.0, 0.05, limit)
    assert off == pytest.approx(0.5, rel=0.01)


def test_a_seen_combination_touching_a_parameter_with_an_unseen_part_is_finite():
    """Columns g, h, h (k1 and k2 seen only through their sum) plus a little of k1 in
    k0's column: the seen eigenvectors touch k1 and k2, whose own variances are infinite.
    Each seen eigenvector is orthogonal to the unseen (0, 1, -1), so its standard error
    is finite, over the seen directions. OpenModelica's Mass_Damper:
    the common scale of m, c and d touched an offset by 0.02, was called infinite on
    that ground, never probed, and m, c, d kept finite intervals that excluded the truth."""
    t = np.linspace(0.0, 1.0, 40)
    g, h = 1.0 + t, np.sin(3 * t)
    u = uncertainty(*_case(np.column_stack([g + 0.05 * h, h, h])))
    assert u.std_error["k1"] == math.inf and u.std_error["k2"] == math.inf
    seen = [c for c in u.combinations if c["determined"]]
    assert len(seen) == 2
    for c in seen:
        v = np.asarray(c["direction"])
        assert abs(v[1]) > 1e-3 and math.isfinite(c["std_error"])
        hac, crb = u.bounds_of  # over the seen directions: its own HAC variance or bound
        own = max(float(v @ hac @ v), float(v @ crb @ v))
        assert c["std_error"] == pytest.approx(math.sqrt(own), rel=1e-12)
    (unseen,) = [c for c in u.combinations if not c["determined"]]
    assert unseen["std_error"] == math.inf
    # any combination: infinite where it reaches the unseen direction, else finite
    assert u.variance(np.array([0.0, 1.0, 0.0])) == math.inf
    assert u.variance(np.array([0.0, 1.0, 1.0 + 1e-2])) == math.inf
    assert 0 < u.variance(np.array([0.0, 1.0, 1.0])) < math.inf  # the sum k1 + k2


def test_the_profiles_refit_does_not_step_along_what_the_outputs_do_not_see():
    """Residuals ``30 w (s_a - s_b)`` (a valley along a + b) and ``w (s_c - 1)^2`` plus
    noise: at s_c = 1 the outputs do not depend on c to first order, and the finite
    differences give its column as rounding (1e-14 of the others), while a's carries
    errors of 1e-8 of its size. Inverting c's rounding, the re-fit's first step moves c
    by thousands of units to follow a's error, the square bites, and the exact valley
    reads as a closed interval. Over the directions the outputs depend on
    only, both ends stay open."""
    w = np.linspace(1.0, 2.0, 10)
    space = Space({n: [0.0, 2.0] for n in "abc"}, dict.fromkeys("abc", WIDE), LevelingOptions())

    def residuals(s):
        noise = 0.1 * np.sin(np.arange(10.0))
        return np.concatenate([30.0 * w * (s[0] - s[1]), w * (s[2] - 1.0) ** 2 + noise])

    class Ev:
        def evaluate(self, sets):
            rs = [residuals(space.to_s(x)) for x in sets]
            costs = np.array([[float(r @ r)] for r in rs])
            return Evaluation(costs, [None] * len(rs), len(rs), rs)

    s0, h, rng = np.array([0.3, 0.3, 1.0]), 1e-6, np.random.default_rng(0)
    jac = np.column_stack(
        [(residuals(s0 + h * e) - residuals(s0 - h * e)) / (2 * h) for e in np.eye(3)]
    )
    # the differences' errors: relative to a column's size, and the rounding of none
    jac = jac * (1 + 1e-8 * rng.normal(size=jac.shape)) + 1e-12 * rng.normal(size=jac.shape)
    cost0 = float(residuals(s0) @ residuals(s0))
    problem = profile.ProfileProblem(Ev(), space, s0, cost0, jac, 1.0)
    out = profile.profile_intervals(problem, {"a": 0.1, "b": 0.1, "c": 0.1})
    assert out["a"] == [None, None] and out["b"] == [None, None]
