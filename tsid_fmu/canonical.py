"""Taguchi iterations on canonical factors: the end stage for coupled parameters.

Main effects assume that each parameter acts on its own. Physical parameters rarely do:
in the SISO example the load-cell force depends on ``F_vm + B_s`` and on
``sqrt(K_s / M_m)`` far more than on each alone, so near the optimum the cost is a long
narrow valley at an angle to every parameter axis. An orthogonal array over the
parameters then sees each factor's effect averaged over the others, the re-leveling
narrows every range around values that only compensate for each other, and the study
stalls short of the minimum (the example stopped at a cost 10 % above that of the
true parameters).

Response-surface practice answers this with *canonical analysis*: rotate to the
principal axes of the local surface, where the factors act independently. Here the axes
come from the output sensitivities ``J`` (central differences of the simulated outputs,
each output scaled by its residual RMS: :func:`tsid_fmu.identifiability.sensitivities`).
In the log-parameters ``z`` the canonical factors are ``w = sqrt(L) V^T z`` with ``J^T J
= V L V^T``: one unit of any ``w`` changes the weighted squared error by the same
amount, and the factors do not interact to first order. Each iteration is an ordinary
Taguchi iteration over the ``w``: a 5-level array spanning twice the Gauss-Newton step
of each factor (at least one standard error), S/N ratios over the noise replicates, main
effects, a confirmation run at the main-effects optimum and one at the Gauss-Newton
point; the best set seen is kept, so the stage never makes the result worse. It stops
when every canonical S/N is flat and every step is within its standard error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.analysis import response_table
from tsid_fmu.analysis import sn_smaller_the_better as sn_stb
from tsid_fmu.arrays import select_array
from tsid_fmu.errors import StudyError
from tsid_fmu.identifiability import sensitivities

__all__ = ["CanonicalRecord", "canonical_iteration"]

#: relative step of the central differences (in the log of each parameter)
STEP = 1e-4
#: levels per canonical factor
LEVELS = 5


@dataclass
class CanonicalRecord:
    """One iteration on canonical factors.

    Attributes
    ----------
    index : int
        1-based number within the canonical stage.
    array : str
        Orthogonal array used.
    names : list of str
        Parameter names.
    directions : numpy.ndarray
        ``(k, k)``: column ``j`` is the change of ``log(parameters)`` per unit of
        canonical factor ``j``.
    levels : numpy.ndarray
        ``(k, 5)``: the levels of each canonical factor.
    values : numpy.ndarray
        ``(runs, k)``: parameter values of each run.
    costs : numpy.ndarray
        ``(runs, replicates)``: cost of each run and replicate.
    sn_means : numpy.ndarray
        ``(k, 5)``: mean S/N at each level of each canonical factor.
    best_x : dict
        Best parameter set seen up to and including this iteration.
    best_cost : float
        Its cost.
    best_source : str
        Where it came from.
    converged : bool
        Every canonical S/N flat and every step within a standard error.
    nfev : int
        Simulations of this iteration.
    """

    index: int
    array: str
    names: list[str]
    directions: np.ndarray
    levels: np.ndarray
    values: np.ndarray
    costs: np.ndarray
    sn_means: np.ndarray
    best_x: dict[str, float]
    best_cost: float
    best_source: str
    converged: bool
    nfev: int
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable summary."""
        return {
            "index": self.index,
            "array": self.array,
            "names": self.names,
            "directions": self.directions.tolist(),
            "levels": self.levels.tolist(),
            "sn_means": self.sn_means.tolist(),
            "best_x": self.best_x,
            "best_cost": self.best_cost,
            "best_source": self.best_source,
            "converged": self.converged,
            "nfev": self.nfev,
            **self.extra,
        }

    def runs_frame(self) -> Any:
        """Return the runs (parameter values, costs) as a DataFrame."""
        import pandas as pd

        frame = pd.DataFrame(self.values, columns=self.names)
        frame.index = pd.RangeIndex(1, len(frame) + 1, name="run")
        for r in range(self.costs.shape[1]):
            frame[f"cost {r + 1}"] = self.costs[:, r]
        frame["S/N"] = sn_stb(self.costs)
        return frame


