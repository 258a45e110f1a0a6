"""A refinement in the combinations the data fix: parameters whose effects are parallel.

Where two parameters act on the outputs only through a combination (a viscous friction
coefficient and a spring's damping, on a motion that depends on their sum), their
Jacobian columns are parallel, and the cost has a straight, narrow valley along which
that combination stays fixed. A trust region in the search coordinates does not follow
it: logarithmic coordinates bend it, and even in linear ones it is diagonal, so each
step that moves along it moves across it too. Measured on the SISO friction laws (law-3
data, dev seed 101): the answer of law 3's study stopped at 1.0170 x the least-squares
cost from the truth, with the cost falling all the way along the line to it; the
forward-difference columns of ``F_vm`` and ``B_s`` had a cosine of 0.99999999 (steps
matched to their sum; 1 - 1.7e-4 with relative steps, whose events differ); least
squares with their sum as one coordinate ended at 0.99908 x in 93 runs, while refinements
with forward-difference steps from 1e-8 to 1e-2 and in the Jacobian's eigen-coordinates
all stopped at 1.0078 to 1.017 x.

:func:`~tsid_fmu.search.local.columns.parallel_pairs` finds such pairs in a Jacobian (the
refinement's last one, kept in its stage: :mod:`~tsid_fmu.search.local.columns`);
:func:`matched_ratio` measures each pair's ratio again; :func:`combined_refinement` refines
with each pair ``(i, j)`` re-parametrised as ``c = p_i + a p_j`` (``a`` from
the columns) and ``p_j``, the valley then along an axis. Bounds of ``p_i`` become a
constraint: a set outside them scores as a failed simulation.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from tsid_fmu.numerics.fdstep import forward_jacobian, relative_steps
from tsid_fmu.numerics.lsq import trust_region
from tsid_fmu.numerics.tuning import COMBINED_FTOL as _FTOL
from tsid_fmu.numerics.tuning import COMBINED_STEP as _STEP
from tsid_fmu.numerics.tuning import FAILED as _FAILED
from tsid_fmu.numerics.tuning import MATCHED as _MATCHED
from tsid_fmu.search.local.adaptive import answer_stage
from tsid_fmu.search.local.columns import PARALLEL, parallel_pairs
from tsid_fmu.search.space import Space
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.search.structure.optima import settle, short
from tsid_fmu.search.verdict import (
    GATE_RTOL,
    Stationarity,
    gauss_newton_test,
)
from tsid_fmu.study.definition import Study

__all__ = [
    "PARALLEL",
    "combined_refinement",
    "matched_ratio",
    "parallel_pairs",
    "physical_jacobian",
    "refine_in_combinations",
]


def _scored(ev: Any, sets: list[dict[str, float]], size: int) -> list[tuple[np.ndarray, float]]:
    """Residuals and cost of each set, one batch; a failed run's residuals are ``_FAILED``."""
    out = ev.evaluate(sets) if sets else None
    if out is None:
        return []
    res = out.residuals or [None] * len(sets)
    scored = []
    for r, c in zip(res, out.costs[:, 0], strict=True):
        if r is not None and math.isfinite(c) and np.isfinite(r).all():
            scored.append((np.asarray(r, float), float(c)))
        else:
            scored.append((np.full(size, _FAILED), math.inf))
    return scored


def _residuals(ev: Any, sets: list[dict[str, float]], size: int) -> list[np.ndarray]:
    return [r for r, _ in _scored(ev, sets, size)]


def named_residuals(
    ev: Any, x: Mapping[str, float], names: list[str], size: int
) -> Callable[[list[np.ndarray]], list[np.ndarray]]:
    """Return the residuals of points in ``names``' own units, the rest of ``x`` held.

    What :func:`~tsid_fmu.numerics.fdstep.forward_jacobian` runs here and at a nesting
    point (:mod:`~tsid_fmu.search.structure.boundary`): one batch of simulations, a
    failed run as residuals of ``1e10`` of length ``size``.
    """

    def run(points: list[np.ndarray]) -> list[np.ndarray]:
        sets = [{**x, **dict(zip(names, map(float, p), strict=True))} for p in points]
        return _residuals(ev, sets, size)

    return run


