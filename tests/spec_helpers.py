"""Build an EvaluationSpec straight from data frames, without a Study.

``experiment(frame, ...)`` arranges one experiment the way the study layer does: the
measured inputs, ``replicates - 1`` noisy copies of them (Gaussian noise of
``input_noise`` times each input's standard deviation, drawn from
``numpy.random.default_rng([seed, index, r])``), weights 1 and residual scale 1 unless
given. ``lag_frame(seed, ...)`` makes the noisy input and smoothed outputs such
experiments fit a first-order lag to. ``CurveEvaluator`` scores parameter sets of a
plain Python model, for the search stages' tests without an FMU.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from tsid_fmu.evaluate import Evaluation, EvaluationSpec, PreparedExperiment


def lag_frame(
    seed: int, n: int = 801, *, omega: float = 9.0, step_at: float = 0.3, window: int = 40
) -> pd.DataFrame:
    """``n`` samples at 1 ms of an input ``u`` and two outputs ``y``, ``y2`` to fit a lag to.

    ``u`` is ``sin(omega * t)`` plus a unit step after ``step_at`` plus Gaussian noise of
    0.05 from ``numpy.random.default_rng(seed)``; ``y`` is its centred moving average over
    ``window`` samples and ``y2 = y / 2``.
    """
    t = np.arange(n) * 1e-3
    rng = np.random.default_rng(seed)
    u = np.sin(omega * t) + (t > step_at) + 0.05 * rng.standard_normal(n)
    y = np.convolve(u, np.ones(window) / window, mode="same")
    return pd.DataFrame({"time": t, "u": u, "y": y, "y2": 0.5 * y})


def experiment(
    frame: pd.DataFrame,
    inputs: Mapping[str, str],
    outputs: Mapping[str, str],
    *,
    name: str = "experiment",
    index: int = 0,
    replicates: int = 1,
    input_noise: float = 0.0,
    seed: int = 0,
    weights: Sequence[float] | None = None,
    scale: Sequence[float] | None = None,
    start_values: Mapping[str, float] | None = None,
) -> PreparedExperiment:
    u = frame[list(inputs.values())].to_numpy(dtype=float) if inputs else None
    noisy = []
    if u is not None and input_noise > 0:
        sigma = input_noise * np.std(u, axis=0)
        for r in range(1, replicates):
            rng = np.random.default_rng([seed, index, r])
            noisy.append(u + rng.standard_normal(u.shape) * sigma)
    n_out = len(outputs)
    return PreparedExperiment(
        name=name,
        time=frame["time"].to_numpy(dtype=float),
        input_names=tuple(inputs),
        output_names=tuple(outputs),
        inputs=u,
        measured=frame[list(outputs.values())].to_numpy(dtype=float),
        weights=np.ones(n_out) if weights is None else np.asarray(weights, dtype=float),
        scale=np.ones(n_out) if scale is None else np.asarray(scale, dtype=float),
        noisy_inputs=tuple(noisy),
        start_values=dict(start_values or {}),
    )


def make_spec(
    fmu: Path,
    parameters: Sequence[str],
    experiments: Sequence[PreparedExperiment],
    **options,
) -> EvaluationSpec:
    return EvaluationSpec(
        fmu=Path(fmu),
        parameter_names=tuple(parameters),
        experiments=tuple(experiments),
        **options,
    )


class CurveEvaluator:
    """Scores parameter sets of ``model(**set)`` against ``measured``, without an FMU.

    The residuals are ``(model(**set) - measured) / scale`` and the cost their sum of
    squares, as a study's ``sse`` cost; ``asked`` logs every set simulated.
    """

    n_replicates = 1
    spec = None

    def __init__(self, model: Callable[..., np.ndarray], measured: np.ndarray, scale: float):
        self.model, self.measured, self.scale = model, measured, scale
        self.nfev, self.asked = 0, []

    def residuals(self, params: Mapping[str, float]) -> np.ndarray:
        return (self.model(**params) - self.measured) / self.scale

    def cost(self, **params: float) -> float:
        r = self.residuals(params)
        return float(r @ r)

    def evaluate(self, sets, progress=None) -> Evaluation:
        residuals = [self.residuals(s) for s in sets]
        self.nfev += len(sets)
        self.asked += [dict(s) for s in sets]
        costs = np.array([[float(r @ r)] for r in residuals])
        return Evaluation(
            costs=costs, errors=[None] * len(sets), nfev=len(sets), residuals=residuals
        )


def floor_experiment(measured: np.ndarray, scale: float) -> object:
    """What ``noise_floor`` reads of a prepared experiment, for a curve with no windows."""
    from types import SimpleNamespace

    return SimpleNamespace(
        measured=measured[:, None],
        scale=np.array([scale]),
        weighted_samples=float(len(measured)),  # no windows: every sample scored
        scored=lambda a: a,
    )
