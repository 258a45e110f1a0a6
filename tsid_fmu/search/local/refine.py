"""The optional refinement stage: a local least-squares polish of the same cost.

Not a Taguchi iteration, and named for what it is: SciPy's trust-region reflective
least squares (:func:`scipy.optimize.least_squares`, ``method="trf"``) on the residual
signals whose sum of squares *is* the study's ``sse`` cost, started from the Taguchi
stage's answer, within the parameters' bounds, in the same search coordinates
(:mod:`tsid_fmu.search.space`). Its Jacobians are forward differences whose ``p``
simulations go to the evaluator as one batch, so they run in parallel. It stops at
SciPy's tolerances or at ``refine_max_nfev`` simulations, and its answer is the best set
it evaluated, so it never ends worse than it started.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.numerics.lsq import Solved, Stop, trust_region
from tsid_fmu.numerics.tuning import FD_STEP, GTOL, PROBLEM_FTOL, XTOL
from tsid_fmu.search.local.columns import named_pairs
from tsid_fmu.search.local.problem import (
    _Budget,
    _Converged,
    _Problem,
    _problem_at,
)
from tsid_fmu.search.outcome import LocalStop, SolverNotes
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.search.taguchi.iteration import ProgressCallback
from tsid_fmu.search.verdict import (
    GN_TRIED,
    LOWER_TRIED,
    MAX_TRIALS,
    Stationarity,
    bounded_trials,
)
from tsid_fmu.study.schema import Method

__all__ = ["FD_STEP", "STOPPED", "refine_stage"]

STOPPED = {
    LocalStop.GTOL: "the slope of the cost is below its tolerance",
    LocalStop.FTOL: "the last step lowered the cost by less than its tolerance",
    LocalStop.XTOL: "the last step moved the parameters by less than their tolerance",
}
"""Why SciPy's least squares stopped, by its tolerance's name, in a practitioner's words
(the message is made from the code, never SciPy's own text passed through)."""


def _solve(
    problem: _Problem, s0: np.ndarray, space: Space, limit: int, notes: SolverNotes
) -> tuple[int, str]:
    """Run SciPy's trust-region least squares from ``s0``; return status and message.

    Why it stopped goes into :attr:`_Problem.stop`, SciPy's counts into ``notes``.
    The first Jacobian, at ``s0``, decides which columns are held
    (:attr:`_Problem.held`): SciPy then moves only the others. A zero column makes
    its trust-region subproblem rank-deficient, and the exact Gauss-Newton step is
    never taken: on a lag with one parameter that acts on nothing
    (``benchmarks/conformance.py``'s ``NO_EFFECT``), 67 runs against 16 without it.
    Every Jacobian differences the held columns too, so the last one, which the
    stationarity test reads, has them all; where one is seen, SciPy starts again from
    that Jacobian's point with its parameter freed.
    """
    try:
        if not problem.decided:
            problem.jac(s0)  # SciPy's first, kept with its residuals for SciPy
            problem.reuse, problem.linearised = problem.jacobian, None
            problem.known = problem.last
    except _Budget:
        problem.stop = LocalStop.LIMIT
        return 1, f"simulation limit ({limit}) of the refinement reached"
    while True:
        solved = _run_free(problem, s0, space)
        if not isinstance(solved.raised, _Freed) or problem.jacobian is None:
            break
        s0, r0, _ = problem.jacobian  # SciPy starts again here, with this Jacobian
        problem.reuse, problem.linearised = problem.jacobian, None
        problem.known = (s0.copy(), r0)
    if isinstance(solved.raised, _Converged):
        problem.stop = solved.raised.stop
        return 0, f"least squares: {solved.raised.args[0]}; stopped before another Jacobian"
    if isinstance(solved.raised, _Budget):
        problem.stop = LocalStop.LIMIT
        return 1, f"simulation limit ({limit}) of the refinement reached"
    if solved.stop is Stop.FAILED:  # the best set so far is kept
        problem.stop = LocalStop.NONE
        return 1, f"least squares could not go on ({solved.error})"
    problem.stop = LocalStop.NONE if solved.stop is Stop.MAX_NFEV else LocalStop(solved.stop)
    notes.nfev, notes.njev = solved.nfev, solved.njev
    said = STOPPED.get(problem.stop, "it stopped")
    return 0, f"least squares: {said}"


class _Freed(Exception):
    """A held parameter's column was seen: SciPy starts again with it free."""


def _run_free(problem: _Problem, s0: np.ndarray, space: Space) -> Solved:
    """Run SciPy from ``s0`` over the parameters not held (:attr:`_Problem.held`)."""
    active = np.flatnonzero(~problem.held)
    held = int(problem.held.sum())

    def embed(z: np.ndarray) -> np.ndarray:
        s = s0.copy()
        s[active] = z
        return s

    def jac(z: np.ndarray) -> np.ndarray:
        out = problem.jac(embed(z))
        if int(problem.held.sum()) < held:
            raise _Freed
        # C order, as the Jacobian itself: SciPy's factorisations of an F-ordered copy
        # differ in the last digits, and so would every refinement that holds nothing
        return out if active.size == out.shape[1] else np.ascontiguousarray(out[:, active])

    return trust_region(
        lambda z: problem.fun(embed(z)),
        s0[active],
        jac,
        bounds=(space.s_lower[active], space.s_upper[active]),
        stops=(_Converged, _Budget, _Freed),
        ftol=PROBLEM_FTOL,
        xtol=XTOL,
        gtol=GTOL,
        max_nfev=10_000,
    )


def _again_wider(
    problem: _Problem, space: Space, limit: int, notes: SolverNotes, message: str
) -> tuple[int, str]:
    """Run the least squares again from the best point, with steps that beat the noise.

    A forward difference of :data:`FD_STEP` that the FMU's own solver noise spoils can
    stop the trust region short and pass the stationarity test (JModelica's
    ``Simple2R1C``: exit 0 at 13 % above the truth's cost). Wider steps from the start
    changed the answers of models with events (dry friction, where short steps serve
    better), and a second pass wherever a column was spoiled cost 14 % more simulations
    on the generalisation evaluation seeds for no success: so this pass runs only where
    the widened Jacobian at the best point predicts a decrease
    (:meth:`_Problem.doubtful`); it can only lower the cost (:mod:`tsid_fmu.numerics.fdstep`).
    """
    problem.linearised, problem.last = None, None
    s = space.to_s(problem.best[1])
    if problem.best_r is not None:
        problem.known = (s.copy(), problem.best_r)
    counts = {"nfev": notes.nfev, "njev": notes.njev}
    first = {"stop": problem.stop.value, **{k: v for k, v in counts.items() if v is not None}}
    status, again = _solve(problem, s, space, limit, notes)
    notes.first_pass = first
    return status, f"{message}; again with difference steps that beat the FMU's noise: {again}"


def _released(problem: _Problem, space: Space, message: str) -> tuple[str, list[str]]:
    """Say which parameters the refinement held to the end, and which it freed.

    Returns the message and the names held.
    """
    if problem.freed:
        message += f"; freed {', '.join(problem.freed)} where the outputs began to depend on it"
    held = _held(problem, space)
    if held:
        them = "it" if len(held) == 1 else "them"
        message += f"; held {', '.join(held)}: the outputs do not depend on {them}"
    return message, held


def _held(problem: _Problem, space: Space) -> list[str]:
    """Return the names of the parameters the refinement holds (:attr:`_Problem.held`)."""
    return [space.names[k] for k in np.flatnonzero(problem.held)]


def _floor_test(
    space: Space,
    problem: _Problem,
    gate: Stationarity,
    fixed: Mapping[str, float] | None,
    floor: float,
    notes: SolverNotes,
) -> tuple[Stationarity, list[list] | None]:
    """Test the answer again in linear coordinates where it is on a log floor.

    On a log parameter's floor (:meth:`~tsid_fmu.search.space.Space.floored`: 0, or
    near it) the cost is flat in that coordinate, so the test in the search's
    coordinates holds whatever the data say. In :meth:`anchored
    <tsid_fmu.search.space.Space.anchored>` coordinates about the answer the step within
    the bounds, all parameters together, is simulated with its halves down to the gate
    (:func:`~tsid_fmu.search.verdict.bounded_trials`), with its own ``2 (p + 1) + 12``
    runs; a point lower by more than the gate becomes the answer, and the test fails
    (the callers refine again from it). Measured on the friction-law plant (law 2 from
    law 1's answer, ``F_vm`` = 0, on a chirp): least squares in logarithmic coordinates
    stayed there at 36 times the optimum's cost and passed its test.

    Held by those trials, the test was decided by simulation (``GN_TRIED``), and the
    linear Jacobian's parallel pairs are returned with it: there the floored parameter
    has the slope that its logarithmic column lacks, so the refinement in the
    combinations (:mod:`~tsid_fmu.search.local.combined`) can follow a valley off the
    floor that a step along the Gauss-Newton direction does not find. Returns the test
    and those pairs (None where the answer is not on a floor, or no Jacobian was made).
    """
    cost, x = problem.best
    floored = space.floored(x)
    if not floored:
        return gate, None
    line, runs = space.anchored(x), 2 * (space.dim + 1) + MAX_TRIALS
    trial, s0 = _problem_at(line, x, cost, problem.evaluator, runs, fixed, problem.best_r)
    pairs = None
    try:
        jac = trial.jac(s0)
        if trial.last is not None and np.isfinite(jac).all():
            pairs = named_pairs(line, line.to_x(s0), jac)
            points = bounded_trials(jac, trial.last[1], s0, line.s_lower, line.s_upper,
                                    trial.gate(cost, floor))  # fmt: skip
            trial._residuals([line.to_x(t) for t in points])
    except (_Budget, _Converged):
        pass
    gain = cost - trial.best[0]
    notes.off_the_floor = {"parameters": floored, "cost": float(trial.best[0])}
    where = f"{', '.join(floored)} on the floor of its logarithmic coordinate"
    if gain <= problem.gate(cost, floor):
        said = f"{gate.detail}; {where}: a step in linear coordinates is no lower"
        tried = pairs is not None  # its trials decided it
        test, by = (GN_TRIED, "trial") if tried else (gate.test, gate.decided_by)
        return Stationarity(True, test, gate.gap, cost, said, by), pairs
    problem.best, problem.best_r = trial.best, trial.best_r
    said = f"{where}, where it is flat: in linear coordinates, {LOWER_TRIED} {gain:.3g}"
    return Stationarity(False, gate.test, gain, cost, said, "trial", gain), pairs


def _keep_pairs(problem: _Problem, space: Space, gate: Stationarity) -> list[list] | None:
    """Return the last Jacobian's parallel pairs where the refinement in combinations reads them.

    That is where the test was decided by a trial, or the refinement's own tests did not
    end it (:attr:`~tsid_fmu.search.outcome.LocalStop.unfinished`): no runs are spent again
    on a Jacobian there.
    """
    if problem.jacobian is None or not (gate.by_trial or problem.stop.unfinished):
        return None
    s_lin, _, jac = problem.jacobian
    return named_pairs(space, space.to_x(s_lin), jac)


def _tested(
    space: Space,
    problem: _Problem,
    fixed: Mapping[str, float] | None,
    floor: float,
    tolerance: float,
    notes: SolverNotes,
) -> tuple[Stationarity, list[list] | None]:
    """Run the stationarity test at the answer; return it and the parallel pairs kept.

    On a log floor the test is made again in linear coordinates (:func:`_floor_test`);
    the parallel pairs the combination step reads are kept with it (:func:`_keep_pairs`).
    """
    gate = problem.stationarity(floor, tolerance)
    floor_pairs = None
    if gate.holds:
        gate, floor_pairs = _floor_test(space, problem, gate, fixed, floor, notes)
    if floor_pairs is not None and gate.by_trial:
        return gate, floor_pairs  # where the floored parameter has a slope
    return gate, _keep_pairs(problem, space, gate)


def refine_stage(
    name: str,
    space: Space,
    start: Mapping[str, float],
    start_cost: float,
    evaluator: Evaluator,
    method: Method,
    fixed: Mapping[str, float] | None = None,
    progress: ProgressCallback | None = None,
    start_residuals: np.ndarray | None = None,
    floor: float = 0.0,
    waypoint: bool = False,
) -> StageResult:
    """Polish ``start`` by trust-region least squares on the same cost (``sse``).

    Parameters
    ----------
    name : str
        Stage name.
    space : Space
        Search coordinates and bounds of the varied parameters.
    start, start_cost : mapping, float
        Starting parameter set (varied parameters) and its cost; the answer is never worse.
    evaluator : Evaluator
        Scores parameter sets (its residuals are the least-squares residuals).
    method : Method
        ``refine_max_nfev`` bounds the simulations.
    fixed : mapping, optional
        Parameters not varied, merged into the answer.
    progress : callable, optional
        Receives ``("refinement", {...})`` when the stage starts and ends.
    start_residuals : numpy.ndarray, optional
        The evaluator's residuals of ``start``, if the caller has them: the stage then
        does not simulate ``start`` again.
    floor : float
        The noise floor of the cost (:func:`~tsid_fmu.search.verdict.noise_floor`): the
        stationarity test measures the predicted decrease against it where the cost is
        below it (an overestimated noise), so that it does not ask for decimals the data
        do not carry.
    waypoint : bool
        A horizon's: :attr:`~tsid_fmu.search.outcome.LocalStop.WAYPOINT`.

    Returns
    -------
    StageResult
    """
    limit = method.refine_max_nfev or 30 * (space.dim + 1) * len(evaluator.spec.experiments)
    n0 = evaluator.nfev
    if progress:
        progress("refinement", {"stage": name, "cost": start_cost})
    notes = SolverNotes(method="scipy.optimize.least_squares(method='trf')")
    at = (start, start_cost, evaluator, limit, fixed, start_residuals, waypoint)
    problem, s0 = _problem_at(space, *at)
    status, message = _solve(problem, s0, space, limit, notes)
    if status == 0 and problem.spoiled and problem.doubtful(floor):
        status, message = _again_wider(problem, space, limit, notes, message)
    message, held = _released(problem, space, message)
    gate, parallel = _tested(space, problem, fixed, floor, method.leveling.tolerance, notes)
    (cost, x), nfev = problem.best, evaluator.nfev - n0
    if status == 0 and not gate.holds:
        status = 1
        message += f"; not shown to be an optimum: {gate.detail}"
    if progress:
        progress("refinement done", {"stage": name, "cost": cost, "nfev": nfev})
    return StageResult(
        name=name,
        kind=StageKind.REFINEMENT,
        x={**(fixed or {}), **x},
        cost=cost,
        nfev=nfev,
        message=message,
        status=status,
        stationarity=gate,
        stop=problem.stop,
        parallel=parallel,
        start_cost=float(start_cost),
        held=held,
        solver=notes,
    )
