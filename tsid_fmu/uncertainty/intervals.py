"""Confidence intervals of the identified parameters, and what the data determine.

From the sensitivities at the answer (:mod:`tsid_fmu.uncertainty.sensitivity`), each
output is whitened by its noise, estimated from its own residuals (the residual RMS at
the answer), and the Fisher information ``F = J^T J`` of the search coordinates gives the
covariance ``F^-1`` (Cramer-Rao). The 95 % interval of each parameter is the value of
its coordinate +/- 1.96 standard errors, mapped back to parameter units (asymmetric for
parameters searched in log10). The eigenvectors of ``F`` name the combinations of
parameters the data determine well (large eigenvalues) and those they do not; a
parameter dominated by an undetermined combination gets an interval with an open end
(``None``) rather than a small, false one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.sensitivity import Sensitivities

__all__ = ["Z95", "Uncertainty", "uncertainty"]

Z95 = 1.959963984540054
"""Two-sided 95 % quantile of the standard normal distribution."""

UNDETERMINED = 0.5
"""A combination whose standard error exceeds this many search units (half of a first
range) is *not determined* by the data."""


@dataclass
class Uncertainty:
    """Standard errors, intervals and determined combinations at the answer.

    Attributes
    ----------
    values : dict
        The parameter values analysed.
    std_error : dict
        Standard error of each parameter's search coordinate, in parameter units near
        the value (``value * ln 10 * se`` for log parameters).
    relative : dict
        Standard error relative to the value, in percent.
    intervals : dict
        95 % interval ``[low, high]`` per parameter; ``None`` for an end the data do not
        determine.
    correlation : dict of dict
        Correlation coefficients of the estimates.
    combinations : list of dict
        Eigen-combinations of the Fisher matrix, best determined first: ``{"terms":
        {parameter: weight}, "std_error": se in search units, "determined": bool}``.
    condition : float
        Condition number of the Fisher matrix.
    noise : dict
        Noise standard deviation used for each experiment's outputs (residual RMS).
    method : str
        How the intervals were computed.
    """

    values: dict[str, float]
    std_error: dict[str, float] = field(default_factory=dict)
    relative: dict[str, float] = field(default_factory=dict)
    intervals: dict[str, list[float | None]] = field(default_factory=dict)
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    combinations: list[dict[str, Any]] = field(default_factory=list)
    condition: float = float("nan")
    noise: dict[str, list[float]] = field(default_factory=dict)
    method: str = "Cramer-Rao bound, noise from the residuals"

    @property
    def sigma(self) -> dict[str, list[float]]:
        """The noise used per experiment and output (the same as :attr:`noise`)."""
        return self.noise

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy (non-finite numbers as ``None``)."""

        def clean(v: Any) -> Any:
            if isinstance(v, float):
                return v if math.isfinite(v) else None
            if isinstance(v, dict):
                return {k: clean(w) for k, w in v.items()}
            if isinstance(v, list):
                return [clean(w) for w in v]
            return v

        return clean(
            {
                "values": self.values,
                "std_error": self.std_error,
                "relative": self.relative,
                "intervals": self.intervals,
                "correlation": self.correlation,
                "combinations": self.combinations,
                "condition": self.condition,
                "noise": self.noise,
                "method": self.method,
            }
        )


def _whitened(sens: Sensitivities) -> tuple[np.ndarray, dict[str, list[float]]]:
    """Stack the Jacobians, each output divided by its residual RMS."""
    blocks, noise = [], {}
    for name, r, jac in zip(sens.experiments, sens.residuals, sens.jacobian, strict=True):
        sigma = np.sqrt(np.mean(r**2, axis=0))
        sigma = np.where(sigma > 0, sigma, 1.0)
        noise[name] = [float(v) for v in sigma]
        blocks.append((jac / sigma[None, :, None]).reshape(-1, jac.shape[-1]))
    return np.vstack(blocks), noise


def _interval(space: Space, j: int, s: float, half: float) -> list[float | None]:
    low_s, high_s = s - half, s + half
    low = None if low_s < space.s_lower[j] - 1.0 else space.value(j, low_s)
    high = None if high_s > space.s_upper[j] + 1.0 else space.value(j, high_s)
    if half > 2 * UNDETERMINED:
        low = high = None
    return [low, high]


def uncertainty(sens: Sensitivities, space: Space, x: Mapping[str, float]) -> Uncertainty | None:
    """Compute the standard errors, intervals and combinations (see the module doc).

    Returns ``None`` if the outputs do not depend on the parameters at all.
    """
    jac, noise = _whitened(sens)
    fisher = jac.T @ jac
    if not np.all(np.isfinite(fisher)) or not np.any(fisher):
        return None
    values, vectors = np.linalg.eigh(fisher)
    top = max(float(values.max()), 1e-300)
    inv = np.where(values > 1e-14 * top, 1.0 / np.maximum(values, 1e-300), np.inf)
    cov = (vectors * np.where(np.isfinite(inv), inv, 0.0)) @ vectors.T
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    weak = ~np.isfinite(inv)
    if weak.any():  # directions the data do not see at all: infinite variance
        se = se + np.where((vectors[:, weak] ** 2).sum(axis=1) > 1e-6, np.inf, 0.0)
    s0 = space.to_s(x)
    out = Uncertainty(values={n: float(x[n]) for n in space.names}, noise=noise)
    out.condition = float(top / max(float(values.min()), 1e-300))
    for j, n in enumerate(space.names):
        width = space.width[j] * se[j]  # in working-domain units (decades for log)
        out.std_error[n] = float(abs(x[n]) * math.log(10) * width) if space.log[j] else float(width)
        out.relative[n] = float(100 * out.std_error[n] / abs(x[n])) if x[n] else math.inf
        out.intervals[n] = _interval(space, j, float(s0[j]), Z95 * float(se[j]))
    d = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = cov / np.outer(d, d)
    for i, n in enumerate(space.names):
        out.correlation[n] = {m: float(corr[i, k]) for k, m in enumerate(space.names)}
    for k in np.argsort(values)[::-1]:
        v = space.u_direction(vectors[:, k])
        se_k = 1.0 / math.sqrt(values[k]) if values[k] > 1e-14 * top else math.inf
        terms = {space.label(j): round(float(c), 3) for j, c in enumerate(v) if abs(c) >= 0.05}
        out.combinations.append(
            {"terms": terms, "std_error": se_k, "determined": se_k < UNDETERMINED}
        )
    return out
