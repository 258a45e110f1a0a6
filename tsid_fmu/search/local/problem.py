"""The refinement's least-squares problem in search coordinates, counting simulations.

Residuals and forward-difference Jacobians of the study's cost for SciPy's
:func:`~scipy.optimize.least_squares` (:mod:`tsid_fmu.search.local.refine` runs it), and
the stationarity test at its answer (:mod:`tsid_fmu.search.verdict`).

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

import numpy as np

from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.numerics.fdstep import (
    forward_jacobian,
    known_noise,
    noise_of,
    solver_noise,
    steps_for,
)
from tsid_fmu.numerics.rank import unseen_columns
from tsid_fmu.numerics.tuning import FAILED as _FAILED
from tsid_fmu.numerics.tuning import FD_STEP
from tsid_fmu.numerics.tuning import PROBLEM_FTOL as _FTOL
from tsid_fmu.numerics.tuning import XTOL as _XTOL
from tsid_fmu.search.local.columns import named_pairs
from tsid_fmu.search.outcome import LocalStop
from tsid_fmu.search.space import Space
from tsid_fmu.search.verdict import (
    GATE_RTOL,
    GN_TEST,
    GN_TRIED,
    LOWER_PROBED,
    Stationarity,
    gauss_newton_step,
    gauss_newton_test,
    probe_points,
)

__all__ = ["FD_STEP"]


class _Budget(Exception):
    """The refinement ran out of simulations."""


class _Converged(Exception):
    """An accepted step met SciPy's ``ftol`` or ``xtol`` test (see the module docstring).

    Its arguments: the sentence, and why (:class:`~tsid_fmu.search.outcome.LocalStop`;
    ``FTOL`` where not given).
    """

    @property
    def stop(self) -> LocalStop:
        """Why it stopped."""
        return LocalStop(self.args[1]) if len(self.args) > 1 else LocalStop.FTOL


class _Problem:
    """Residuals and Jacobians of the cost in search coordinates, counting simulations."""

    def __init__(
        self,
        space: Space,
        evaluator: Evaluator,
        limit: int,
        fixed: Mapping[str, float],
        waypoint: bool = False,
    ):
        self.space, self.evaluator, self.limit = space, evaluator, limit
        self.waypoint = waypoint  # a horizon: ends where a step gains < GATE_RTOL of it
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
        self.steps = np.full(space.dim, FD_STEP)  # forward differences' (numerics.fdstep)
        self.spoiled = False  # a column's difference was mostly the FMU's own noise
        self.widen = False  # widen such columns' steps (the second pass of refine_stage)
        self.reuse: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        # columns the outputs do not depend on at the first Jacobian (numerics.rank):
        # held where they are; every Jacobian differences them again, and one seen
        # frees its parameter (``freed``: the least squares restarts with it)
        self.held = np.zeros(space.dim, dtype=bool)
        self.decided = False
        self.freed: list[str] = []
        self.stop = LocalStop.NONE  # why the last least squares stopped (refine._solve)

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
            raise _Converged(f"the last step was shorter than xtol={_XTOL:g}", LocalStop.XTOL)
        if reduction < GATE_RTOL * cost_old and self.waypoint:
            raise _Converged(
                f"the last step lowered the cost by less than {GATE_RTOL:g} of it, "
                "enough for a waypoint",
                LocalStop.WAYPOINT,
            )
        if reduction < GATE_RTOL * cost_old and self._parallel():
            raise _Converged(
                f"the last step lowered the cost by less than {GATE_RTOL:g} of it, along "
                "parallel columns (a valley the trust region crawls)",
                LocalStop.VALLEY,
            )

    def _parallel(self) -> bool:
        """Whether the last Jacobian has parallel columns (:mod:`.columns`).

        There the cost has a narrow valley along the pair's combination, which a trust
        region in the search coordinates crawls: each step along it also moves across it.
        A step that gains less than the stationarity gate (:data:`GATE_RTOL` of the
        cost) there ends the refinement, and the refinement in that combination
        (:mod:`~tsid_fmu.search.local.combined`) follows. Measured on the SISO example
        with the default pipeline: the refinement reached 18639.6 in 67 runs, then spent
        107 more, 7e-5 to 1e-9 of the cost a step, to reach 18621.2 (0.6 % above the
        optimum), which the refinement in ``F_vm + B_s`` then reached in 20.
        """
        if self.jacobian is None:
            return False
        s, _, jac = self.jacobian
        return bool(named_pairs(self.space, self.space.to_x(s), jac))

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
        # a log coordinate on its floor is flat whatever the outputs do: never held
        # (the floor test decides it, in linear coordinates)
        floored = self.space.floored(self.space.to_x(s))
        unseen = unseen_columns(jac) & ~np.isin(self.space.names, floored)
        if not self.decided:
            self.decided = True
            self.held = unseen if not unseen.all() else self.held
        elif np.any(self.held & ~unseen):
            self.freed += [
                n for n, k in zip(self.space.names, self.held & ~unseen, strict=True) if k
            ]
            self.held = self.held & unseen
        try:
            noise = noise_of(self.evaluator, lambda: self._noise(s, r0))
        except _Budget:  # no runs left to measure it: this Jacobian as it is
            noise = 0.0
        wider = steps_for(self.steps, jac, noise)
        # columns the FMU's noise spoils (a held column is zero, not spoiled)
        redo = np.flatnonzero((wider > 1.5 * self.steps) & ~self.held)
        self.spoiled = self.spoiled or bool(redo.size)
        if redo.size and self.widen:
            self.steps[redo] = wider[redo]
            jac[:, redo] = self._columns(s, r0, redo)
        self.jacobian = (s.copy(), r0, jac)
        return jac

    def gate(self, cost: float, floor: float) -> float:
        """Return the decrease of the cost below which nothing is refuted.

        :data:`~tsid_fmu.search.verdict.GATE_RTOL` of the cost (or of the noise floor,
        where larger), or, where the FMU's own solver adds noise of ``sigma`` per sample
        (:mod:`tsid_fmu.numerics.fdstep`), two standard deviations of the cost's change
        that noise makes between two points, ``2 * 2 |r| sigma``: a trial lower by less
        is the noise.
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
        return forward_jacobian(
            lambda pts: self._residuals([self.space.to_x(t) for t in pts]),
            s,
            r0,
            self.steps,
            self.space.s_upper,
            which,
        )

    def _noise(self, s: np.ndarray, r0: np.ndarray) -> float:
        """Return the FMU's noise under parameter changes (ECnoise, numerics.fdstep)."""
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
        gate (:func:`~tsid_fmu.search.verdict.trial_fractions`), even where the
        refinement is out of runs (at most 12 more: "no runs left" would decide nothing;
        on the SISO plant's damping, warm refinements out of runs along ``F_vm + B_s``
        then never reached the refinement in combinations): a lower cost there
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
            # the trial runs even where the refinement is out of runs: "no runs left"
            # decides nothing, and a lower trial sends the search on
            self.limit = max(self.limit, self.evaluator.nfev - self.start + len(points))
            self._residuals([self.space.to_x(self.space.clip(t)) for t in points])
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
            said = detail + "; no runs left for probes"
            return Stationarity(False, test, gap, cost, said, "probe")
        lower = cost - self.best[0]
        if lower > gate:
            detail += f"; {LOWER_PROBED} {lower:.3g} ({probe:g} of a first range)"
            return Stationarity(False, test, gap, cost, detail, "probe", lower)
        detail += f"; no probe {probe:g} of a first range either side is lower"
        return Stationarity(True, test, gap, cost, detail, "probe")


def _problem_at(
    space: Space,
    start: Mapping[str, float],
    start_cost: float,
    evaluator: Evaluator,
    limit: int,
    fixed: Mapping[str, float] | None,
    start_residuals: np.ndarray | None,
    waypoint: bool = False,
) -> tuple[_Problem, np.ndarray]:
    """Return the least-squares problem at ``start`` and its start point, just inside bounds.

    The start's residuals, where the caller has them, are kept, so that it is not
    simulated again. ``waypoint``: see :attr:`~tsid_fmu.search.outcome.LocalStop.WAYPOINT`.
    """
    problem = _Problem(space, evaluator, limit, fixed or {}, waypoint)
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
