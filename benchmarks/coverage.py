"""Coverage of the 95 % intervals, measured over many noise seeds (no FMU).

The plant is an exponential decay ``y = a exp(-b t)`` sampled at ``N`` points on
``[0, 4]``; ``b``'s first levels span a decade, so it lives in log10 coordinates and
its intervals are asymmetric, as in a study. For every seed the data get fresh noise,
SciPy's least squares finds the minimum of the study's ``sse`` cost, and the package
computes the intervals at that minimum exactly as :func:`tsid_fmu.uncertainty.assess.assess`
does:

- ``wald``: :func:`tsid_fmu.uncertainty.intervals.uncertainty` (HAC sandwich from an
  AR(p) model of the residuals, at least the Cramer-Rao bound, Student t) on white
  noise;
- ``profile``: the profile-likelihood intervals of ``assess`` on white noise;
- ``hac``: the ``wald`` intervals on AR(1) noise (``RHO``), where the Cramer-Rao
  intervals alone would be far too narrow;
- ``profile_ar1``: the profile intervals on the same AR(1) noise (their threshold
  carries the HAC inflation);
- for reference, not the package's: ``crb_ar1``, the Cramer-Rao (white-noise)
  intervals on the AR(1) noise, ``exact_ar1``, the sandwich with the noise's true
  covariance, and ``nw_ar1``, the Newey-West sandwich (Bartlett kernel, Andrews'
  bandwidth from the residuals' lag-1 correlation, at least the Cramer-Rao bound) that
  the package used before issue 27, all ``+/- Z95`` standard errors in the search
  coordinates.

The coverage of each parameter is the share of seeds whose interval holds the truth.
A correct 95 % interval lands in :data:`BAND` with high probability
(:func:`pass_probability`); 68 % intervals (``se`` instead of ``1.96 se``) do not.
Run::

    python benchmarks/coverage.py              # 400 seeds per kind
    python benchmarks/coverage.py --seeds 1000
    python benchmarks/coverage.py --rho 0.3 0.8  # other AR(1) coefficients
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy import linalg, optimize, stats

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.evaluate import Evaluation, PreparedExperiment, Simulated
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.assess import _widen_by_profile
from tsid_fmu.uncertainty.intervals import Z95, uncertainty
from tsid_fmu.uncertainty.sensitivity import sensitivities

TRUTH = {"a": 2.0, "b": 1.3}
LEVELS = {"a": [1.0, 2.0, 3.0], "b": [0.2, 1.0, 5.0]}
N = 200
SIGMA = 0.02
RHO = 0.5
"""Lag-1 correlation of the coloured noise (``hac``, ``profile_ar1``)."""

BAND = (0.925, 0.975)
"""Coverage a 95 % interval must reach over the seeds (400 seeds: about 2.3 binomial
standard deviations either side of 0.95)."""

KINDS = ("wald", "profile", "hac", "profile_ar1", "crb_ar1", "exact_ar1", "nw_ar1")
T = np.linspace(0.0, 4.0, N)


def model(a: float, b: float) -> np.ndarray:
    """The plant's output at ``T``."""
    return a * np.exp(-b * T)


def ar1(rng: np.random.Generator, n: int, rho: float, sigma: float) -> np.ndarray:
    """Stationary AR(1) noise of standard deviation ``sigma``."""
    e = rng.normal(0.0, sigma * math.sqrt(1 - rho**2), n)
    out = np.empty(n)
    out[0] = rng.normal(0.0, sigma)
    for k in range(1, n):
        out[k] = rho * out[k - 1] + e[k]
    return out


