"""Predicted S/N at the chosen levels, its confidence interval, and the confirmation run.

Taguchi's additive model predicts the S/N at the chosen level of each factor as
``eta = T + sum_f (m_f - T)`` over the factors not pooled into the error (``T`` the
grand mean of the S/N, ``m_f`` the mean S/N at the chosen level of factor ``f``). Its
95 % confidence interval is ``± sqrt(F(0.05; 1, dof_e) V_e / n_eff)`` with ``V_e`` the
error variance after pooling and ``n_eff = runs / (1 + sum of the dof of the factors
used)``; for one confirmation run the interval is ``± sqrt(F V_e (1/n_eff + 1))``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tsid_fmu.search.record import IterationRecord

__all__ = ["prediction"]


def _chosen_is_confirmed(rec: IterationRecord) -> bool:
    """Tell whether the confirmation run used exactly the chosen level of every factor."""
    best = rec.response.best_level
    offsets = rec.prediction.get("offsets") or []
    if len(offsets) != len(rec.frame.factors):
        return False
    return all(
        math.isclose(float(z), float(f.offsets[best[f.name]]), rel_tol=1e-9, abs_tol=1e-12)
        for z, f in zip(offsets, rec.frame.factors, strict=True)
    )


def prediction(rec: IterationRecord) -> dict[str, Any]:
    """Return the predicted S/N at the chosen levels and the confirmation run's S/N.

    Returns
    -------
    dict
        ``predicted`` (dB), ``ci`` (half width of the 95 % interval of the mean,
        NaN when the error has no degrees of freedom), ``ci_confirmation`` (for one
        run), ``factors`` (used in the prediction), ``confirmation_cost``,
        ``confirmation_sn`` (dB, ``-20 lg cost``: replicate 1, the measured inputs),
        ``at_chosen_levels`` (False where the confirmation run sat between levels),
        ``within`` (True/False/None: the confirmation S/N inside the interval).
    """
    from scipy.stats import f as f_dist

    rt, an = rec.response, rec.anova
    used = [n for n in rec.names if n not in an.pooled]
    grand = float(rt.grand_mean)
    eta = grand + sum(float(rt.means[n][rt.best_level[n]]) - grand for n in used)
    runs = len(rec.sn)
    n_eff = runs / (1 + sum(an.dof[n] for n in used))
    ci = ci_conf = math.nan
    if an.error_dof > 0 and math.isfinite(an.error_ms) and an.error_ms >= 0:
        f_crit = float(f_dist.ppf(0.95, 1, an.error_dof))
        ci = math.sqrt(f_crit * an.error_ms / n_eff)
        ci_conf = math.sqrt(f_crit * an.error_ms * (1 / n_eff + 1))
    cost = float(rec.prediction.get("cost", math.inf))
    sn = -20 * math.log10(cost) if math.isfinite(cost) and cost > 0 else math.nan
    within = (
        None
        if not (math.isfinite(ci_conf) and math.isfinite(sn))
        else bool(abs(sn - eta) <= ci_conf)
    )
    return {
        "predicted": float(np.clip(eta, -1e6, 1e6)),
        "ci": ci,
        "ci_confirmation": ci_conf,
        "factors": used,
        "confirmation_cost": cost,
        "confirmation_sn": sn,
        "at_chosen_levels": _chosen_is_confirmed(rec),
        "within": within,
        "error_dof": an.error_dof,
    }
