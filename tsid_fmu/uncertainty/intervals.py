"""Confidence intervals of the identified parameters, and what the data determine.

From the sensitivities at the answer (:mod:`tsid_fmu.uncertainty.sensitivity`), each
output is whitened by its residual RMS at the answer (its noise as the fit sees it).
The Fisher matrix ``F = J^T J`` of the search coordinates gives the Cramer-Rao
covariance ``F^-1``, which holds for white residuals. Residuals that are correlated in
time (a model that misses something, a quantised sensor) make it too small, so the
covariance used is the HAC sandwich ``F^-1 S F^-1``, ``S`` the long-run covariance of
the score from an AR(p) model of every output series, corrected for what the fit
absorbs (:mod:`tsid_fmu.uncertainty.longrun`), and never less than the Cramer-Rao one.
For white residuals the two agree.

The 95 % interval of each parameter is its coordinate +/- ``t`` standard errors, mapped
back to parameter units (asymmetric for parameters in log10); ``t`` is the Student
quantile with the Satterthwaite degrees of freedom of the parameter's variance (how
well the residuals determine it: ``n - p`` for white residuals, far fewer for strongly
correlated ones), 1.96 for many. The eigenvectors of ``F`` name the combinations of
parameters the data determine and those they do not; a parameter dominated by an
undetermined combination gets an open interval (``None``) rather than a small, false
one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from tsid_fmu.numerics.rank import UNSEEN
from tsid_fmu.numerics.space import Space
from tsid_fmu.numerics.tuning import LEVEL, RATIO_GAIN, UNDETERMINED, Z95
from tsid_fmu.uncertainty.discrepancy import Discrepancy, constancy
from tsid_fmu.uncertainty.longrun import long_run_covariance
from tsid_fmu.uncertainty.residuals import ljung_box
from tsid_fmu.uncertainty.sensitivity import Sensitivities

__all__ = [
    "LEVEL",
    "UNDETERMINED",
    "UNSEEN",
    "Z95",
    "Uncertainty",
    "combination_terms",
    "quantile",
    "seen_inverse",
    "uncertainty",
]


def seen_inverse(a: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of ``a`` over the directions the outputs depend on (:data:`UNSEEN`).

    A Gauss-Newton re-fit with NumPy's default cut-off inverts the rounding along an
    exact symmetry: on OpenModelica's ``Mass_Damper`` (an input without effect, and
    three offsets that only act through their sum) the profile's first re-fit put the
    force at 2e7 N and an offset at 9e6 m, and the intervals closed around the answer
    where the cost is flat.
    """
    return np.linalg.pinv(a, rcond=math.sqrt(UNSEEN))