def physical_jacobian(
    ev: Any, x: Mapping[str, float], names: list[str], r0: np.ndarray
) -> np.ndarray:
    """Return forward-difference columns per unit of each parameter (one batch of runs)."""
    z = np.array([float(x[n]) for n in names])
    steps = _STEP * np.maximum(np.abs(z), 1e-12)
    return forward_jacobian(named_residuals(ev, x, names, r0.size), z, r0, steps)


def matched_ratio(
    ev: Any, x: Mapping[str, float], names: list[str], r0: np.ndarray, pair: tuple
) -> tuple[int, int, float]:
    """Return ``pair`` with its ratio ``a`` measured again by steps matched to it (2 runs each).

    ``p_j`` moved by ``h`` and ``p_i`` by ``a h`` move ``p_i + a p_j`` by about the same
    amount, so on a model with events both shift the same events, and the ratio of the
    two output changes is free of the event noise that steps of different sizes carry.
    Measured on the SISO pair at law 3's answer (dev seed 103): ``a`` = 1.0234 from
    relative steps, against 1.0000 for the sum; refined in that wrong combination, the
    answer stayed at 1.0123 x the reference, in the right one it fell to 0.9996 x.
    Two rounds, the second only where the first moved ``a`` by more than ``_MATCHED``
    of itself (its steps would otherwise be the first round's, to that fraction).
    """
    i, j, a = pair
    for _ in range(2):
        pi, pj = float(x[names[i]]), float(x[names[j]])
        h = _STEP * max(abs(pj), abs(pi / a) if a else 0.0, 1e-12)
        moved = _residuals(ev, [{**x, names[j]: pj + h}, {**x, names[i]: pi + a * h}], r0.size)
        dj, di = moved[0] - r0, moved[1] - r0
        if not float(di @ di) > 0:
            break
        factor = float(di @ dj) / float(di @ di)
        a *= factor
        if abs(factor - 1.0) < _MATCHED:
            break
    return i, j, a


def combined_refinement(
    ev: Any,
    space: Space,
    x: Mapping[str, float],
    pairs: list[tuple[int, int, float]],
    limit: int,
    start: tuple[np.ndarray, float] | None = None,
) -> tuple[dict[str, float], float, int, Stationarity | None]:
    """Least squares from ``x`` with each pair ``(i, j, a)`` as ``p_i + a p_j`` and ``p_j``.

    The other parameters stay in the search coordinates of ``space``; a pair's two
    coordinates are its values scaled by their magnitudes at ``x`` (at least their
    lowest first levels: see the comment at ``scale``). ``start``, the residuals and cost
    at ``x`` where the caller has them, saves their run. Jacobians are SciPy's
    ``"2-point"`` differences, each one batch of runs (so they run in parallel), the
    last at SciPy's answer for the stationarity test there. Returns the best set
    evaluated (``x`` if none is lower), its cost, the simulations spent (at most
    ``limit``, and two for the test), and the stationarity test at the end (None where
    the limit stopped it, or SciPy could not go on).
    """
    names = list(space.names)
    bounds = space.bounds
    paired = {k for i, j, _ in pairs for k in (i, j)}
    rest = [k for k in range(len(names)) if k not in paired]
    x0 = {n: float(x[n]) for n in names}
    # not below the lowest first level: B_s at 0.0007 made the valley 1e4 units long
    scale = {k: max(abs(x0[names[k]]), abs(space.value(k, -0.5)), 1e-12) for k in paired}
    n0 = ev.nfev

    def to_x(z: np.ndarray) -> dict[str, float] | None:
        out = dict(x0)
        for m, k in enumerate(rest):
            out[names[k]] = space.value(k, float(z[m]))
        at = len(rest)
        for i, j, a in pairs:
            pj = float(z[at + 1]) * scale[j]
            pi = float(z[at]) * scale[i] - a * pj
            at += 2
            for k, v in ((i, pi), (j, pj)):
                lo, hi = bounds[names[k]]
                if not lo <= v <= hi:
                    return None
                out[names[k]] = v
        return out

    z0 = [space.coordinate(k, x0[names[k]]) for k in rest]
    for i, j, a in pairs:
        z0 += [(x0[names[i]] + a * x0[names[j]]) / scale[i], x0[names[j]] / scale[j]]
    runs = _Runs(ev, to_x, limit, np.array(z0, float), x0, start)
    solved = trust_region(
        runs.fun, runs.z0, runs.jac, stops=(StopIteration,), x_scale="jac", ftol=_FTOL,
        max_nfev=limit,
    )  # fmt: skip
    if solved.x is None or solved.fun is None or solved.jac is None:
        # out of runs (StopIteration), or SciPy's trust-region step failed (a Jacobian
        # it cannot factor: failed runs beside finite ones): the best set so far is the
        # answer, with no test
        return runs.best[1], float(runs.best[0]), ev.nfev - n0, None
    z, r, jac = solved.x, solved.fun, solved.jac
    inf = [math.inf] * (2 * len(pairs))
    lower = np.array([space.s_lower[k] for k in rest] + [-v for v in inf])
    upper = np.array([space.s_upper[k] for k in rest] + inf)
    gate = _gate(runs.fun, z, r, jac, (lower, upper), runs.best)
    return runs.best[1], float(runs.best[0]), ev.nfev - n0, gate


