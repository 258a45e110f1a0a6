"""The optional refinement stage: a local least-squares polish of the same cost.

Not a Taguchi iteration, and named for what it is: SciPy's trust-region reflective
least squares (:func:`scipy.optimize.least_squares`, ``method="trf"``) on the residual
signals whose sum of squares *is* the study's ``sse`` cost, started from the Taguchi
stage's answer, within the parameters' bounds, in the same search coordinates
(:mod:`tsid_fmu.search.space`). Its Jacobians are forward differences whose ``p``
simulations go to the evaluator as one batch, so they run in parallel. It stops at
SciPy's tolerances or at ``refine_max_nfev`` simulations, and its answer is the best set
it evaluated, so it never ends worse than it started.

Two simulations SciPy would spend are not: the start's residuals come from the caller,
which has just scored it; and SciPy's own ``ftol``/``xtol`` tests on an accepted step are
checked before the Jacobian at the new point is paid for (``p`` simulations SciPy
computes and then discards when those tests stop it). Unlike SciPy's ``ftol`` test,
this one does not also ask that the step's actual reduction be at least a quarter of the
predicted one: a step that lowers the cost by less than ``ftol`` of itself ends the stage.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.search.local.columns import named_pairs
from tsid_fmu.search.local.fdstep import known_noise, noise_of, solver_noise, steps_for
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.taguchi.iteration import ProgressCallback
from tsid_fmu.search.verdict import (
    GATE_RTOL,
    GN_TEST,
    GN_TRIED,
    LOWER_PROBED,
    Stationarity,
    bounded_trials,
    decided_by_trial,
    gauss_newton_step,
    gauss_newton_test,
    probe_points,
)
from tsid_fmu.study.schema import Method

__all__ = ["FD_STEP", "refine_stage"]

FD_STEP = 1e-5
"""Forward-difference step in search coordinates (1e-5 of a first range's width), where
the FMU's own noise allows it (:mod:`tsid_fmu.search.local.fdstep` widens it where not).

Small enough for a sharply curved valley (a swinging pendulum's cost over seconds of
data: 1e-3 gave secants whose steps kept failing), large against the integrators' error
(the own Model Exchange solver's rtol is 1e-8)."""

_FAILED = 1e10
"""Residual value given to every sample of a failed simulation (its cost is then huge)."""


_FTOL = _XTOL = _GTOL = 1e-8
"""SciPy's termination tolerances, as :func:`scipy.optimize.least_squares` names them."""


class _Budget(Exception):
    """The refinement ran out of simulations."""


class _Converged(Exception):
    """An accepted step met SciPy's ``ftol`` or ``xtol`` test (see the module docstring)."""


class _Problem:
    """Residuals and Jacobians of the cost in search coordinates, counting simulations."""

    def __init__(self, space: Space, evaluator: Evaluator, limit: int, fixed: Mapping[str, float]):
        self.space, self.evaluator, self.limit = space, evaluator, limit
        self.fixed = dict(fixed)
        self.start = evaluator.nfev
        self.best: tuple[float, dict[str, float]] = (math.inf, {})
        self.best_r: np.ndarray | None = None
        self.last: tuple[np.ndarray, np.ndarray] | None = None
        self.jacobian: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.known: tuple[np.ndarray, np.ndarray] | None = None
        self.linearised: tuple[np.ndarray, float] | None = None
        self.calls = 0
        self.size = 0
        self.steps = np.full(space.dim, FD_STEP)  # forward-difference steps (:mod:`.fdstep`)
        self.spoiled = False  # a column's difference was mostly the FMU's own noise
        self.widen = False  # widen such columns' steps (the second pass of refine_stage)
        self.reuse: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def _residuals(self, sets: list[dict[str, float]]) -> list[np.ndarray]:
        if self.evaluator.nfev - self.start >= self.limit:
            raise _Budget
        ev = self.evaluator.evaluate(sets)
        out = []
        for x, cost, r in zip(
            sets, ev.costs[:, 0], ev.residuals or [None] * len(sets), strict=True
        ):
            if r is None or not np.isfinite(cost):
                r = np.full(self.size or 1, _FAILED)
            self.size = self.size or r.size
            if cost < self.best[0]:
                self.best, self.best_r = (float(cost), dict(x)), r
            out.append(r)
        return out

    def fun(self, s: np.ndarray) -> np.ndarray:
        self.calls += 1
        if self.known is not None and np.array_equal(self.known[0], s):
            r = self.known[1]
        else:
            r = self._residuals([self.space.to_x(s)])[0]
        self.last = (s.copy(), r)
        return r

    def _check_step(self, s: np.ndarray, r: np.ndarray) -> None:
        """Raise :class:`_Converged` if the step to ``s`` meets SciPy's ftol or xtol test."""
        if self.linearised is None:
            return
        s_old, cost_old = self.linearised
        reduction = cost_old - 0.5 * float(np.dot(r, r))
        step = float(np.linalg.norm(s - s_old))
        if reduction < _FTOL * cost_old:
            raise _Converged(f"the last step lowered the cost by less than ftol={_FTOL:g}")
        if step < _XTOL * (_XTOL + float(np.linalg.norm(s_old))):
            raise _Converged(f"the last step was shorter than xtol={_XTOL:g}", "xtol")

    def jac(self, s: np.ndarray) -> np.ndarray:
        if self.last is None or not np.array_equal(self.last[0], s):
            self.fun(s)
        assert self.last is not None
        r0 = self.last[1]
        self._check_step(s, r0)
        self.linearised = (s.copy(), 0.5 * float(np.dot(r0, r0)))
        if self.reuse is not None and np.array_equal(self.reuse[0], s):
            jac, self.reuse = self.reuse[2], None  # :meth:`doubtful`'s, at this point
            self.jacobian = (s.copy(), r0, jac)
            return jac
        jac = self._columns(s, r0, np.arange(s.size))
        try:
            noise = noise_of(self.evaluator, lambda: self._noise(s, r0))
        except _Budget:  # no runs left to measure it: this Jacobian as it is
            noise = 0.0
        wider = steps_for(self.steps, jac, noise)
        redo = np.flatnonzero(wider > 1.5 * self.steps)  # columns the FMU's noise spoils
        self.spoiled = self.spoiled or bool(redo.size)
        if redo.size and self.widen:
            self.steps = np.where(wider > 1.5 * self.steps, wider, self.steps)
            jac[:, redo] = self._columns(s, r0, redo)
        self.jacobian = (s.copy(), r0, jac)
        return jac

    def gate(self, cost: float, floor: float) -> float:
        """Return the decrease of the cost below which nothing is refuted.

        :data:`~tsid_fmu.search.verdict.GATE_RTOL` of the cost (or of the noise floor,
        where larger), or, where the FMU's own solver adds noise of ``sigma`` per sample
        (:mod:`.fdstep`), two standard deviations of the cost's change that noise makes
        between two points, ``2 * 2 |r| sigma``: a trial lower by less is the noise.
        """
        noise, r = known_noise(self.evaluator), self.best_r
        own = 4.0 * float(np.linalg.norm(r)) * noise if r is not None and noise > 0 else 0.0
        return max(GATE_RTOL * max(cost, floor), own)

    def doubtful(self, floor: float) -> bool:
        """Whether steps that beat the FMU's noise see a decrease the short ones missed.

        The Jacobian at the best point, with the spoiled columns' steps widened: where its
        projected Gauss-Newton step predicts more than the gate, the short steps' answer
        is in doubt (:func:`_again_wider`); otherwise it stands, and this Jacobian is the
        one the stationarity test reads.
        """
        cost, x = self.best
        s = self.space.to_s(x)
        self.widen, self.linearised, self.last = True, None, None
        if self.best_r is not None:
            self.known = (s.copy(), self.best_r)
        try:
            jac = self.jac(s)
        except (_Budget, _Converged):
            return False
        assert self.last is not None
        gap, _ = gauss_newton_step(jac, self.last[1], s, self.space.s_lower, self.space.s_upper)
        self.reuse = self.jacobian
        return gap > self.gate(cost, floor)

    def _columns(self, s: np.ndarray, r0: np.ndarray, which: np.ndarray) -> np.ndarray:
        """Forward differences of the columns ``which``, each with its step."""
        h = self.steps[which]
        h = np.where(s[which] + h <= self.space.s_upper[which], h, -h)
        trial = []
        for j, hj in zip(which, h, strict=True):
            t = s.copy()
            t[j] += hj
            trial.append(self.space.to_x(t))
        cols = self._residuals(trial)
        return np.column_stack([(c - r0) / hj for c, hj in zip(cols, h, strict=True)])

    def _noise(self, s: np.ndarray, r0: np.ndarray) -> float:
        """Return the FMU's noise under parameter changes, by ECnoise (:mod:`.fdstep`)."""
        return solver_noise(
            lambda pts: self._residuals([self.space.to_x(self.space.clip(t)) for t in pts]),
            s,
            r0,
            FD_STEP,
            self.space.s_upper,
        )

    def stationarity(self, floor: float = 0.0, probe: float = 0.0) -> Stationarity:
        """Test the answer with the last Jacobian (see :mod:`tsid_fmu.search.verdict`).

        At the answer's own residuals where the refinement has them; the Jacobian is the
        last one computed (at the answer, or one accepted step before it). Where the
        predicted decrease is too large, the predicted step is tried, halved down to the
        gate (:func:`~tsid_fmu.search.verdict.trial_fractions`): a lower cost there
        becomes the answer and the test fails. If none is lower, the first-order model
        does not hold this close to the answer (events, or a Jacobian the FMU solver's
        noise made), and it cannot show an optimum: with ``probe`` > 0, the local
        probes ``probe`` of a first range either side along every parameter decide
        (:func:`~tsid_fmu.search.verdict.probe_points`, ``2 p`` simulations).
        """
        cost, x = self.best
        if self.jacobian is None or not math.isfinite(cost):
            return Stationarity(False, GN_TEST, math.inf, cost, "no Jacobian")
        s_lin, r_lin, jac = self.jacobian
        s = self.space.to_s(x)
        r = self.best_r if self.best_r is not None else r_lin
        if not np.array_equal(s, s_lin) and self.best_r is None:
            s = s_lin
        scale, gate = max(cost, floor), self.gate(cost, floor)

        def say(gap: float) -> str:
            share = gap / scale if scale > 0 else 0.0
            said = (
                f"the projected Gauss-Newton step predicts a decrease of {gap:.3g} "
                f"({share:.2g} of the cost or the noise floor, whichever is larger; "
                f"{'at most' if gap <= gate else 'more than'} {GATE_RTOL:g})"
            )
            if gate > GATE_RTOL * scale:
                said += f"; the FMU's own noise makes a change of the cost below {gate:.3g} moot"
            return said

        def simulate(points: list[np.ndarray]) -> bool:
            try:
                self._residuals([self.space.to_x(self.space.clip(t)) for t in points])
            except _Budget:
                return False
            return True

        bounds = (self.space.s_lower, self.space.s_upper)
        found = gauss_newton_test(
            jac, r, s, bounds, cost, gate, say, simulate, lambda: self.best[0]
        )
        if found.test != GN_TRIED or not found.holds or probe <= 0:
            return found
        test, gap, detail = found.test, found.gap, found.detail
        try:
            self._residuals(probe_points(self.space, x, probe))
        except _Budget:
            return Stationarity(False, test, gap, cost, detail + "; no runs left for probes")
        if cost - self.best[0] > gate:
            detail += f"; {LOWER_PROBED} {cost - self.best[0]:.3g} ({probe:g} of a first range)"
            return Stationarity(False, test, gap, cost, detail)
        detail += f"; no probe {probe:g} of a first range either side is lower"
        return Stationarity(True, test, gap, cost, detail)


def _problem_at(
    space: Space,
    start: Mapping[str, float],
    start_cost: float,
    evaluator: Evaluator,
    limit: int,
    fixed: Mapping[str, float] | None,
    start_residuals: np.ndarray | None,
) -> tuple[_Problem, np.ndarray]:
    """Return the least-squares problem at ``start`` and its start point, just inside bounds.

    The start's residuals, where the caller has them, are kept, so that it is not
    simulated again.
    """
    problem = _Problem(space, evaluator, limit, fixed or {})
    problem.best = (float(start_cost), {n: float(start[n]) for n in space.names})
    width = space.s_upper - space.s_lower
    s_start = space.to_s(start)
    s0 = np.clip(
        s_start,
        space.s_lower + 1e-9 * np.minimum(width, 1.0),
        space.s_upper - 1e-9 * np.minimum(width, 1.0),
    )
    if start_residuals is not None and np.array_equal(s0, s_start):
        problem.known = (s0.copy(), start_residuals)
        problem.size = start_residuals.size
        problem.best_r = start_residuals
    return problem, s0


def _solve(
    problem: _Problem, s0: np.ndarray, space: Space, limit: int, extra: dict[str, Any]
) -> tuple[int, str]:
    """Run SciPy's trust-region least squares from ``s0``; return status and message.

    Why it stopped (``stop``: gtol, ftol or xtol) and its counts go into ``extra``.
    """
    from scipy.optimize import least_squares

    try:
        out = least_squares(
            problem.fun,
            s0,
            jac=problem.jac,
            bounds=(space.s_lower, space.s_upper),
            method="trf",
            ftol=_FTOL,
            xtol=_XTOL,
            gtol=_GTOL,
            max_nfev=10_000,
        )
        extra["stop"] = {1: "gtol", 2: "ftol", 3: "xtol", 4: "xtol"}.get(int(out.status), "")
        extra.update(nfev=int(out.nfev), njev=int(out.njev or 0))
        return 0, f"least squares: {out.message}"
    except _Converged as stop:
        extra["stop"] = stop.args[1] if len(stop.args) > 1 else "ftol"
        return 0, f"least squares: {stop.args[0]}; stopped before another Jacobian"
    except _Budget:
        extra["stop"] = "limit"
        return 1, f"simulation limit ({limit}) of the refinement reached"
    except (ValueError, np.linalg.LinAlgError) as exc:  # the best set so far is kept
        return 1, f"least squares could not go on ({exc})"


def _again_wider(
    problem: _Problem, space: Space, limit: int, extra: dict[str, Any], message: str
) -> tuple[int, str]:
    """Run the least squares again from the best point, with steps that beat the noise.

    A forward difference of :data:`FD_STEP` that the FMU's own solver noise spoils can
    stop the trust region short and pass the stationarity test (JModelica's
    ``Simple2R1C``: exit 0 at 13 % above the truth's cost). Wider steps from the start
    changed the answers of models with events (dry friction, where short steps serve
    better), and a second pass wherever a column was spoiled cost 14 % more simulations
    on the generalisation evaluation seeds for no success: so this pass runs only where
    the widened Jacobian at the best point predicts a decrease
    (:meth:`_Problem.doubtful`); it can only lower the cost (:mod:`.fdstep`).
    """
    problem.linearised, problem.last = None, None
    s = space.to_s(problem.best[1])
    if problem.best_r is not None:
        problem.known = (s.copy(), problem.best_r)
    first = dict(extra)
    status, again = _solve(problem, s, space, limit, extra)
    extra["first_pass"] = {k: first[k] for k in ("stop", "nfev", "njev") if k in first}
    return status, f"{message}; again with difference steps that beat the FMU's noise: {again}"


def _off_the_floor(
    space: Space,
    start: Mapping[str, float],
    start_cost: float,
    evaluator: Evaluator,
    limit: int,
    fixed: Mapping[str, float] | None,
    start_residuals: np.ndarray | None,
    floor: float,
) -> tuple[dict[str, float], float, np.ndarray | None]:
    """Leave a log parameter's floor by one Gauss-Newton step in linear coordinates.

    On its floor (:meth:`~tsid_fmu.search.space.Space.floored`: a nesting value of 0,
    embedded) the cost is flat in the coordinate, and a valley along a sum (viscous
    friction and spring damping) is bent by the logarithm. In :meth:`anchored
    <tsid_fmu.search.space.Space.anchored>` coordinates the step within the bounds, all
    parameters together, is simulated with its halves down to the gate; the lowest point
    is the new start. Measured on the friction-law plant (law 2 from law 1's answer on a
    chirp): least squares in logarithmic coordinates stopped at 36 times the optimum's.
    """
    line = space.anchored(start)
    problem, s0 = _problem_at(line, start, start_cost, evaluator, limit, fixed, start_residuals)
    try:
        jac = problem.jac(s0)
        r = problem.last[1] if problem.last is not None else start_residuals
        if r is not None and np.isfinite(jac).all():
            gate = problem.gate(start_cost, floor)
            points = bounded_trials(jac, r, s0, line.s_lower, line.s_upper, gate)
            problem._residuals([line.to_x(t) for t in points])
    except (_Budget, _Converged):
        pass
    cost, x = problem.best
    if cost >= start_cost:
        return dict(start), start_cost, start_residuals
    return {**dict(start), **x}, cost, problem.best_r


def _started(
    space: Space,
    start: Mapping[str, float],
    start_cost: float,
    evaluator: Evaluator,
    limit: int,
    fixed: Mapping[str, float] | None,
    start_residuals: np.ndarray | None,
    floor: float,
    extra: dict[str, Any],
) -> tuple[_Problem, np.ndarray]:
    """Return the refinement's problem and start point, off any log parameter's floor."""
    n0, floored = evaluator.nfev, space.floored(start)
    if floored:
        start, start_cost, start_residuals = _off_the_floor(
            space, start, start_cost, evaluator, limit, fixed, start_residuals, floor
        )
        extra["off_the_floor"] = {"parameters": floored, "cost": float(start_cost)}
    left = max(limit - (evaluator.nfev - n0), 1)
    return _problem_at(space, start, start_cost, evaluator, left, fixed, start_residuals)


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
) -> StageResult:
    """Polish ``start`` by trust-region least squares on the same cost (``sse``).

    Parameters
    ----------
    name : str
        Stage name.
    space : Space
        Search coordinates and bounds of the varied parameters.
    start : mapping
        Starting parameter set (the previous stage's answer, varied parameters).
    start_cost : float
        Its cost; the stage's answer is never worse.
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

    Returns
    -------
    StageResult
    """
    limit = method.refine_max_nfev or 30 * (space.dim + 1) * len(evaluator.spec.experiments)
    n0 = evaluator.nfev
    if progress:
        progress("refinement", {"stage": name, "cost": start_cost})
    extra: dict[str, Any] = {
        "method": "scipy.optimize.least_squares(method='trf')",
        "start_cost": float(start_cost),
    }
    problem, s0 = _started(space, start, start_cost, evaluator, limit, fixed, start_residuals,
                           floor, extra)  # fmt: skip
    status, message = _solve(problem, s0, space, limit, extra)
    if status == 0 and problem.spoiled and problem.doubtful(floor):
        status, message = _again_wider(problem, space, limit, extra, message)
    gate = problem.stationarity(floor, method.leveling.tolerance)
    (cost, x), nfev = problem.best, evaluator.nfev - n0
    extra["stationarity"] = gate.to_dict()
    if problem.jacobian is not None and decided_by_trial(extra["stationarity"]):
        # what the refinement in combinations reads: no runs spent again on a Jacobian
        s_lin, _, jac = problem.jacobian
        extra["parallel"] = named_pairs(space, space.to_x(s_lin), jac)
    if status == 0 and not gate.holds:
        status = 1
        message += f"; not shown to be an optimum: {gate.detail}"
    if progress:
        progress("refinement done", {"stage": name, "cost": cost, "nfev": nfev})
    return StageResult(
        name=name,
        kind="refinement",
        x={**(fixed or {}), **x},
        cost=cost,
        nfev=nfev,
        message=message,
        status=status,
        extra=extra,
    )