def json_safe(v: Any) -> Any:
    """Return ``v`` with its non-finite floats, in nested dicts and lists, as ``None``."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: json_safe(w) for k, w in v.items()}
    if isinstance(v, list):
        return [json_safe(w) for w in v]
    return v


@dataclass
class Uncertainty:
    """Standard errors, intervals, residual diagnostics and determined combinations.

    Attributes
    ----------
    values : dict
        The parameter values analysed.
    std_error : dict
        Standard error of each parameter, in parameter units near the value.
    relative : dict
        Standard error relative to the value, in percent.
    cramer_rao : dict
        The Cramer-Rao (white-residual) relative standard error, in percent.
    intervals : dict
        95 % interval ``[low, high]`` per parameter; ``None`` for an end the data do not
        determine.
    correlation : dict of dict
        Correlation coefficients of the estimates.
    combinations : list of dict
        Eigen-combinations of the Fisher matrix, best determined first: ``{"terms":
        {coordinate: weight}, "std_error": in search units, "percent": relative standard
        error of the combination when all its parameters are in log10, "determined"}``.
    condition : float
        Condition number of the Fisher matrix.
    noise : dict
        Residual RMS of each experiment's outputs at the answer.
    whiteness : dict
        Per experiment and output: Ljung-Box p-value, lag-1 autocorrelation, whether
        white, and the order of the AR model of the HAC covariance.
    inflation : float
        Median over the parameters of the HAC standard error over the Cramer-Rao one: how
        optimistic white-residual standard errors would be.
    method : str
        How the intervals were computed.
    dof : dict
        Degrees of freedom of each parameter's variance (Satterthwaite); its interval
        is +/- :func:`quantile` ``(dof)`` standard errors.
    constancy : dict
        The score test that every half of every experiment calls for the same
        parameters (:func:`tsid_fmu.uncertainty.discrepancy.constancy`).
    discrepancy : Discrepancy
        Whether the intervals hold: the verdict on the model's fit to the data
        (:mod:`tsid_fmu.uncertainty.discrepancy`).
    resolution : dict
        Parameters whose standard error lies below what the profile likelihood resolves
        (:data:`tsid_fmu.uncertainty.profile.RESOLUTION`): the bound, in percent of the
        value. Their ``std_error`` and ``relative`` hold that bound, not an estimate.
    cov : numpy.ndarray or None
        Covariance of the search coordinates; a parameter with a direction the outputs
        do not depend on has an infinite variance (:data:`UNSEEN`).
    seen_cov : numpy.ndarray or None
        The same over the directions the outputs depend on, finite.
    bounds_of : tuple of numpy.ndarray or None
        The HAC covariance and the Cramer-Rao bound over those directions, each
        combination's variance being the larger of its two (:meth:`variance`).
    unseen : numpy.ndarray or None
        ``(p, m)`` orthonormal basis of the directions the outputs do not depend on.
    """

    values: dict[str, float]
    std_error: dict[str, float] = field(default_factory=dict)
    relative: dict[str, float] = field(default_factory=dict)
    cramer_rao: dict[str, float] = field(default_factory=dict)
    intervals: dict[str, list[float | None]] = field(default_factory=dict)
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    combinations: list[dict[str, Any]] = field(default_factory=list)
    condition: float = float("nan")
    noise: dict[str, list[float]] = field(default_factory=dict)
    whiteness: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    inflation: float = 1.0
    profile: dict[str, list[float | None]] = field(default_factory=dict)
    scale_groups: list[dict[str, Any]] = field(default_factory=list)
    method: str = (
        "HAC sandwich (AR(p) long-run covariance, BIC order, corrected for the fit), at "
        "least the Cramer-Rao bound; Student t with Satterthwaite degrees of freedom"
    )
    resolution: dict[str, float] = field(default_factory=dict)
    dof: dict[str, float] = field(default_factory=dict)
    constancy: dict[str, Any] = field(default_factory=dict)
    discrepancy: Discrepancy = field(default_factory=Discrepancy)
    cov: np.ndarray | None = field(default=None, repr=False)
    seen_cov: np.ndarray | None = field(default=None, repr=False)
    unseen: np.ndarray | None = field(default=None, repr=False)
    bounds_of: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    def variance(self, g: np.ndarray) -> float:
        """Variance of the combination ``g @ s`` of the search coordinates ``s``.

        Infinite where ``g`` reaches a direction the outputs do not depend on (by more
        than a thousandth of its length), else the larger of its HAC variance and its
        Cramer-Rao bound (:attr:`bounds_of`; :attr:`seen_cov` without them). NaN without
        a covariance.

        The bound is the combination's own: the parameters' covariance floors each
        diagonal entry at its bound, and a parameter in a weak direction has a large one,
        which ``g @ seen_cov @ g`` would add to every combination of it, however well
        determined (the sum of two parameters whose difference is weak).
        """
        if self.cov is None:
            return math.nan
        g = np.asarray(g, dtype=float)
        if self.unseen is not None and self.unseen.size:
            reach = float(np.sum((self.unseen.T @ g) ** 2))
            if reach > 1e-6 * float(g @ g):
                return math.inf
        if self.bounds_of is not None:  # g's own HAC variance, at least its own bound
            hac, crb = self.bounds_of
            return max(float(g @ hac @ g), float(g @ crb @ g), 0.0)
        seen = self.seen_cov
        if seen is None:
            seen = np.where(np.isfinite(self.cov), self.cov, 0.0)
        return max(float(g @ seen @ g), 0.0)

    @property
    def sigma(self) -> dict[str, list[float]]:
        """The noise used per experiment and output (the same as :attr:`noise`)."""
        return self.noise

    @property
    def coloured(self) -> list[str]:
        """``experiment / output`` of every residual series that is not white."""
        return [
            f"{e} / {o}"
            for e, outs in self.whiteness.items()
            for o, w in outs.items()
            if not w["white"]
        ]

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy (non-finite numbers as ``None``)."""
        keys = (
            "values",
            "std_error",
            "relative",
            "cramer_rao",
            "intervals",
            "correlation",
            "combinations",
            "condition",
            "noise",
            "whiteness",
            "inflation",
            "profile",
            "scale_groups",
            "method",
            "resolution",
            "dof",
            "constancy",
        )
        out = json_safe({k: getattr(self, k) for k in keys})
        out["discrepancy"] = self.discrepancy.to_dict()
        return out