class _Runs:
    """Residuals and Jacobians in the combined coordinates, keeping the best set scored.

    ``best`` is ``[cost, set]``. A set outside the bounds scores as a failed run.
    """

    def __init__(
        self,
        ev: Any,
        to_x: Any,
        limit: int,
        z0: np.ndarray,
        x0: dict[str, float],
        start: tuple[np.ndarray, float] | None,
    ) -> None:
        self.ev, self.to_x, self.limit, self.z0, self.n0 = ev, to_x, limit, z0, ev.nfev
        self.known = np.asarray(start[0], float) if start is not None else None
        self.size = self.known.size if self.known is not None else 0
        self.best: list[Any] = [float(start[1]) if start is not None else math.inf, dict(x0)]
        self.last: tuple[np.ndarray, np.ndarray] | None = None

    def _failed(self) -> np.ndarray:
        return np.full(self.size or 1, _FAILED)

    def run(self, zs: list[np.ndarray]) -> list[np.ndarray]:
        """Return the residuals at ``zs``, scored in one batch."""
        if self.ev.nfev - self.n0 + len(zs) > self.limit:
            raise StopIteration  # a batch that would pass the limit is not started
        sets = [self.to_x(z) for z in zs]
        scored = iter(_scored(self.ev, [p for p in sets if p is not None], self.size or 1))
        out = []
        for p in sets:
            r, cost = next(scored) if p is not None else (self._failed(), math.inf)
            if cost < self.best[0]:
                self.best[:] = [cost, p]  # in place: _gate holds this list
            self.size = self.size or (r.size if math.isfinite(cost) else 0)
            out.append(r)
        return out

    def fun(self, z: np.ndarray) -> np.ndarray:
        if self.known is not None and np.array_equal(z, self.z0):
            r = self.known
        else:
            r = self.run([z])[0]
        self.last = (np.array(z, float), r)
        return r

    def jac(self, z: np.ndarray) -> np.ndarray:
        """SciPy's ``"2-point"`` Jacobian at ``z`` (its steps), as one batch of runs."""
        if self.last is None or not np.array_equal(self.last[0], z):
            self.fun(z)
        assert self.last is not None
        r = self.last[1]
        return forward_jacobian(self.run, z, r, relative_steps(z))


def _gate(
    fun: Any, z: np.ndarray, r: np.ndarray, jac: np.ndarray, bounds: tuple, best: list
) -> Stationarity:
    """Run the refinement's stationarity test (:mod:`~tsid_fmu.search.verdict`) at SciPy's end.

    From SciPy's last Jacobian, in the combined coordinates; where it predicts too large
    a decrease, the step and its half are tried (two runs, through ``fun``, which keeps
    the ``best`` set).
    """
    cost = float(r @ r)

    def say(gap: float) -> str:
        return (
            f"the projected Gauss-Newton step in the combinations predicts a decrease of "
            f"{gap:.3g} ({gap / cost if cost > 0 else 0.0:.2g} of the cost)"
        )

    def simulate(points: list[np.ndarray]) -> bool:
        try:
            for point in points:
                fun(point)
        except StopIteration:
            return False
        return True

    gate = GATE_RTOL * cost
    return gauss_newton_test(jac, r, z, bounds, cost, gate, say, simulate, lambda: best[0])


