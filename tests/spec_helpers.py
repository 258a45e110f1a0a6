"""Build an EvaluationSpec straight from data frames, without a Study.

``experiment(frame, ...)`` arranges one experiment the way the study layer does: the
measured inputs, ``replicates - 1`` noisy copies of them (Gaussian noise of
``input_noise`` times each input's standard deviation, drawn from
``numpy.random.default_rng([seed, index, r])``), weights 1 and residual scale 1 unless
given. ``lag_frame(seed, n, ...)`` makes the noisy input and smoothed outputs such
experiments fit a first-order lag to.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from tsid_fmu.evaluate import EvaluationSpec, PreparedExperiment


def lag_frame(seed: int, n: int, *, omega: float, step_at: float, window: int) -> pd.DataFrame:
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
