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
where a Gaussian draw would be white and make the intervals too narrow. It costs what
the study's own intervals cost: ``2p + 1`` simulations and the profiles'.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from tsid_fmu.evaluate.factory import make_evaluator
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.assess import assess

__all__ = ["predicted_intervals"]


def predicted_intervals(
    spec: EvaluationSpec,
    proposal: EvaluationSpec,
    outputs: np.ndarray,
    noise: np.ndarray,
    space: Space,
    x: Mapping[str, float],
    seed: int,
    *,
    workers: int | None = 1,
    timeout: float | None = 0,
) -> tuple[dict[str, list[float | None]], int]:
    """Return the 95 % intervals of the study plus ``proposal``, and the simulations used.

    ``proposal`` holds the one proposed experiment (:func:`~tsid_fmu.design.plan.
    candidate_spec`), ``outputs`` its simulated outputs at ``x``, ``noise`` the template
    experiment's residuals ``(n, outputs)`` (measured minus simulated at ``x``).
    """
    (exp,) = proposal.experiments
    shift = int(np.random.default_rng([seed, 48]).integers(noise.shape[0]))
    rows = (np.arange(outputs.shape[0]) + shift) % noise.shape[0]
    measured = outputs + noise[rows]
    synthetic = dataclasses.replace(exp, name="proposed", measured=measured)
    # the proposal's residuals are scaled as the candidates' (its sensors' noise)
    both = dataclasses.replace(spec, experiments=(*spec.experiments, synthetic))
    with make_evaluator(both, workers=workers, timeout=timeout) as ev:
        found = assess(ev, both, space, dict(x))
        nfev = ev.nfev
    u = found.uncertainty
    none: list[float | None] = [None, None]
    return ({n: list(u.intervals.get(n, none)) if u else none for n in space.names}, nfev)
