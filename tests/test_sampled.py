"""Sampled intervals (issue 29, item 5): ``[method] uncertainty = "bootstrap"`` or
``"monte_carlo"``: the noise draws keep the residuals' colour, the re-fits give the
textbook intervals of a linear model, the option is checked, and the intervals travel
through result.json, the reports and the command line beside the primary ones."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from spec_helpers import experiment

from tsid_fmu import Method, StudyError
from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.evaluate import Evaluation, Simulated
from tsid_fmu.search.space import Space
from tsid_fmu.study.toml import study_from_document
from tsid_fmu.uncertainty.longrun import fit_ar
from tsid_fmu.uncertainty.resample import ar_draw, block_bootstrap, block_length, percentile
from tsid_fmu.uncertainty.sampled import Sampled, sampled_intervals
from tsid_fmu.uncertainty.sensitivity import sensitivities


def _ar1(rng: np.random.Generator, n: int, rho: float) -> np.ndarray:
    out = np.empty(n)
    out[0] = rng.normal()
    e = rng.normal(0.0, math.sqrt(1 - rho * rho), n)
    for k in range(1, n):
        out[k] = rho * out[k - 1] + e[k]
    return out


def _lag1(x: np.ndarray) -> float:
    x = x - x.mean()
    return float(x[1:] @ x[:-1] / (x @ x))


# ------------------------------------------------------------------ the noise draws


def test_the_block_bootstrap_keeps_the_lag1_correlation_of_an_ar1_series():
    rng = np.random.default_rng(3)
    for rho in (0.5, 0.8):
        x = _ar1(rng, 3000, rho)
        block = block_length(x)
        drawn = [_lag1(block_bootstrap(x[:, None], block, rng)[:, 0]) for _ in range(20)]
        # i.i.d. resampling (block 1) would give a lag-1 correlation near 0
        assert np.mean(drawn) == pytest.approx(_lag1(x), abs=0.06), (rho, block)


def test_white_residuals_are_resampled_one_sample_at_a_time():
    assert block_length(np.random.default_rng(1).normal(size=2000)) == 1


def test_the_monte_carlo_draws_have_the_residuals_ar_model():
    rng = np.random.default_rng(5)
    model = fit_ar(_ar1(rng, 4000, 0.7))
    paths = [ar_draw(model, 4000, rng) for _ in range(10)]
    assert np.mean([_lag1(p) for p in paths]) == pytest.approx(0.7, abs=0.03)
    assert np.mean([p.std() for p in paths]) == pytest.approx(1.0, rel=0.05)
    # stationary from the first sample: the start is no quieter than the rest
    heads = np.array([ar_draw(model, 5, rng)[0] for _ in range(2000)])
    assert heads.std() == pytest.approx(1.0, rel=0.06)


def test_the_percentile_interval_is_the_quantiles_of_the_finite_values():
    values = [*np.arange(1.0, 102.0), math.nan]
    assert percentile(values, 0.9) == pytest.approx([6.0, 96.0])
    assert percentile([1.0, math.nan], 0.95) == [None, None]


# ------------------------------------------------------------- a known linear model

T = np.linspace(0.0, 1.0, 120)
SIGMA = 0.05


class LineEvaluator:
    """``y = a + b t`` against ``measured``: an evaluator without an FMU."""

    n_replicates = 1

    def __init__(self, measured: np.ndarray) -> None:
        frame = pd.DataFrame({"time": T, "y": measured})
        exp = experiment(frame, {}, {"y": "y"}, name="line", scale=[SIGMA])
        self.spec = SimpleNamespace(cost="sse", experiments=(exp,))
        self.measured, self.nfev = measured, 0

    def evaluate(self, sets, progress=None) -> Evaluation:
        res = [(s["a"] + s["b"] * T - self.measured) / SIGMA for s in sets]
        self.nfev += len(res)
        costs = np.array([[float(r @ r)] for r in res])
        return Evaluation(costs=costs, errors=[None] * len(res), nfev=len(res), residuals=res)

    def simulate(self, sets, *, count=True) -> list:
        out = [[Simulated("line", (s["a"] + s["b"] * T)[:, None], None)] for s in sets]
        self.nfev += len(out) if count else 0
        return out


def _line_fit(seed: int) -> tuple[LineEvaluator, Space, dict[str, float], np.ndarray]:
    rng = np.random.default_rng(seed)
    y = 1.0 + 2.0 * T + rng.normal(0.0, SIGMA, T.size)
    design = np.column_stack([np.ones_like(T), T])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    resid = y - design @ coef
    s2 = float(resid @ resid) / (T.size - 2)
    half = 1.96 * np.sqrt(s2 * np.diag(np.linalg.inv(design.T @ design)))
    levels = {"a": [0.0, 2.0], "b": [1.0, 3.0]}
    bounds = {n: (-math.inf, math.inf) for n in levels}
    space = Space(levels, bounds, LevelingOptions(scale="linear"))
    return LineEvaluator(y), space, {"a": coef[0], "b": coef[1]}, half


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["bootstrap", "monte_carlo"])
def test_percentile_intervals_of_a_linear_model_are_the_textbook_ones(kind):
    ratios, centres = [], []
    for seed in range(8):
        ev, space, x, half = _line_fit(seed)
        sens = sensitivities(ev, ev.spec, space, x)
        out = sampled_intervals(ev, ev.spec, space, x, sens, kind=kind, replicates=400, seed=seed)
        assert out.failed == 0 and out.unfinished == 0 and out.nfev <= 2 * 400
        for j, n in enumerate(("a", "b")):
            low, high = out.intervals[n]
            ratios.append((high - low) / (2 * half[j]))
            centres.append((0.5 * (low + high) - x[n]) / half[j])
    # +/- 1.96 s sqrt((X^T X)^-1): the mean over seeds within a few percent
    assert np.mean(ratios) == pytest.approx(1.0, abs=0.05)
    assert np.std(ratios) < 0.12
    assert np.mean(np.abs(centres)) < 0.1


def test_the_refits_find_each_replicates_least_squares_optimum():
    ev, space, x, _ = _line_fit(11)
    sens = sensitivities(ev, ev.spec, space, x)
    out = sampled_intervals(ev, ev.spec, space, x, sens, kind="monte_carlo", replicates=30, seed=2)
    # the replicates' estimates spread as the noise does: the re-fits moved
    assert out.std_error["a"] > 0 and out.std_error["b"] > 0
    frame = out.to_pandas()
    assert list(frame.columns) == ["a", "b"] and len(frame) == 30
    assert frame.index.name == "replicate"


# --------------------------------------------------------------- the study option


def test_the_option_is_checked_with_clear_errors():
    assert Method(cost="sse", uncertainty="bootstrap").uncertainty_replicates == 100
    with pytest.raises(StudyError, match="uncertainty must be 'analytic', 'bootstrap' or"):
        Method(cost="sse", uncertainty="bootstrapping")
    with pytest.raises(StudyError, match=r"minimises the sse cost; the study uses .iae."):
        Method(cost="iae", uncertainty="monte_carlo")
    with pytest.raises(StudyError, match="uncertainty_replicates must be an integer >= 20"):
        Method(cost="sse", uncertainty="bootstrap", uncertainty_replicates=5)


def test_the_option_is_read_from_a_study_file(tmp_path):
    (tmp_path / "m.fmu").write_bytes(b"")
    (tmp_path / "d.csv").write_text("time,y\n0,1\n1,2\n")
    doc = {
        "study": {"fmu": "m.fmu"},
        "data": {"file": "d.csv", "outputs": {"y": "y"}},
        "parameters": {"k": {"levels": [1, 2]}},
        "method": {"cost": "sse", "uncertainty": "monte_carlo", "uncertainty_replicates": 40},
    }
    method = study_from_document(doc, tmp_path, "s.toml")["method"]
    assert (method.uncertainty, method.uncertainty_replicates) == ("monte_carlo", 40)
    doc["method"]["uncertainty_replicates"] = "many"
    with pytest.raises(StudyError, match=r"s\.toml: .method. uncertainty_replicates must be an"):
        study_from_document(doc, tmp_path, "s.toml")


def test_sampled_intervals_travel_through_json():
    out = Sampled(
        "bootstrap",
        3,
        intervals={"a": [1.0, 2.0], "b": [None, 3.0]},
        std_error={"a": 0.1, "b": math.nan},
        estimates={"a": [1.0, math.nan, 2.0], "b": [3.0, 3.0, 3.0]},
        noise={"e": {"block_length": 4}},
        nfev=9,
        method="words",
    )
    back = Sampled.from_dict(json.loads(json.dumps(out.to_dict(), allow_nan=False)))
    assert back.to_dict() == out.to_dict()
    assert math.isnan(back.estimates["a"][1]) and math.isnan(back.std_error["b"])


def test_the_shared_model_refits_reach_each_replicates_own_optimum():
    from scipy.optimize import least_squares

    from tsid_fmu.uncertainty.refits import Replicate, SharedModel, refit, tolerance

    t = np.linspace(0.0, 4.0, 80)
    sigma = 0.3  # large: one Gauss-Newton step misses the optima by up to 0.3 se

    def residuals(s: np.ndarray) -> np.ndarray:
        return s[0] * np.exp(-s[1] * t) / sigma

    rng = np.random.default_rng(4)
    data = [2.0 * np.exp(-1.3 * t) + rng.normal(0.0, sigma, t.size) for _ in range(25)]
    s0 = least_squares(lambda s: residuals(s) - data[0] / sigma, [2.0, 1.3]).x
    r0 = residuals(s0)
    jac0 = np.column_stack(
        [(residuals(s0 + h) - residuals(s0 - h)) / 2e-6 for h in np.eye(2) * 1e-6]
    )
    tol = tolerance(r0 - data[0] / sigma)  # the answer's residual variance
    reps = [Replicate(y / sigma, np.zeros(2), r0 - y / sigma, tol) for y in data[1:]]
    space = Space(
        {"a": [1.0, 3.0], "b": [0.5, 2.0]},
        {"a": (0, 9), "b": (0, 9)},
        LevelingOptions(scale="linear"),
    )
    refit(reps, SharedModel(r0, jac0), space, s0, lambda pts: [residuals(p) for p in pts])
    se = np.sqrt(np.diag(np.linalg.inv(jac0.T @ jac0)))  # residuals in units of the noise
    for rep, y in zip(reps, data[1:], strict=True):
        best = least_squares(lambda s, y=y: residuals(s) - y / sigma, s0, xtol=1e-12).x
        assert np.all(np.abs(s0 + rep.d - best) < 0.05 * se), (rep.steps, s0 + rep.d, best)
    assert sum(rep.steps for rep in reps) <= 5 * len(reps)