def refine_in_combinations(
    study: Study, evs: Any, stages: list[StageResult], progress: Any = None
) -> tuple[StageResult | None, int]:
    """Refine a structure's answer in the combinations the data fix, where that lowers it.

    Only where the refinement did not end by its own tests
    (:attr:`~tsid_fmu.search.outcome.LocalStop.unfinished`: it crawled along the valley,
    or ran out of runs), or where the answer's stationarity test held by a trial alone
    ("step tried": the first-order model does not hold this close to the answer, as on
    a cost made rough by events), or failed with its step, simulated, lower (a
    refinement that stopped at its tolerances in a valley: law-3 dev seed 116, ``B_s``
    at 0.82 of 2.5, 1.009 x the least-squares cost), and its Jacobian has parallel
    columns (:func:`parallel_pairs`,
    each pair's ratio measured again, :func:`matched_ratio`): then
    :func:`combined_refinement` (at most 5 runs per parameter + 1). A lower end whose
    stationarity test holds there is the answer; otherwise a refinement in the usual
    coordinates from it gives the verdict (:func:`~tsid_fmu.search.structure.optima.settle`).
    The Jacobian is the refinement's last (its ``parallel``, no run), or ``p``
    runs at the answer where a stage has none (one read back from an older trail).
    Returns that stage, or None, and the simulations spent here (the stage's ``nfev``
    counts them all).
    """
    answer = answer_stage(stages)
    if answer.pairs is not None:
        return None, 0  # refined in its combinations already (a study of its own)
    test = answer.stationarity  # not ended by its own tests, or decided by a trial
    if not answer.stop.unfinished and not (test is not None and test.by_trial):
        return None, 0
    names = list(study.parameter_names)
    found = answer.parallel  # from the refinement's last Jacobian
    if found is not None:
        found = [(names.index(a), names.index(b), r) for a, b, r in found if {a, b} <= {*names}]
        if not found:
            return None, 0
    ev = evs.get(names, study.identify_names(), {})
    n0 = ev.nfev
    x = {n: float(answer.x[n]) for n in names}
    scored = ev.evaluate([x])
    r0 = scored.residuals[0] if scored.residuals else None
    if r0 is None or not math.isfinite(float(scored.costs[0, 0])):
        return None, ev.nfev - n0
    r0 = np.asarray(r0, float)
    pairs = found if found is not None else parallel_pairs(physical_jacobian(ev, x, names, r0))
    pairs = [matched_ratio(ev, x, names, r0, p) for p in pairs]
    if not pairs:
        return None, ev.nfev - n0
    space = Space(study.first_levels(), study.bounds(), study.method.leveling)
    what = ", ".join(f"{names[i]} + {a:.4g} {names[j]}" for i, j, a in pairs)
    if progress:
        message = f"refining in the combinations the data fix: {what} ..."
        progress("rerun", {"message": message})
    limit = 5 * (len(names) + 1)
    start = (r0, float(scored.costs[0, 0]))
    xb, cost, _, gate = combined_refinement(ev, space, x, pairs, limit, start)
    if not cost < answer.cost:
        return None, ev.nfev - n0
    name = f"refinement in the combinations the data fix: {what}"
    if gate is not None and gate.holds:
        message = f"least squares in the combinations; stationary: {gate.detail}"
        lower = StageResult(name, StageKind.REFINEMENT, xb, cost, 0, message, 0, stationarity=gate)
        lower.start_cost = float(answer.cost)
    else:  # the test in the usual coordinates decides
        lower = settle(name, short(study), xb, ev, progress)
    lower.nfev = ev.nfev - n0
    lower.pairs = [[names[i], names[j], a] for i, j, a in pairs]
    return lower, lower.nfev
