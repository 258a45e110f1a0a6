"""The refinement stage: SciPy's trust-region least squares, without its wasted simulations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from spec_helpers import CurveEvaluator

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search.local import refine
from tsid_fmu.search.local.refine import refine_stage
from tsid_fmu.search.outcome import LocalStop, SolverNotes
from tsid_fmu.search.space import Space
from tsid_fmu.search.verdict import (
    GATE_RTOL,
    LOWER_PROBED,
    LOWER_TRIED,
    MAX_TRIALS,
    trial_fractions,
    trial_reaches_gate,
)
from tsid_fmu.study.schema import Method

T = np.linspace(0.0, 4.0, 60)
TRUTH = {"a": 2.0, "k": 1.3, "c": 0.4}
NOISE = np.random.default_rng(3).normal(0.0, 0.01, T.size)


def _model(a: float, k: float, c: float) -> np.ndarray:
    return a * np.exp(-k * T) + c


MEASURED = _model(**TRUTH) + NOISE


def ResidualEvaluator() -> CurveEvaluator:
    """Scores sets by a nonlinear least-squares fit, and logs every set it simulates."""
    return CurveEvaluator(_model, MEASURED, 0.01)


def _stage(with_start=True):
    space = Space(
        {"a": [1.0, 1.5, 3.0], "k": [0.5, 1.0, 2.0], "c": [0.0, 0.5, 1.0]},
        {n: (0.0, math.inf) for n in TRUTH},
        LevelingOptions(),
    )
    start = {"a": 1.8, "k": 1.1, "c": 0.5}
    first = ResidualEvaluator().evaluate([start])
    ev = ResidualEvaluator()
    result = refine_stage(
        "refinement",
        space,
        start,
        float(first.costs[0, 0]),
        ev,
        Method(cost="sse", refine="least_squares", refine_max_nfev=500),
        start_residuals=first.residuals[0] if with_start else None,
    )
    return result, ev, start


def test_refinement_reaches_scipys_answer_without_scipys_last_jacobian(monkeypatch):
    result, ev, start = _stage()
    assert result.status == 0 and "stopped before another Jacobian" in result.message
    assert start not in ev.asked  # the start's residuals came from the caller
    assert result.nfev == ev.nfev
    # the same trust-region path with SciPy's own stopping: SciPy pays one more
    # Jacobian (p = 3 simulations) after the step that meets its test
    monkeypatch.setattr(refine._Problem, "_check_step", lambda self, s, r: None)
    plain, _, _ = _stage()
    assert plain.status == 0 and plain.message == f"least squares: {refine.STOPPED['ftol']}"
    assert "`" not in plain.message  # SciPy's own text is not passed through (issue 64)
    assert result.nfev == plain.nfev - 3
    assert result.x == plain.x and result.cost == plain.cost
    assert result.x == pytest.approx(TRUTH, rel=0.05)


def test_refinement_simulates_the_start_when_the_caller_has_no_residuals():
    result, ev, start = _stage(with_start=False)
    with_start, _, _ = _stage()
    assert len(ev.asked) == result.nfev == with_start.nfev + 1
    assert ev.asked[0] == pytest.approx(start, rel=1e-12)
    assert result.cost == with_start.cost


def test_a_least_squares_that_cannot_go_on_keeps_the_best_set_and_says_why(monkeypatch):
    """SciPy's step can fail on a Jacobian it cannot factor; the stage then answers with
    the lowest set scored, not shown to be an optimum (status 1), instead of raising."""
    import scipy.optimize

    real = scipy.optimize.least_squares

    def failing(fun, x0, **kwargs):
        kwargs["max_nfev"] = 3
        real(fun, x0, **kwargs)
        raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setattr(scipy.optimize, "least_squares", failing)
    result, ev, start = _stage()
    assert result.status == 1 and "could not go on" in result.message
    assert result.cost < ResidualEvaluator().cost(**start)  # the steps it took are kept
    assert result.cost == pytest.approx(ev.cost(**result.x))


# -- the stationarity test's trial: halve the step until the model predicts the gate ------


def _problem_at(x: dict[str, float], jac_factor: float | np.ndarray):
    """A refinement problem at ``x`` whose last Jacobian is the true one times a factor."""
    space = Space(
        {"a": [1.0, 1.5, 3.0], "k": [0.5, 1.0, 2.0], "c": [0.1, 0.5, 1.0]},
        {n: (0.0, math.inf) for n in TRUTH},
        LevelingOptions(),
    )
    ev = ResidualEvaluator()
    problem, _ = refine._problem_at(space, x, ev.cost(**x), ev, 500, None, None)
    jac = problem.jac(space.to_s(x))  # forward differences at x
    s, r, _ = problem.jacobian
    problem.jacobian = (s, r, jac * jac_factor)
    problem.best, problem.best_r = (ev.cost(**x), dict(x)), r  # the answer is x itself
    return problem, ev


def test_a_step_too_long_for_the_model_is_halved_until_it_lowers_the_cost():
    """A Jacobian ten times too small makes a step ten times too long: the step and its
    half raise the cost, and the test used to call the answer stationary on that evidence
    (Simple2R1C_ic, exit 0 at 1.24 times the noise floor). An eighth of it is lower."""
    x = {"a": 2.0 * 1.01, "k": 1.3, "c": 0.4}
    problem, ev = _problem_at(x, 0.1)
    gate = problem.stationarity()
    assert not gate.holds and LOWER_TRIED in gate.detail
    assert problem.best[0] < ev.cost(**x)  # the lower point is the problem's answer now
    tried = ev.asked[-len(trial_fractions(*_gn(problem))) :]
    assert ev.cost(**tried[0]) > ev.cost(**x) and ev.cost(**tried[1]) > ev.cost(**x)


def _gn(problem):
    from tsid_fmu.search.verdict import gauss_newton_step

    s, r, jac = problem.jacobian
    _, step = gauss_newton_step(jac, r, s, problem.space.s_lower, problem.space.s_upper)
    return jac, r, step, GATE_RTOL * float(r @ r)


def test_trial_fractions_halve_down_to_the_gate_and_no_further():
    r, jac = np.array([1.0, 0.0]), np.array([[-1.0], [0.0]])
    step = np.array([1.0])  # predicted decrease at f: 2 f - f**2
    fractions = trial_fractions(jac, r, step, 0.1)
    assert fractions == [1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125]  # 0.0615 <= 0.1
    assert trial_reaches_gate(jac, r, step, 0.1, fractions)
    capped = trial_fractions(jac, r, step, 1e-6)
    assert len(capped) == MAX_TRIALS and not trial_reaches_gate(jac, r, step, 1e-6, capped)


@pytest.mark.parametrize("offset, holds", [(5e-4, True), (1e-2, False)])
def test_an_answer_no_fraction_lowers_holds_only_where_the_trial_reached_the_gate(offset, holds):
    """A Jacobian of the wrong sign points uphill: no fraction lowers the cost. Near the
    optimum its predicted gap reaches the gate in a few halvings, and the answer holds by
    trial; further off it does not within MAX_TRIALS, and the answer is not shown to be
    an optimum (it used to hold after the step and its half)."""
    x = {"a": 2.0 * (1 + offset), "k": 1.3, "c": 0.4}
    problem, ev = _problem_at(x, -1.0)
    gate = problem.stationarity()
    jac, r, step, limit = _gn(problem)
    fractions = trial_fractions(jac, r, step, limit)
    assert gate.gap > limit and problem.best[0] == ev.cost(**x)  # tried, none lower
    assert gate.holds is holds and trial_reaches_gate(jac, r, step, limit, fractions) is holds
    assert (2 < len(fractions) < MAX_TRIALS) is holds
    assert ("no lower point there" in gate.detail) is holds
    assert ("not shown to be an optimum" in gate.detail) is not holds


def test_where_no_fraction_is_lower_the_local_probes_decide():
    """A Jacobian the FMU solver's noise made can point anywhere: JModelica's Simple2R1C_ic
    (tsid init study) stopped at 1.25 times the noise floor, no fraction down to 1/512 of
    its step lower, while probes 0.005 of a first range away were 169 lower. The uphill
    Jacobian near the optimum stands in for it: the trial holds, the probes do not."""
    x = {"a": 2.0 * (1 + 5e-4), "k": 1.3, "c": 0.4}
    problem, ev = _problem_at(x, -1.0)
    gate = problem.stationarity(probe=0.001)
    assert not gate.holds and LOWER_PROBED in gate.detail
    assert problem.best[0] < ev.cost(**x)  # the probe is the answer now
    assert gate.by_trial  # the combinations' refinement may follow
    at_optimum, _, _ = _stage()
    problem, _ = _problem_at(dict(at_optimum.x), 1.0)
    assert problem.stationarity(probe=0.001).holds  # the model holds: no probe needed


def test_a_trial_point_lower_by_no_more_than_the_gate_refutes_nothing():
    """OpenModelica's MassSpringSubSystem2 (tsid init study) exited 1: its trials found
    points lower by 2.9e-5, 1.4e-8 of a cost of 2014, under the gate (1e-4 of it) that a
    predicted decrease must pass. The same gate now applies to what a trial finds."""
    x = {"a": 2.0 * (1 + 5e-4), "k": 1.3, "c": 0.4}
    problem, ev = _problem_at(x, -1.0)
    r_x = ev.residuals(x)
    real = ev.evaluate

    def barely_lower(sets, progress=None):  # every trial point 2e-7 of the cost lower
        out = real(sets, progress)
        out.residuals = [r_x * (1 - 1e-7) for _ in sets]
        out.costs[:, 0] = float(r_x @ r_x) * (1 - 1e-7) ** 2
        return out

    ev.evaluate = barely_lower
    gate = problem.stationarity()
    assert gate.holds and "lower the cost by no more than" in gate.detail
    assert problem.best[0] < ev.cost(**x)  # the lower point is kept as the answer
    problem, ev = _problem_at(x, -1.0)
    ev.evaluate = lambda sets, progress=None: real_lower(real, sets, r_x, 1e-3)
    assert not problem.stationarity().holds  # 2e-3 of the cost lower: that refutes it


def real_lower(real, sets, r_x, share):
    out = real(sets)
    out.residuals = [r_x * (1 - share) for _ in sets]
    out.costs[:, 0] = float(r_x @ r_x) * (1 - share) ** 2
    return out


def test_a_stop_on_xtol_reads_as_a_sentence_not_a_tuple(monkeypatch):
    # the xtol stop carries its kind as a second argument: the message once printed
    # "('the last step was shorter than xtol=1e-08', 'xtol')"
    def shorter(self, s, r):
        if self.linearised is not None:
            raise refine._Converged("the last step was shorter than xtol=1e-08", "xtol")

    monkeypatch.setattr(refine._Problem, "_check_step", shorter)
    result, _, _ = _stage()
    assert "least squares: the last step was shorter than xtol=1e-08; stopped" in result.message
    assert result.stop is LocalStop.XTOL and "('" not in result.message
    assert result.to_dict()["extra"]["stop"] == "xtol"  # the JSON form


def test_a_refinement_out_of_runs_says_so_and_the_search_goes_on_from_it():
    """A refinement stopped by its budget did not end by its own tests: its stage says
    ``stop = "limit"``, and the adaptive search treats it as not settled (on the SISO
    encoder's rough cost such a point passed the stationarity test at 1.014 x the
    optimum)."""
    from tsid_fmu.search.local.flow import _collapsed

    space = Space(
        {"a": [1.0, 1.5, 3.0], "k": [0.5, 1.0, 2.0], "c": [0.0, 0.5, 1.0]},
        {n: (0.0, math.inf) for n in TRUTH},
        LevelingOptions(),
    )
    start = {"a": 1.0, "k": 2.0, "c": 1.0}
    ev = ResidualEvaluator()
    limited = Method(cost="sse", refine_max_nfev=6)
    short = refine_stage("refinement", space, start, ev.cost(**start), ev, limited)
    assert short.status == 1 and short.message.startswith("simulation limit (6)")
    assert short.stop is LocalStop.LIMIT
    assert _collapsed(short) == (
        "the refinement ran out of simulations before its own tests ended it"
    )
    done, _, _ = _stage()
    assert done.stop is not LocalStop.LIMIT and _collapsed(done) is None


def test_an_answer_on_a_log_parameters_floor_is_tested_in_linear_coordinates():
    """A nesting value of 0 (a richer structure's extra damping) sits three decades below
    the first levels in logarithmic coordinates, where the cost is flat in the coordinate
    and an FMU's own noise swamps its Jacobian column: least squares stays and its test
    holds (here exit 0 at twice the optimum's cost; on the friction-law plant law 2 from
    law 1's answer at 36 times). The test is made again in linear coordinates there: a
    lower point fails it, and a refinement from that point reaches the optimum."""

    def model(a: float, d: float) -> np.ndarray:
        # a valley along a + d (viscous friction and spring damping), d seen alone, and
        # a solver's noise: 1e-4 of the sensor's, at random with the parameters
        return (a + d) * np.exp(-T) + 1e-2 * d * T + 1e-6 * np.sin(1e9 * (a + 3 * d) + 7 * T)

    ev = CurveEvaluator(model, model(2.0, 0.5) + NOISE, 0.01)
    space = Space({"a": [1.0, 2.0, 4.0], "d": [0.1, 1.0, 10.0]},
                  {"a": (0.0, math.inf), "d": (0.0, math.inf)}, LevelingOptions())  # fmt: skip
    assert list(space.log) == [False, True]
    assert space.floored({"a": 2.5, "d": 0.0}) == ["d"]
    # near it too: the flat coordinate lets the refinement wander about the floor by its
    # noise (the refinement below ends 5 % above it on one platform, at or below it on CI)
    assert space.floored({"a": 2.5, "d": 1.05e-4}) == ["d"]
    assert space.floored({"a": 2.5, "d": 1e-3}) == []
    method = Method(cost="sse", refine="least_squares", refine_max_nfev=200)

    def refined(start):
        first = ev.evaluate([start])
        return refine_stage("refinement", space, start, float(first.costs[0, 0]), ev, method,
                            start_residuals=first.residuals[0])  # fmt: skip

    stuck = refined({"a": 2.5, "d": 0.0})  # the simpler structure's answer: a carries a + d
    assert stuck.solver.off_the_floor["parameters"] == ["d"]
    assert stuck.status == 1 and "on the floor" in stuck.message, stuck.message
    assert not space.floored(stuck.x)
    again = refined(stuck.x)
    basis = np.column_stack([np.exp(-T), np.exp(-T) + 1e-2 * T]) / 0.01
    a, d = np.linalg.lstsq(basis, ev.measured / 0.01, rcond=None)[0]
    assert again.status == 0 and again.cost <= 1.0001 * ev.cost(a=a, d=d)


def test_a_refinement_out_of_runs_still_tries_its_step():
    """ "No runs left" decides nothing: the stationarity test of a refinement that spent
    its limit still simulates its step (at most MAX_TRIALS runs more), so that its verdict
    can send the search on, to the refinement in combinations where two parameters act
    through one (the SISO plant's damping, seed 5: warm refinements out of runs along
    F_vm + B_s, the structure chosen at 1.0054 times the optimum's cost, exit 1)."""

    def model(a: float, d: float) -> np.ndarray:
        return (a + d) * np.exp(-T) + 1e-3 * d * T  # a valley along a + d

    ev = CurveEvaluator(model, model(2.0, 0.5) + NOISE, 0.01)
    space = Space({"a": [1.0, 2.0, 4.0], "d": [0.1, 1.0, 10.0]},
                  {"a": (0.0, math.inf), "d": (0.0, math.inf)}, LevelingOptions())  # fmt: skip
    start = {"a": 2.5, "d": 0.05}
    first = ev.evaluate([start])
    out = refine_stage("refinement", space, start, float(first.costs[0, 0]), ev,
                       Method(cost="sse", refine="least_squares", refine_max_nfev=20),
                       start_residuals=first.residuals[0])  # fmt: skip
    assert out.status == 1 and "simulation limit (20)" in out.message
    assert out.stationarity is not None and out.stationarity.by_trial
    assert 20 < out.nfev <= 20 + MAX_TRIALS


def test_a_floor_test_held_by_its_trials_hands_its_linear_pairs_to_the_combinations(
    monkeypatch,
):
    """On the floor of ``d``'s logarithmic coordinate its column is zero, so the
    refinement's own Jacobian shows no valley; the floor test's linear one does. Where
    that test's trials along the Gauss-Newton step find nothing lower (a rough cost's
    differences: SISO rig, eval seed 10003, B_s at 2.4e-17 and 1.003 x the optimum, the
    cost falling 65 per unit of B_s along F_vm + B_s), it held by simulation, and its
    pairs go on to the refinement in the combinations, which leaves the floor."""
    from tsid_fmu.search.local.combined import refine_in_combinations
    from tsid_fmu.search.local.problem import _problem_at
    from tsid_fmu.search.stage import StageResult
    from tsid_fmu.search.verdict import GN_TEST, Stationarity

    def model(a: float, d: float) -> np.ndarray:
        return (a + d) * np.exp(-T) + 1e-2 * d * T  # the valley along a + d; d seen alone

    ev = CurveEvaluator(model, model(2.0, 0.5) + NOISE, 0.01)
    levels = {"a": [1.0, 2.0, 4.0], "d": [0.1, 1.0, 10.0]}
    bounds = {"a": (0.0, math.inf), "d": (0.0, math.inf)}
    space = Space(levels, bounds, LevelingOptions())
    monkeypatch.setattr(refine, "bounded_trials", lambda jac, r, s, *_: [s])  # it misses
    start = {"a": 2.5, "d": 0.0}
    first = ev.evaluate([start])
    cost = float(first.costs[0, 0])
    problem, _ = _problem_at(space, start, cost, ev, 100, None, first.residuals[0])
    held = Stationarity(True, GN_TEST, 0.0, cost, "no decrease predicted")
    notes = SolverNotes()
    # a gate of 1e-4 of a noise floor of 1e4: the differences' own steps are no lower
    test, pairs = refine._floor_test(space, problem, held, None, 1e4, notes)
    assert notes.off_the_floor["parameters"] == ["d"]
    assert test.holds and test.decided_by == "trial" and test.by_trial
    assert [p[:2] for p in pairs] == [["a", "d"]] and abs(pairs[0][2] - 1) < 0.05

    class Study:
        parameter_names = ("a", "d")
        method = Method(cost="sse")

        def identify_names(self):
            return ["measured"]

        def first_levels(self):
            return levels

        def bounds(self):
            return bounds

    class Evs:
        def get(self, names, experiments, fixed):
            return ev

    stage = StageResult("refinement", "refinement", start, cost, 5, "", parallel=pairs,
                        stationarity=test, stop=LocalStop.XTOL)  # fmt: skip
    lower, _ = refine_in_combinations(Study(), Evs(), [stage])
    assert lower is not None and lower.cost < 0.5 * cost
    assert abs(lower.x["d"] / 0.5 - 1) < 0.1
    # the rule removed (held as the model's test, no pairs): nothing follows
    stage = StageResult("refinement", "refinement", start, cost, 5, "",
                        stationarity=held, stop=LocalStop.XTOL)  # fmt: skip
    assert refine_in_combinations(Study(), Evs(), [stage]) == (None, 0)