def quantile(dof: float) -> float:
    """Two-sided :data:`LEVEL` quantile of Student's t with ``dof`` degrees of freedom."""
    return float(stats.t.ppf(0.5 + LEVEL / 2, max(dof, 1.0)))


def _series(
    sens: Sensitivities,
) -> tuple[np.ndarray, list[tuple[str, str, np.ndarray, np.ndarray]]]:
    """Whitened Jacobian of everything, and each output's (residual, Jacobian) series."""
    blocks, series = [], []
    for name, outs, r, jac in zip(
        sens.experiments, sens.output_names, sens.residuals, sens.jacobian, strict=True
    ):
        sigma = np.sqrt(np.mean(r**2, axis=0))
        sigma = np.where(sigma > 0, sigma, 1.0)
        for k, out in enumerate(outs):
            rk, jk = r[:, k] / sigma[k], jac[:, k, :] / sigma[k]
            series.append((name, out, rk, jk))
            blocks.append(jk)
    return np.vstack(blocks), series


def _covariances(
    fisher: np.ndarray, series: list[tuple[str, str, np.ndarray, np.ndarray]], out: Uncertainty
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cramer-Rao and HAC covariances, Fisher eigen-decomposition, degrees of freedom."""
    values, vectors = np.linalg.eigh(fisher)
    top = max(float(values.max()), 1e-300)
    keep = values > UNSEEN * top
    inv = np.where(keep, 1.0 / np.maximum(values, 1e-300), 0.0)
    pinv = (vectors * inv) @ vectors.T
    found = long_run_covariance([(r, jac) for _, _, r, jac in series], pinv)
    for (name, output, r, _), model in zip(series, found.models, strict=True):
        test = ljung_box(r)
        out.whiteness.setdefault(name, {})[output] = {
            "p_value": test.p_value,
            "rho1": test.rho1,
            "white": test.white,
            "ar_order": model.order,
        }
    crb = pinv
    hac = pinv @ found.middle @ pinv
    # never below the Cramer-Rao bound on the diagonal (HAC estimates are noisy too)
    floored = np.diag(hac) <= np.diag(crb)
    cov = hac + np.diag(np.maximum(np.diag(crb) - np.diag(hac), 0.0))
    # Satterthwaite: a variance known from nu degrees of freedom has variance 2 V^2 / nu
    white = max(sum(r.size for _, _, r, _ in series) - int(keep.sum()), 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = np.where(found.variance > 0, 2 * np.diag(hac) ** 2 / found.variance, white)
    dof = np.clip(np.where(floored | ~np.isfinite(nu), white, nu), 1.0, white)
    out.seen_cov, out.unseen = cov, vectors[:, ~keep]
    out.bounds_of = (hac, crb)
    if not keep.all():  # directions the data do not see at all: infinite variance
        unseen = (vectors[:, ~keep] ** 2).sum(axis=1) > 1e-6
        cov = cov + np.diag(np.where(unseen, np.inf, 0.0))
        crb = crb + np.diag(np.where(unseen, np.inf, 0.0))
    out.condition = float(top / max(float(values.min()), 1e-300))
    return crb, cov, values, vectors, dof


def _interval(space: Space, j: int, s: float, half: float) -> list[float | None]:
    if not math.isfinite(half) or half > 2 * UNDETERMINED:
        return [None, None]
    low_s, high_s = s - half, s + half
    low = None if low_s < space.s_lower[j] - 1.0 else space.value(j, low_s)
    high = None if high_s > space.s_upper[j] + 1.0 else space.value(j, high_s)
    return [low, high]


def combination_terms(space: Space, v: np.ndarray) -> dict[str, float]:
    """Name a direction ``v`` of the search coordinates by its working-domain weights.

    ``{coordinate label: weight}`` of the unit vector of working-domain changes, for the
    weights of at least 0.05.
    """
    u = space.u_direction(v)
    return {space.label(j): round(float(c), 3) for j, c in enumerate(u) if abs(c) >= 0.05}


def _combinations(
    space: Space, values: np.ndarray, vectors: np.ndarray, found: Uncertainty
) -> list:
    """Return the Fisher matrix's eigenvectors as combinations, with standard errors.

    A combination's ``percent`` is its relative standard error, over log and linear
    members alike: with only log members counted, a common scale whose damping was made
    linear below its first levels (:meth:`.Space.near`) had none, was never probed
    (:mod:`.probe`) and stayed "determined" while its members' profiles were open.

    A combination has an infinite one where the outputs do not depend on it at all
    (:data:`UNSEEN`). Every other eigenvector is orthogonal to those directions, so its
    variance is finite even where it touches a parameter that also has an unseen part:
    on OpenModelica's ``Mass_Damper`` the common scale of mass, stiffness and damping
    touched an offset of the spring by 0.02, was called infinite on that ground, and so
    was never probed, while its members kept finite intervals excluding the truth.
    """
    out = []
    seen = values > UNSEEN * max(float(values.max()), 1e-300)
    # each coordinate's relative change per search unit, as a parameter's own relative
    # standard error is read (local_scale / |x|): log10 units, or linear ones (a log
    # coordinate made linear below its first levels, Space.near, is a relative one too)
    x = found.values
    rel = np.array(
        [
            space.local_scale(j, x[n]) / abs(x[n]) if x[n] else math.nan
            for j, n in enumerate(space.names)
        ]
    )
    for k in np.argsort(values)[::-1]:
        v = vectors[:, k]
        se = math.sqrt(found.variance(v)) if seen[k] else math.inf
        terms = combination_terms(space, v)
        used = [j for j, c in enumerate(space.u_direction(v)) if abs(c) >= 0.05]
        # relative standard error along the unit direction; undefined where a member is 0
        # (its rel not finite: left out of the norm, which nan_to_num's 1.8e308 overflowed)
        with np.errstate(over="ignore"):
            scale = float(np.linalg.norm(v * np.where(np.isfinite(rel), rel, 0.0)))
        percent = (
            100 * se * scale
            if math.isfinite(se) and all(math.isfinite(rel[j]) for j in used)
            else math.nan
        )
        out.append(
            {
                "terms": terms,
                "std_error": se,
                "percent": percent,
                "determined": se < UNDETERMINED,
                "direction": [float(c) for c in v],  # in the search coordinates
            }
        )
    return out


def uncertainty(sens: Sensitivities, space: Space, x: Mapping[str, float]) -> Uncertainty | None:
    """Compute standard errors, intervals, diagnostics and combinations (module doc).

    Returns ``None`` if the outputs do not depend on the parameters at all.
    """
    jac, series = _series(sens)
    fisher = jac.T @ jac
    if not np.all(np.isfinite(fisher)) or not np.any(fisher):
        return None
    out = Uncertainty(values={n: float(x[n]) for n in space.names})
    for name, r in zip(sens.experiments, sens.residuals, strict=True):
        out.noise[name] = [float(v) for v in np.sqrt(np.mean(r**2, axis=0))]
    crb, cov, values, vectors, dof = _covariances(fisher, series, out)
    se, se_crb = np.sqrt(np.clip(np.diag(cov), 0, None)), np.sqrt(np.clip(np.diag(crb), 0, None))
    s0 = space.to_s(x)
    ratios = []
    for j, n in enumerate(space.names):
        out.std_error[n] = float(space.local_scale(j, x[n]) * se[j])
        out.relative[n] = float(100 * out.std_error[n] / abs(x[n])) if x[n] else math.inf
        crb_n = float(space.local_scale(j, x[n]) * se_crb[j])
        out.cramer_rao[n] = float(100 * crb_n / abs(x[n])) if x[n] else math.inf
        out.dof[n] = float(dof[j])
        out.intervals[n] = _interval(space, j, float(s0[j]), quantile(dof[j]) * float(se[j]))
        if 0 < se_crb[j] < math.inf and math.isfinite(se[j]):
            ratios.append(se[j] / se_crb[j])
    out.inflation = float(np.median(ratios)) if ratios else 1.0
    finite = np.where(np.isfinite(cov), cov, 0.0)
    d = np.sqrt(np.clip(np.diag(finite), 1e-300, None))
    corr = finite / np.outer(d, d)
    for i, n in enumerate(space.names):
        out.correlation[n] = {m: float(corr[i, k]) for k, m in enumerate(space.names)}
    out.cov = cov
    out.combinations = _combinations(space, values, vectors, out)
    values, vectors = np.linalg.eigh(fisher)
    keep = values > UNSEEN * max(float(values.max()), 1e-300)
    inv = np.divide(1.0, values, out=np.zeros_like(values), where=keep)
    out.constancy = constancy(series, (vectors * inv) @ vectors.T)
    return out


def scale_groups(u: Uncertainty, space: Space) -> list[dict[str, Any]]:
    """Find groups of parameters whose ratios the data fix better than the parameters.

    A model that depends on some parameters only through their ratios (a mass and a
    stiffness through a natural frequency) lets the data fix those ratios well and the
    group's common scale poorly. Parameters are joined when the relative standard error
    of their ratio (from the covariance) is :data:`RATIO_GAIN` times smaller than both
    of theirs (which include the profile likelihood).

    Returns
    -------
    list of dict
        ``{"parameters": [...], "ratios": {"a/b": percent}, "scale_percent": percent}``.
    """
    cov = getattr(u, "cov", None)
    if cov is None:
        return []
    names = list(space.names)
    idx = [j for j, n in enumerate(names) if space.log[j] and math.isfinite(u.relative[n])]
    w = space.width * math.log(10.0) * 100.0  # percent per search unit, for log parameters
    parent = {j: j for j in idx}

    def root(j: int) -> int:
        while parent[j] != j:
            j = parent[j]
        return j

    ratios: dict[tuple[int, int], float] = {}
    for a in idx:
        for b in idx:
            if b <= a:
                continue
            var = cov[a, a] * w[a] ** 2 + cov[b, b] * w[b] ** 2 - 2 * cov[a, b] * w[a] * w[b]
            pct = math.sqrt(max(var, 0.0)) if np.isfinite(var) else math.inf
            weaker = min(u.relative[names[a]], u.relative[names[b]])
            if weaker > 1.0 and pct * RATIO_GAIN < weaker:
                ratios[(a, b)] = pct
                parent[root(b)] = root(a)
    groups: dict[int, list[int]] = {}
    for j in idx:
        groups.setdefault(root(j), []).append(j)
    out = []
    for members in groups.values():
        if len(members) < 2:
            continue
        ref = min(members, key=lambda j: u.relative[names[j]])
        found = {
            f"{names[a]}/{names[b]}": p
            for (a, b), p in ratios.items()
            if a in members and b in members
        }
        out.append(
            {
                "parameters": [names[j] for j in members],
                "ratios": found,
                "scale_percent": u.relative[names[ref]],
            }
        )
    return out
