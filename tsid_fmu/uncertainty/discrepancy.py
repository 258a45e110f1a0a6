"""Do the intervals hold? A verdict on the model's fit to the data, from what the study has.

Every interval assumes that the model explains the data and the residuals are noise.
A model that leaves something out (friction, a sensor's filter, a stiffening spring)
biases the parameters that absorb it; no covariance, white or HAC, covers a bias, so
those intervals miss the truth however narrow they are. This module tests the
assumption at the answer with no further simulation, and returns one verdict:

- **constancy** across segments: each experiment's record is cut into halves, and the
  parameters each segment alone would move to (one Gauss-Newton step from the answer,
  with the Jacobian the intervals use) are compared with their scatter under the noise
  model of the intervals (each segment's own AR(p) long-run covariance of the score, so
  coloured noise is allowed for). A correct model gives the same parameters in every
  segment; a mismatch that acts differently on different stretches of the excitation
  does not. The statistic is the score test of parameter constancy (Chow's test in its
  Lagrange-multiplier form, made robust to correlation as Andrews 1993 does): the stacked
  segment scores at the answer, ``g_s = J_s^T r_s``, have covariance
  ``A diag(S_s) A^T`` with ``A = I - [F_s] F^-1 [I ... I]``; their Mahalanobis norm is
  chi-square with its rank of degrees of freedom. The scores tested are ``A g``: each
  segment's less its share of the total. At an exact optimum, with the Jacobian it was
  found with, the total is zero and nothing changes; where it is not (forward
  differences across corners that move with the parameters, as OpenModelica's ramp
  has, or an answer stopped a little short), the raw scores read that as the segments
  disagreeing (the ramp: p = 7.6e-6 with the intervals' step of 2e-3, 0.24 with 5e-4;
  projected, 0.53 and 0.53).
- **residual RMS** above :data:`~tsid_fmu.uncertainty.assess.MISMATCH` times the noise
  (reported by :mod:`tsid_fmu.uncertainty.assess`).
- **colour** (Ljung-Box) of an output whose noise is not a sensor's rounding: the
  residuals keep a pattern in time. Coloured sensor noise does that, and the HAC
  intervals allow for it; so does a model error, and then they do not hold. One record
  cannot tell the two apart, and the verdict says so rather than choose.

Verdicts: ``"consistent"`` (no evidence against the model: the intervals hold as far
as these data can show), ``"coloured"`` (the intervals may not hold) and
``"mismatch"`` (they do not hold: the model does not explain the data).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from tsid_fmu.numerics.tuning import DISCREPANCY_ALPHA as ALPHA
from tsid_fmu.numerics.tuning import RANK as _RANK
from tsid_fmu.numerics.tuning import SEGMENTS
from tsid_fmu.uncertainty.longrun import long_run_covariance

__all__ = ["ALPHA", "SEGMENTS", "Discrepancy", "constancy", "judge"]


@dataclass
class Discrepancy:
    """One verdict on whether the intervals hold (module doc).

    Attributes
    ----------
    verdict : str
        ``"consistent"``, ``"coloured"`` or ``"mismatch"``.
    reasons : list of str
        The evidence, in words.
    constancy : dict
        The constancy test: ``statistic``, ``dof``, ``p_value``, ``segments``.
    """

    verdict: str = "consistent"
    reasons: list[str] = field(default_factory=list)
    constancy: dict[str, Any] = field(default_factory=dict)

    @property
    def holds(self) -> bool:
        """True when nothing in the data speaks against the intervals."""
        return self.verdict == "consistent"

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy."""
        return {
            "verdict": self.verdict,
            "holds": self.holds,
            "reasons": list(self.reasons),
            "constancy": dict(self.constancy),
        }

    def warning(self) -> str:
        """Return the warning a study shows (empty when the intervals hold)."""
        if self.holds:
            return ""
        what = (
            "the intervals do not hold: the model does not explain these data"
            if self.verdict == "mismatch"
            else "the intervals may not hold"
        )
        tail = (
            "; a model error biases the parameters that absorb it, and no interval "
            "covers a bias. Add what the model leaves out, or judge the answer on a "
            "validation experiment"
            if self.verdict == "mismatch"
            else "; coloured sensor noise does this, and the intervals allow for it, "
            "but so does a model that leaves something out, and then they miss the "
            "truth: these data cannot tell which. A validation experiment, or a second "
            "experiment with other inputs, can"
        )
        return f"{what} ({'; '.join(self.reasons)}){tail}"


