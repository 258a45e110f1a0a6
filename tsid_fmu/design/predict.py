"""The intervals a study would report with a proposed experiment added.

The Fisher matrix of finite differences is no guide to them where the model has events:
on the SISO example with a designed experiment added, it gave B_s a 0.002 % standard
error while the study's profile found 19 % (the dry friction's switching makes the
differences see sensitivity the data do not have). So the prediction runs the study's
own analysis (:func:`tsid_fmu.uncertainty.assess.assess`: the HAC covariance, the
profile likelihood, the probes of loose combinations) at the answer, on the study's
experiments plus the proposal, whose "measured" outputs are the model's at the answer
plus the template experiment's own residuals there, circularly shifted by a seeded
offset (repeated where the proposal is longer): the sensors' noise with the colour and
the distribution this rig's data show (an encoder's rounding, a load cell's noise),
where a Gaussian draw would be white and make the intervals too narrow. That noise
less its part along the proposal's sensitivities (:func:`centred`): the answer is then
the optimum of the synthetic data, as the achieved answer is of the real ones. Without
it, the profiles start from a point the noise has moved the optimum away from, by a
rise of the cost comparable to their threshold, and every interval came out wider: on
the MISO example 1.6 to 1.9 times (``benchmarks/design.py --case miso``). It costs what the
study's own intervals cost: ``2p + 1`` simulations and the profiles'.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from tsid_fmu.evaluate.factory import make_evaluator
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.assess import assess

__all__ = ["centred", "predicted_intervals"]


def centred(noise: np.ndarray, jacobian: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Return ``noise`` ``(n, outputs)`` less its least-squares fit by the sensitivities.

    ``jacobian`` is the proposal's, whitened by the sensors' noise ``sigma``, one row
    per sample and output (sample after sample). Whitened, the noise's projection on
    the Jacobian's columns is what would move the estimate; removed, the answer is the
    optimum of the answer's outputs plus this noise, to first order. Noise or a
    Jacobian with a non-finite entry is returned as it is.
    """
    white = (noise / sigma[None, :]).ravel()
    if jacobian.shape[0] != white.size or not (
        np.all(np.isfinite(white)) and np.all(np.isfinite(jacobian))
    ):
        return noise
    coef = np.linalg.lstsq(jacobian, white, rcond=None)[0]
    return (white - jacobian @ coef).reshape(noise.shape) * sigma[None, :]


def predicted_intervals(
    spec: EvaluationSpec,
    proposal: EvaluationSpec,
    outputs: np.ndarray,
    noise: np.ndarray,
    space: Space,
    x: Mapping[str, float],
    seed: int,
    *,
    jacobian: np.ndarray | None = None,
    sigma: np.ndarray | None = None,
    workers: int | None = 1,
    timeout: float | None = 0,
) -> tuple[dict[str, list[float | None]], int]:
    """Return the 95 % intervals of the study plus ``proposal``, and the simulations used.

    ``proposal`` holds the one proposed experiment (:func:`~tsid_fmu.design.plan.
    candidate_spec`), ``outputs`` its simulated outputs at ``x``, ``noise`` the template
    experiment's residuals ``(n, outputs)`` (measured minus simulated at ``x``);
    ``jacobian`` and ``sigma`` the proposal's whitened sensitivities and its sensors'
    noise, to centre that noise (:func:`centred`; left as it is without them).
    """
    (exp,) = proposal.experiments
    shift = int(np.random.default_rng([seed, 48]).integers(noise.shape[0]))
    rows = (np.arange(outputs.shape[0]) + shift) % noise.shape[0]
    drawn = noise[rows]
    if jacobian is not None and sigma is not None:
        drawn = centred(drawn, jacobian, sigma)
    measured = outputs + drawn
    synthetic = dataclasses.replace(exp, name="proposed", measured=measured)
    # the proposal's residuals are scaled as the candidates' (its sensors' noise)
    both = dataclasses.replace(spec, experiments=(*spec.experiments, synthetic))
    with make_evaluator(both, workers=workers, timeout=timeout) as ev:
        found = assess(ev, both, space, dict(x))
        nfev = ev.nfev
    u = found.uncertainty
    none: list[float | None] = [None, None]
    return ({n: list(u.intervals.get(n, none)) if u else none for n in space.names}, nfev)