def canonical_iteration(
    index: int,
    evaluator: Any,
    names: list[str],
    best: tuple[dict[str, float], float, str],
    bounds: Mapping[str, tuple[float, float]],
    significance_db: float,
    radius: float = math.inf,
) -> CanonicalRecord:
    """Run one Taguchi iteration on the canonical factors about ``best``.

    Parameters
    ----------
    index : int
        1-based number within the canonical stage.
    evaluator : Evaluator or ParallelEvaluator
        Scores parameter sets (``evaluate``) and simulates the measured inputs
        (``simulate_clean``).
    names : list of str
        Parameters to identify; all must be positive (the factors act on logarithms).
    best : tuple
        ``(x, cost, source)``: the best set so far, the centre of this iteration.
    bounds : mapping
        Physical bounds ``(min, max)`` of each parameter; runs are clipped into them.
    significance_db : float
        S/N spread below which a canonical factor is flat (as in re-leveling).
    radius : float
        Largest half-range of a factor, in standard errors (a trust region: the stage
        quarters it after an iteration that found nothing better, doubles it after
        one that did; the record's ``extra["radius"]`` is the value for the next).

    Returns
    -------
    CanonicalRecord
        The iteration, with the best set seen.

    Raises
    ------
    StudyError
        A parameter is not positive, or the simulations at the centre failed.
    """
    x0, c0, src0 = dict(best[0]), float(best[1]), best[2]
    bad = [n for n in names if not x0[n] > 0]
    if bad:
        raise StudyError(
            f"canonical iterations need positive parameters; {', '.join(bad)} "
            f"{'is' if len(bad) == 1 else 'are'} not"
        )
    k = len(names)
    nfev0 = evaluator.nfev
    sens = sensitivities(evaluator, x0, log=True, step=STEP)
    if sens is None:
        raise StudyError("canonical iterations: a simulation at or near the best set failed")
    jac = sens.jacobian[:, [sens.names.index(n) for n in names]]
    r0 = sens.residuals
    logx = np.log(np.array([x0[n] for n in names]))
    lam, vec = np.linalg.eigh(jac.T @ jac)
    lam = np.maximum(lam, max(float(lam.max()), 1e-300) * 1e-12)
    directions = vec / np.sqrt(lam)  # dz = directions @ w
    step = -(vec.T @ (jac.T @ r0)) / np.sqrt(lam)  # Gauss-Newton step in w
    # one unit of w is one standard error (residuals scaled to unit RMS)
    step = np.clip(step, -radius, radius)
    half = np.minimum(np.maximum(2.0 * np.abs(step), 1.0), max(radius, 1e-6))
    levels = np.linspace(-1.0, 1.0, LEVELS)[None, :] * half[:, None]
    array, cols = select_array([LEVELS] * k)
    level_index = np.asarray(array.table[:, cols], dtype=int)

    def to_x(w: np.ndarray) -> dict[str, float]:
        z = logx + directions @ w
        out = {}
        for n, v in zip(names, np.exp(z), strict=True):
            lo, hi = bounds.get(n, (-math.inf, math.inf))
            out[n] = float(min(max(v, lo), hi))
        return out

    runs = [to_x(levels[np.arange(k), level_index[i]]) for i in range(array.n_runs)]
    ev = evaluator.evaluate(runs)
    sn = sn_stb(ev.costs)
    factors = [f"w{j + 1}" for j in range(k)]
    rt = response_table(level_index, sn, factors, n_levels=[LEVELS] * k)
    sn_means = np.array([rt.means[f] for f in factors], dtype=float)
    best_level = np.argmax(np.where(np.isfinite(sn_means), sn_means, -np.inf), axis=1)
    w_main = levels[np.arange(k), best_level]
    trials = [to_x(w_main), to_x(step)]
    conf = evaluator.evaluate(trials)
    candidates = [(x0, c0, src0)]
    means = ev.mean_costs
    i_best = int(np.argmin(means))
    candidates.append((runs[i_best], float(means[i_best]), f"canonical {index}, run {i_best + 1}"))
    for label, x, c in zip(
        ("main-effects optimum", "Gauss-Newton point"), trials, conf.mean_costs, strict=True
    ):
        candidates.append((x, float(c), f"canonical {index}, {label}"))
    best_x, best_cost, best_source = min(candidates, key=lambda c: c[1])
    widest = float(half.max())
    next_radius = 2.0 * widest if best_cost < c0 else 0.25 * widest
    spread = np.nanmax(sn_means, axis=1) - np.nanmin(sn_means, axis=1)
    converged = bool(
        (np.all(spread < significance_db) and np.all(np.abs(step) <= 1.0))
        or (best_cost >= c0 and widest <= 1e-3)
    )
    return CanonicalRecord(
        index=index,
        array=array.name,
        names=list(names),
        directions=directions,
        levels=levels,
        values=np.array([[r[n] for n in names] for r in runs]),
        costs=ev.costs,
        sn_means=sn_means,
        best_x=dict(best_x),
        best_cost=float(best_cost),
        best_source=best_source,
        converged=converged,
        nfev=evaluator.nfev - nfev0,
        extra={
            "gauss_newton_step": step.tolist(),
            "sn_spread_db": spread.tolist(),
            "radius": next_radius,
        },
    )
