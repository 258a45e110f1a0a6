"""How precisely the data determine each parameter: standard errors at the answer.

For outputs with white Gaussian noise of standard deviation ``sigma``, no unbiased
estimator can do better than the covariance ``sigma^2 (J^T J)^-1`` (the Cramer-Rao
bound), where ``J`` holds the sensitivities of the simulated outputs to the parameters.
:func:`standard_errors` computes ``J`` by central differences at the identified
parameters, estimates ``sigma`` of each output from the residuals, and returns the
relative standard error of each parameter and their correlations. A parameter with a
large relative standard error, or one that is almost perfectly correlated with others,
is weakly constrained by the data whatever the search found.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Identifiability", "Sensitivities", "sensitivities", "standard_errors"]

STEP = 1e-2
"""Relative step of the central differences.

Large enough to average over the small discontinuities of models with dry friction
or events (in the SISO example a step of 1e-3 gave F_vm's standard error as 0.027 %
at one point and 0.32 % at another; 1e-2 gave 0.24 % at both), small enough that the
central difference's truncation error, of order ``step**2``, does not matter for a
standard error.
"""


@dataclass
class Identifiability:
    """Standard errors and correlations of the parameters at the answer.

    Attributes
    ----------
    values : dict
        The parameter values analysed.
    std_error : dict
        Standard error of each parameter (Cramer-Rao bound, same unit as the value).
    relative : dict
        Standard error relative to the value, in percent.
    correlation : dict of dict
        Correlation coefficients between the parameters' estimates.
    condition : float
        Condition number of the (whitened) Fisher information ``J^T J``.
    sigma : dict
        Noise standard deviation estimated for each experiment's outputs.
    """

    values: dict[str, float]
    std_error: dict[str, float] = field(default_factory=dict)
    relative: dict[str, float] = field(default_factory=dict)
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    condition: float = float("nan")
    sigma: dict[str, list[float]] = field(default_factory=dict)

    def to_pandas(self):
        """Return value, standard error and relative error per parameter."""
        import pandas as pd

        rows = [
            {
                "parameter": n,
                "value": self.values[n],
                "std error": self.std_error.get(n, float("nan")),
                "std error [%]": self.relative.get(n, float("nan")),
            }
            for n in self.values
        ]
        return pd.DataFrame(rows).set_index("parameter")


@dataclass
class Sensitivities:
    """Output sensitivities at a parameter set, each output scaled by its residual RMS.

    Attributes
    ----------
    names : list of str
        The parameters, in the order of the columns of ``jacobian``.
    residuals : numpy.ndarray
        Scaled residuals ``(simulated - measured) / sigma`` of every experiment and
        output, flattened.
    jacobian : numpy.ndarray
        ``(len(residuals), len(names))``: derivative of the scaled residuals with
        respect to each parameter divided by its ``scale``.
    sigma : dict
        Residual RMS of each output, by experiment name.
    scale : numpy.ndarray
        The scale of each parameter (see :func:`sensitivities`).
    """

    names: list[str]
    residuals: np.ndarray
    jacobian: np.ndarray
    sigma: dict[str, list[float]]
    scale: np.ndarray


def sensitivities(
    evaluator: Any,
    x: Mapping[str, float],
    *,
    step: float = STEP,
    scale: Mapping[str, float] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
) -> Sensitivities | None:
    """Compute the scaled output sensitivities at ``x`` by central differences.

    Parameters
    ----------
    evaluator : Evaluator
        The study's evaluator (its :meth:`simulate_clean` is used: measured inputs, no
        added noise).
    x : mapping of str to float
        Parameter values.
    step : float
        Relative step: each parameter moves by ``+/-step * scale``.
    scale : mapping of str to float, optional
        Differentiate with respect to ``x / scale``; default ``|x|`` (1 where ``x`` is
        0), i.e. relative sensitivities. Give a scale for values at or near zero.
    bounds : mapping of str to (float, float), optional
        A step that would leave these bounds is taken one-sided.

    Returns
    -------
    Sensitivities or None
        None if a simulation failed.
    """
    names = list(x)
    if scale is None:
        scale = {n: abs(x[n]) or 1.0 for n in names}
    sets, halves = [dict(x)], []
    for n in names:
        h = step * scale[n]
        lo, hi = (bounds or {}).get(n, (-np.inf, np.inf))
        up, down = min(x[n] + h, max(hi, x[n])), max(x[n] - h, min(lo, x[n]))
        halves.append((up - down) / 2 / scale[n])  # derivative per unit of x / scale
        sets += [{**x, n: up}, {**x, n: down}]
    # one batch: a parallel evaluator runs the 2 k + 1 simulations side by side
    base, *moved = evaluator.simulate_clean_many(sets)
    if not base or any(y is None for batch in (base, *moved) for _, y, _ in batch):
        return None
    sigma = {}
    rms = []
    parts = []
    for prep, y, _ in base:
        resid = y - np.asarray(prep.measured)
        s = np.sqrt(np.mean(resid**2, axis=0))
        s = np.where(s > 0, s, 1.0)
        sigma[prep.experiment.name] = [float(v) for v in s]
        rms.append(s)
        parts.append((resid / s).ravel())
    columns = []
    for j, half in enumerate(halves):
        plus, minus = moved[2 * j], moved[2 * j + 1]
        col = [
            ((yp - ym) / (2 * half) / s).ravel()
            for (_, yp, _), (_, ym, _), s in zip(plus, minus, rms, strict=True)
        ]
        columns.append(np.concatenate(col))
    return Sensitivities(
        names=names,
        residuals=np.concatenate(parts),
        jacobian=np.column_stack(columns),
        sigma=sigma,
        scale=np.array([scale[n] for n in names], dtype=float),
    )


def standard_errors(evaluator: Any, x: Mapping[str, float]) -> Identifiability | None:
    """Estimate the standard errors of the parameters ``x`` from the study's data.

    Parameters
    ----------
    evaluator : Evaluator
        The study's evaluator (its :meth:`simulate_clean` is used: measured inputs, no
        added noise).
    x : mapping of str to float
        Identified parameter values.

    Returns
    -------
    Identifiability or None
        None if a simulation failed or the outputs do not depend on the parameters.
    """
    names = list(x)
    sens = sensitivities(evaluator, x)
    if sens is None:
        return None
    jac = sens.jacobian / sens.scale  # per unit of each parameter
    fisher = jac.T @ jac
    try:
        cov = np.linalg.inv(fisher)
    except np.linalg.LinAlgError:
        return None
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    if not np.all(np.isfinite(se)):
        return None
    corr = cov / np.outer(se, se)
    out = Identifiability(values={n: float(x[n]) for n in names}, sigma=sens.sigma)
    out.condition = float(np.linalg.cond(fisher))
    for i, n in enumerate(names):
        out.std_error[n] = float(se[i])
        out.relative[n] = float(100 * se[i] / abs(x[n])) if x[n] else float("inf")
        out.correlation[n] = {m: float(corr[i, j]) for j, m in enumerate(names)}
    return out
