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
come from the output sensitivities ``J`` (central differences of the simulated outputs
with respect to the relative changes ``z = dx / s``, ``s = max(|x|, scale)``, each
output scaled by its residual RMS: :func:`tsid_fmu.identifiability.sensitivities`). The
canonical factors are ``w = sqrt(L) V^T z`` with ``J^T J = V L V^T``: one unit of any
``w`` changes the weighted squared error by the same amount (one standard error), and
the factors do not interact to first order. Each iteration is an ordinary Taguchi
iteration over the ``w``: a 5-level array spanning twice the Gauss-Newton step of each
factor (at least one standard error), S/N ratios over the noise replicates, main
effects, then confirmation runs at the best runs, the main-effects optimum and along
the Gauss-Newton step (half, whole, double).

The confirmation runs are compared by their cost on the *measured* inputs, not by the
replicates' mean: along a weakly determined valley a few replicates' input noise changes
the cost more than the valley does, and choosing by it let the answer drift with the
replicate seed. So after this stage the study's cost is the cost on the measured inputs.
The best set seen is kept, so the stage never makes the result worse. It stops when
every canonical S/N is flat and every Gauss-Newton step is within its standard error.
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


def _json_safe(value: Any) -> Any:
    """Replace non-finite floats (nested in lists) by None: strict JSON for other tools."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, list):
        return [_json_safe(v) for v in value]
    return value


def _from_json(value: Any) -> Any:
    """Undo :func:`_json_safe` in lists of numbers (None back to NaN)."""
    if isinstance(value, list) and all(v is None or isinstance(v, int | float) for v in value):
        return [math.nan if v is None else v for v in value]
    return math.inf if value is None else value


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
        Its cost on the measured inputs (no added noise).
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
            "values": self.values.tolist(),
            "costs": [
                [c if math.isfinite(c) else None for c in row] for row in self.costs.tolist()
            ],
            "sn_means": [
                [v if math.isfinite(v) else None for v in row] for row in self.sn_means.tolist()
            ],
            "best_x": self.best_x,
            "best_cost": self.best_cost,
            "best_source": self.best_source,
            "converged": self.converged,
            "nfev": self.nfev,
            **{k: _json_safe(v) for k, v in self.extra.items()},
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> CanonicalRecord:
        """Rebuild a record from :meth:`to_dict` (a resumed study's ``record.json``)."""
        known = {"index", "array", "names", "directions", "levels", "values", "costs"}
        known |= {"sn_means", "best_x", "best_cost", "best_source", "converged", "nfev"}
        costs = [[math.inf if c is None else c for c in row] for row in data["costs"]]
        return cls(
            index=int(data["index"]),
            array=str(data["array"]),
            names=list(data["names"]),
            directions=np.array(data["directions"], dtype=float),
            levels=np.array(data["levels"], dtype=float),
            values=np.array(data["values"], dtype=float),
            costs=np.array(costs, dtype=float),
            sn_means=np.array(
                [[math.nan if v is None else v for v in row] for row in data["sn_means"]],
                dtype=float,
            ),
            best_x={k: float(v) for k, v in data["best_x"].items()},
            best_cost=float(data["best_cost"]),
            best_source=str(data["best_source"]),
            converged=bool(data["converged"]),
            nfev=int(data["nfev"]),
            extra={k: _from_json(v) for k, v in data.items() if k not in known},
        )

    def runs_frame(self) -> Any:
        """Return the runs (parameter values, costs, S/N) as a DataFrame."""
        import pandas as pd

        data: dict[str, Any] = {"iteration": self.index, "run": np.arange(1, len(self.values) + 1)}
        for j, n in enumerate(self.names):
            data[n] = self.values[:, j]
        for r in range(self.costs.shape[1]):
            data[f"cost r{r + 1}"] = self.costs[:, r]
        data["mean cost"] = self.costs.mean(axis=1)
        data["S/N [dB]"] = sn_stb(self.costs)
        return pd.DataFrame(data)


def canonical_iteration(
    index: int,
    evaluator: Any,
    names: list[str],
    best: tuple[dict[str, float], float, str],
    bounds: Mapping[str, tuple[float, float]],
    significance_db: float,
    radius: float = math.inf,
    progress: Any = None,
    scales: Mapping[str, float] | None = None,
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
        Parameters to identify.
    best : tuple
        ``(x, cost, source)``: the best set so far, the centre of this iteration, with
        its cost on the measured inputs (``evaluator.evaluate([x], clean=True)``).
    bounds : mapping
        Physical bounds ``(min, max)`` of each parameter; runs are clipped into them.
    significance_db : float
        S/N spread below which a canonical factor is flat (as in re-leveling).
    radius : float
        Largest half-range of a factor, in standard errors (a trust region: the stage
        quarters it after an iteration that found nothing better, doubles it after
        one that did; the record's ``extra["radius"]`` is the value for the next).
    progress : callable, optional
        Called as ``progress(done, total)`` as the array's runs finish.
    scales : mapping of str to float, optional
        Smallest scale of each parameter: changes are relative to ``max(|x|, scale)``,
        so a parameter at or near zero (a damping on its bound) can still move.

    Returns
    -------
    CanonicalRecord
        The iteration, with the best set seen.

    Raises
    ------
    StudyError
        A parameter is zero and has no scale, or the simulations at the centre failed.
    """
    x0, c0, src0 = dict(best[0]), float(best[1]), best[2]
    size = {n: max(abs(x0[n]), (scales or {}).get(n, 0.0)) for n in names}
    bad = [n for n in names if not size[n] > 0]
    if bad:
        raise StudyError(
            f"canonical iterations: {', '.join(bad)} {'is' if len(bad) == 1 else 'are'} 0 "
            "and no scale was given to step from"
        )
    k = len(names)
    nfev0 = evaluator.nfev
    sens = sensitivities(evaluator, x0, step=STEP, scale=size, bounds=bounds)
    if sens is None:
        raise StudyError("canonical iterations: a simulation at or near the best set failed")
    jac = sens.jacobian[:, [sens.names.index(n) for n in names]]
    r0 = sens.residuals
    x_ref = np.array([x0[n] for n in names])
    s_ref = np.array([size[n] for n in names])
    lam, vec = np.linalg.eigh(jac.T @ jac)
    # directions the data do not see at all are not varied (their factor stays at 0)
    seen = lam > max(float(lam.max()), 1e-300) * 1e-10
    lam = np.where(seen, lam, 1.0)
    directions = vec / np.sqrt(lam)  # dz = directions @ w
    step = np.where(seen, -(vec.T @ (jac.T @ r0)) / np.sqrt(lam), 0.0)  # Gauss-Newton step in w
    # one unit of w is one standard error (residuals scaled to unit RMS)
    step = np.clip(step, -radius, radius)
    half = np.where(seen, np.minimum(np.maximum(2.0 * np.abs(step), 1.0), max(radius, 1e-6)), 0.0)
    levels = np.linspace(-1.0, 1.0, LEVELS)[None, :] * half[:, None]
    array, cols = select_array([LEVELS] * k)
    level_index = np.asarray(array.table[:, cols], dtype=int)

    def to_x(w: np.ndarray) -> dict[str, float]:
        out = {}
        for n, v in zip(names, x_ref + s_ref * (directions @ w), strict=True):
            lo, hi = bounds.get(n, (-math.inf, math.inf))
            out[n] = float(min(max(v, lo), hi))
        return out

    runs = [to_x(levels[np.arange(k), level_index[i]]) for i in range(array.n_runs)]
    ev = evaluator.evaluate(runs, progress=progress)
    sn = sn_stb(ev.costs)
    factors = [f"w{j + 1}" for j in range(k)]
    rt = response_table(level_index, sn, factors, n_levels=[LEVELS] * k)
    sn_means = np.array([rt.means[f] for f in factors], dtype=float)
    best_level = np.argmax(np.where(np.isfinite(sn_means), sn_means, -np.inf), axis=1)
    w_main = levels[np.arange(k), best_level]
    # The candidates are compared by their cost on the measured inputs: the S/N ratios
    # need the noise replicates, but a few replicates' noise shifts the cost by more than
    # a weakly determined valley changes it, and choosing by it lets the answer drift
    # along the valley (in the SISO example B_s wandered by +26 % to +290 % with the seed).
    i_best = int(np.argmin(ev.mean_costs))
    i_sn = int(np.argmax(np.where(np.isfinite(sn), sn, -np.inf)))
    trials = {
        f"run {i_best + 1}": runs[i_best],
        f"run {i_sn + 1}": runs[i_sn],
        "main-effects optimum": to_x(w_main),
        "Gauss-Newton point": to_x(step),
        "half Gauss-Newton step": to_x(0.5 * step),
        # far from the optimum the linearisation tends to under-shoot along a valley
        "double Gauss-Newton step": to_x(2.0 * step),
    }
    conf = evaluator.evaluate(list(trials.values()), clean=True)
    candidates = [(x0, c0, src0)]
    for (label, x), c in zip(trials.items(), conf.mean_costs, strict=True):
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