def constancy(
    series: Sequence[tuple[str, str, np.ndarray, np.ndarray]], inverse: np.ndarray
) -> dict[str, Any]:
    """Score test that every segment of the records has the same parameters (module doc).

    Parameters
    ----------
    series : sequence of (experiment, output, residuals, jacobian)
        Whitened residuals ``(n,)`` and their Jacobian ``(n, q)`` per experiment and
        output, in time order.
    inverse : numpy.ndarray
        The pseudo-inverse of the Fisher matrix of all the series.

    Returns
    -------
    dict
        ``statistic``, ``dof``, ``p_value`` (1.0 where nothing can be tested) and
        ``segments`` (their number).
    """
    groups: dict[tuple[str, int], list[tuple[np.ndarray, np.ndarray]]] = {}
    for name, _, r, jac in series:
        edges = np.linspace(0, r.size, SEGMENTS + 1).astype(int)
        for k in range(SEGMENTS):
            cut = slice(edges[k], edges[k + 1])
            if edges[k + 1] - edges[k] > 2 * jac.shape[1] + 2:
                groups.setdefault((name, k), []).append((r[cut], jac[cut]))
    q = inverse.shape[0]
    blank = {"statistic": 0.0, "dof": 0, "p_value": 1.0, "segments": len(groups)}
    if len(groups) < 2:
        return blank
    scores, fishers, middles = [], [], []
    for parts in groups.values():
        scores.append(sum(jac.T @ r for r, jac in parts))
        fishers.append(sum(jac.T @ jac for _, jac in parts))
        middles.append(long_run_covariance(parts, inverse).middle)
    k = len(groups)
    a = np.eye(k * q) - np.vstack(fishers) @ inverse @ np.hstack([np.eye(q)] * k)
    blocks = np.zeros((k * q, k * q))
    for i, m in enumerate(middles):
        blocks[i * q : (i + 1) * q, i * q : (i + 1) * q] = m
    cov = a @ blocks @ a.T
    g = a @ np.concatenate(scores)  # each segment less its share of the total score
    if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(g))):
        return blank
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = values > _RANK * max(float(values.max()), 1e-300)
    dof = int(keep.sum())  # (k - 1) q at most: the scores sum to 0 at the answer
    if dof < 1:
        return blank
    statistic = float(np.sum((vectors[:, keep].T @ g) ** 2 / values[keep]))
    return {
        "statistic": statistic,
        "dof": dof,
        "p_value": float(stats.chi2.sf(statistic, dof)),
        "segments": k,
    }


def judge(
    test: dict[str, Any], coloured: Sequence[str], misfit: Sequence[str], inflation: float = 1.0
) -> Discrepancy:
    """Return the verdict on the intervals from the evidence (module doc).

    Parameters
    ----------
    test : dict
        :func:`constancy`'s result.
    coloured : sequence of str
        ``experiment / output`` of coloured residuals whose noise is not a rounding.
    misfit : sequence of str
        ``experiment / output`` whose residual RMS exceeds the mismatch threshold.
    inflation : float
        How optimistic white-noise standard errors would be (the HAC's median ratio).
    """
    out = Discrepancy(constancy=dict(test))
    if misfit:
        out.reasons.append(f"residual RMS far above the noise: {', '.join(misfit)}")
    if test.get("p_value", 1.0) < ALPHA:
        out.reasons.append(
            f"the {test['segments']} segments of the records (halves of each experiment) "
            f"call for different parameters beyond the noise (constancy test: chi-square "
            f"{test['statistic']:.3g} on {test['dof']} degrees of freedom, p = "
            f"{test['p_value']:.2g})"
        )
    if out.reasons:
        out.verdict = "mismatch"
    if coloured:
        out.reasons.append(
            f"the residuals are coloured ({', '.join(coloured)}): standard errors that "
            f"assume white noise would be optimistic by ~x{inflation:.3g}, and the "
            "intervals use a HAC covariance that allows for coloured noise"
        )
        out.verdict = out.verdict if out.verdict == "mismatch" else "coloured"
    return out