class DecayEvaluator:
    """Scores and simulates parameter sets of :func:`model` against ``measured``."""

    n_replicates = 1

    def __init__(self, measured: np.ndarray, scale: float) -> None:
        self.spec = SimpleNamespace(
            cost="sse",
            experiments=(
                PreparedExperiment(
                    name="decay",
                    time=T,
                    input_names=(),
                    output_names=("y",),
                    inputs=None,
                    measured=measured[:, None],
                    weights=np.ones(1),
                    scale=np.array([scale]),
                ),
            ),
        )
        self.measured, self.scale, self.nfev = measured, scale, 0

    def residuals(self, x: dict[str, float]) -> np.ndarray:
        """``(model - measured) / scale``."""
        return (model(x["a"], x["b"]) - self.measured) / self.scale

    def evaluate(self, sets: Iterable[dict[str, float]], progress: object = None) -> Evaluation:
        """Cost and residuals of each set."""
        res = [self.residuals(dict(s)) for s in sets]
        self.nfev += len(res)
        costs = np.array([[float(r @ r)] for r in res])
        return Evaluation(costs=costs, errors=[None] * len(res), nfev=len(res), residuals=res)

    def simulate(self, sets: Iterable[dict[str, float]], *, count: bool = True) -> list:
        """Outputs of each set, as an evaluator's ``simulate``."""
        out = [[Simulated("decay", model(s["a"], s["b"])[:, None], None)] for s in sets]
        self.nfev += len(out) if count else 0
        return out


@dataclass
class Fit:
    """One seed's data and least-squares answer."""

    evaluator: DecayEvaluator
    space: Space
    x: dict[str, float]
    cost: float
    rho: float


def fit(seed: int, rho: float = 0.0) -> Fit:
    """Draw seed ``seed``'s noise (AR(1) when ``rho``), fit, return the answer."""
    rng = np.random.default_rng(seed)
    noise = ar1(rng, N, rho, SIGMA) if rho else rng.normal(0.0, SIGMA, N)
    ev = DecayEvaluator(model(**TRUTH) + noise, SIGMA)
    sol = optimize.least_squares(
        lambda p: ev.residuals({"a": p[0], "b": p[1]}),
        [TRUTH["a"], TRUTH["b"]],
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
    )
    x = {"a": float(sol.x[0]), "b": float(sol.x[1])}
    space = Space(LEVELS, {n: (0.0, math.inf) for n in LEVELS}, LevelingOptions())
    return Fit(ev, space, x, float(ev.evaluate([x]).costs[0, 0]), rho)


def wald(f: Fit) -> dict[str, list[float | None]]:
    """The package's covariance intervals at the answer."""
    sens = sensitivities(f.evaluator, f.evaluator.spec, f.space, f.x)
    u = uncertainty(sens, f.space, f.x)
    return u.intervals


def profile(f: Fit) -> dict[str, list[float | None]]:
    """The package's profile-likelihood intervals at the answer."""
    sens = sensitivities(f.evaluator, f.evaluator.spec, f.space, f.x)
    u = uncertainty(sens, f.space, f.x)
    spec = f.evaluator.spec
    _widen_by_profile(f.evaluator, spec, f.space, sens, u, x=f.x, cost=f.cost)
    return u.profile


def newey_west(scores: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """Newey-West long-run covariance of ``scores``, Andrews' Bartlett bandwidth.

    The bandwidth ``ceil(1.1447 (alpha n)^(1/3))``, ``alpha = 4 rho^2 / ((1 - rho)^2
    (1 + rho)^2)``, ``rho`` the residuals' lag-1 autocorrelation, at most ``n / 4``.
    """
    n = residuals.size
    x = residuals - residuals.mean()
    rho = min(max(float(x[1:] @ x[:-1] / (x @ x)), -0.999), 0.999)
    alpha = 4 * rho * rho / ((1 - rho) ** 2 * (1 + rho) ** 2)
    bandwidth = int(min(math.ceil(1.1447 * (alpha * n) ** (1 / 3)), n // 4))
    out = scores.T @ scores
    for lag in range(1, bandwidth + 1):
        gamma = scores[lag:].T @ scores[:-lag]
        out += (1.0 - lag / (bandwidth + 1.0)) * (gamma + gamma.T)
    return out


def reference(f: Fit, how: str) -> dict[str, list[float | None]]:
    """``+/- Z95`` standard errors of a covariance the package does not compute.

    ``how``: ``"exact"``, the sandwich with the noise's true covariance; ``"crb"``, the
    Cramer-Rao covariance with the residual RMS as the noise (white residuals assumed);
    ``"nw"``, the Newey-West sandwich, at least the Cramer-Rao covariance.
    """
    sens = sensitivities(f.evaluator, f.evaluator.spec, f.space, f.x)
    jac, r = sens.jacobian[0][:, 0, :], sens.residuals[0][:, 0]
    inv = np.linalg.inv(jac.T @ jac)
    cov = inv * float(np.mean(r**2))
    if how == "exact":
        noise = SIGMA**2 * linalg.toeplitz(f.rho ** np.arange(N))
        cov = inv @ jac.T @ noise @ jac @ inv
    elif how == "nw":
        hac = inv @ newey_west(jac * r[:, None], r) @ inv
        cov = hac + np.diag(np.maximum(np.diag(cov) - np.diag(hac), 0.0))
    s0, se = f.space.to_s(f.x), np.sqrt(np.diag(cov))
    return {
        n: [f.space.value(j, s0[j] - Z95 * se[j]), f.space.value(j, s0[j] + Z95 * se[j])]
        for j, n in enumerate(f.space.names)
    }


def covers(interval: list[float | None], truth: float) -> bool:
    """Whether ``interval`` (``None``: an open end) holds ``truth``."""
    low, high = interval
    return (low is None or low <= truth) and (high is None or truth <= high)


def coverage(
    fits: list[Fit], intervals: Callable[[Fit], dict[str, list[float | None]]]
) -> dict[str, float]:
    """Share of ``fits`` whose interval of each parameter holds the truth."""
    hits = dict.fromkeys(TRUTH, 0)
    for f in fits:
        found = intervals(f)
        for name, truth in TRUTH.items():
            hits[name] += covers(found[name], truth)
    return {name: hits[name] / len(fits) for name in TRUTH}


def in_band(share: float, band: tuple[float, float] = BAND) -> bool:
    """Whether a measured coverage is what a 95 % interval gives."""
    return band[0] <= share <= band[1]


def pass_probability(seeds: int, p: float = 0.95, band: tuple[float, float] = BAND) -> float:
    """Probability that ``seeds`` independent seeds of a ``p`` interval land in ``band``."""
    lo, hi = math.ceil(band[0] * seeds - 1e-9), math.floor(band[1] * seeds + 1e-9)
    return float(stats.binom.cdf(hi, seeds, p) - stats.binom.cdf(lo - 1, seeds, p))


def table(seeds: int, rho: float = RHO) -> list[tuple[str, str, float, float]]:
    """Coverage of every kind and parameter: ``(kind, parameter, coverage, seconds)``."""
    rows = []
    white = [fit(s) for s in range(seeds)]
    coloured = [fit(s, rho) for s in range(seeds)]
    how = {
        "wald": wald,
        "profile": profile,
        "hac": wald,
        "profile_ar1": profile,
        "crb_ar1": lambda f: reference(f, "crb"),
        "exact_ar1": lambda f: reference(f, "exact"),
        "nw_ar1": lambda f: reference(f, "nw"),
    }
    for kind in KINDS:
        fits = white if kind in ("wald", "profile") else coloured
        start = time.perf_counter()
        found = coverage(fits, how[kind])
        seconds = time.perf_counter() - start
        rows += [(kind, name, share, seconds) for name, share in found.items()]
    return rows


def main() -> None:
    """Print the coverage table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=400)
    parser.add_argument("--rho", type=float, nargs="+", default=[RHO], help="AR(1) coefficients")
    args = parser.parse_args()
    seeds = args.seeds
    print(
        f"band {BAND[0]:.1%} .. {BAND[1]:.1%}: a true 95 % interval lands in it with "
        f"probability {pass_probability(seeds):.3f}; a 68 % one with "
        f"{pass_probability(seeds, 0.6827):.1g}"
    )
    for rho in args.rho:
        print(f"\n{seeds} seeds, N = {N}, sigma = {SIGMA}, AR(1) rho = {rho}")
        rows = table(seeds, rho)
        exact = {name: share for kind, name, share, _ in rows if kind == "exact_ar1"}
        print(
            f"{'kind':<12} {'parameter':<9} {'coverage':>8}  {'in band':<7} "
            f"{'miss/exact':>12} {'s':>5}"
        )
        for kind, name, share, seconds in rows:
            ok = "yes" if in_band(share) else "NO"
            ratio = (1 - share) / max(1 - exact[name], 1e-9)
            shown = "" if kind in ("wald", "profile") else f"{ratio:.2f}"
            print(f"{kind:<12} {name:<9} {share:>8.2%}  {ok:<7} {shown:>12} {seconds:>5.1f}")


if __name__ == "__main__":
    main()
