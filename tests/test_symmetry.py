"""An exact symmetry is reported as not determined, never with finite intervals (issue 45).

OpenModelica's ``MassSpringSubSystem1`` depends on its masses and stiffnesses only
through their ratios, as modestpy's ``Simple2R1C`` on R1, R2 and C through R1 C and R2 C.
Finite differences see a little sensitivity along the exact null direction, so the
covariance gave it a finite standard error, called it "determined", and the intervals
excluded the truth. :func:`~tsid_fmu.uncertainty.probe.probe_combinations` profiles each
loose combination; here a cost that is exactly flat along ``lg a - lg b`` stands in for
the FMU, with the combination the differences report tilted 3 degrees off it.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from fmu_factory import build_pythonfmu, pythonfmu_available

from tsid_fmu import Experiment, Parameter, Study
from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.search.space import Space
from tsid_fmu.study.prepare import serial_evaluator
from tsid_fmu.uncertainty import probe
from tsid_fmu.uncertainty.intervals import Uncertainty, _combinations
from tsid_fmu.uncertainty.probe import (
    FLAT,
    fixed_across,
    open_undetermined,
    probe_combinations,
    structural,
)

WEIGHTS = np.linspace(1.0, 2.0, 10)


class _Flat:
    """Residuals ``w (s_a - s_b)``: exactly flat along (1, 1), steep across it."""

    def __init__(self, space: Space, curved: float) -> None:
        self.space, self.curved, self.calls = space, curved, 0

    def residuals(self, s: np.ndarray) -> np.ndarray:
        across = 30.0 * WEIGHTS * (s[0] - s[1])
        along = self.curved * WEIGHTS * (s[0] + s[1])  # 0: an exact symmetry
        return np.concatenate([across, along])

    def evaluate(self, sets):
        self.calls += len(sets)
        rs = [self.residuals(self.space.to_s(x)) for x in sets]
        costs = np.array([[float(r @ r)] for r in rs])
        return SimpleNamespace(costs=costs, residuals=rs)


def _case(curved: float):
    space = Space({"a": [1.0, 10.0], "b": [1.0, 10.0]}, {"a": (0.0, math.inf),
                  "b": (0.0, math.inf)}, LevelingOptions())  # fmt: skip
    x = {"a": 3.0, "b": 3.0}
    ev = _Flat(space, curved)
    s0 = space.to_s(x)
    h = 1e-6
    jac = np.column_stack([(ev.residuals(s0 + h * e) - ev.residuals(s0)) / h for e in np.eye(2)])
    u = Uncertainty(values=dict(x))
    u.intervals = {"a": [2.0, 4.5], "b": [2.0, 4.5]}  # what the covariance said
    u.std_error, u.relative = {"a": 0.6, "b": 0.6}, {"a": 20.0, "b": 20.0}
    u.dof = {"a": 50.0, "b": 50.0}
    tilt = math.radians(3.0)
    along = [math.cos(math.pi / 4 + tilt), math.sin(math.pi / 4 + tilt)]
    u.combinations = [
        {"terms": {"lg a": 0.707, "lg b": -0.707}, "std_error": 1e-4, "percent": 0.02,
         "determined": True, "direction": [0.707, -0.707]},
        {"terms": {"lg a": 0.68, "lg b": 0.73}, "std_error": 0.1, "percent": 30.0,
         "determined": True, "direction": along},
    ]  # fmt: skip
    return space, x, ev, jac, u


def test_a_flat_combination_the_covariance_calls_determined_gets_open_intervals():
    space, x, ev, jac, u = _case(curved=0.0)
    warnings = probe_combinations(ev, space, u, x, 0.0, 4.0, jac)
    assert u.intervals == {"a": [None, None], "b": [None, None]}
    assert u.combinations[1]["determined"] is False and u.combinations[0]["determined"]
    assert len(warnings) == 1 and "a, b have open intervals" in warnings[0]
    assert ev.calls <= 7  # REFITS per side, and one for the cost's level near the answer


def test_an_answer_the_solvers_noise_made_lucky_does_not_hide_the_symmetry(monkeypatch):
    # JModelica's Simple2R1C: the answer cost 1.8 less than every point along the exact
    # symmetry (the FMU solver's noise, picked by the search); here 2, against a 95 %
    # threshold of 4
    space, x, ev, jac, u = _case(curved=0.0)
    ev.residuals = lambda s: np.concatenate([_Flat.residuals(ev, s), [math.sqrt(10.0)]])
    jac = np.vstack([jac, np.zeros((1, 2))])
    probe_combinations(ev, space, u, x, 8.0, 4.0, jac)  # 10 everywhere, 8 at the answer
    assert u.intervals == {"a": [None, None], "b": [None, None]}
    # measured from the lucky answer, the same profile reads as a rise
    monkeypatch.setattr(probe, "_level", lambda evaluator, space, s0, v, cost: cost)
    u.intervals = {"a": [2.0, 4.5], "b": [2.0, 4.5]}
    u.combinations[1].update(determined=True, std_error=0.1, percent=30.0)
    u.combinations[1].pop("why", None)
    probe_combinations(ev, space, u, x, 8.0, 4.0, jac)
    assert u.intervals == {"a": [2.0, 4.5], "b": [2.0, 4.5]}


def test_a_curved_combination_stays_determined():
    space, x, ev, jac, u = _case(curved=20.0)
    before = dict(u.intervals)
    assert probe_combinations(ev, space, u, x, 0.0, 4.0, jac) == []
    assert u.intervals == before and u.combinations[1]["determined"]


def test_without_the_refit_the_tilt_would_hide_the_symmetry():
    """Straight along the tilted direction the cost rises steeply: why the probe re-fits."""
    space, x, ev, _, u = _case(curved=0.0)
    v = np.array(u.combinations[1]["direction"])
    s = space.to_s(x) + 2 * 2.0 * 0.1 * v
    assert float(ev.evaluate([space.to_x(s)]).costs[0, 0]) > FLAT * 4.0


def test_a_combination_the_covariance_leaves_open_opens_its_parameters_intervals():
    """MassSpringSubSystem2: the scale 'not determined', yet k3 and m2 had finite
    intervals that excluded the truth."""
    space, x, ev, jac, u = _case(curved=0.0)
    u.combinations[1].update(determined=False, std_error=0.53, percent=122.0)
    warnings = probe_combinations(ev, space, u, x, 0.0, 4.0, jac)
    assert u.intervals == {"a": [None, None], "b": [None, None]} and ev.calls == 0
    assert len(warnings) == 1 and "its standard error is 0.53 search units" in warnings[0]


def test_a_combination_the_fisher_matrix_does_not_see_opens_nothing_more():
    """Mass_Damper: m, c and d determined beside offsets that act only through their
    sum; their combination with a trace of the offsets has an infinite standard error,
    which is not a reason to open m, c and d."""
    space, x, ev, jac, u = _case(curved=0.0)
    u.combinations[1].update(determined=False, std_error=math.inf, percent=math.nan)
    assert probe_combinations(ev, space, u, x, 0.0, 4.0, jac) == []
    assert u.intervals == {"a": [2.0, 4.5], "b": [2.0, 4.5]}


def test_the_combinations_across_an_open_direction_are_named_with_intervals():
    """modestpy's Simple2R1C fixes only R1 C and R2 C (issue 45): with C, R1 and R2 open,
    the report names those products, in the parameters' own terms, with intervals."""
    levels = {"C": [500.0, 5000.0], "R1": [0.01, 1.0], "R2": [0.05, 2.0]}
    space = Space(levels, {n: (0.0, math.inf) for n in levels}, LevelingOptions())
    truth = {"C": 2000.0, "R1": 0.1, "R2": 0.25}
    v = np.array([-1.0, 1.0, 1.0]) / space.width  # lg C down as lg R1 and lg R2 go up
    unit = v / np.linalg.norm(v)
    across = np.linalg.svd(np.eye(3) - np.outer(unit, unit))[0][:, :2]
    # a covariance huge along the symmetry (the differences' noise), 1e-6 across it
    u = Uncertainty(values=dict(truth))
    u.cov = 1e4 * np.outer(unit, unit) + 1e-6 * across @ across.T
    u.dof = {n: 100.0 for n in levels}
    fixed = fixed_across(space, u, v, ["C", "R1", "R2"])
    assert [f["name"] for f in fixed] == ["C R1", "C R2"]
    assert [f["value"] for f in fixed] == pytest.approx([200.0, 500.0], rel=1e-12)
    for f, value in zip(fixed, (200.0, 500.0), strict=True):
        low, high = f["interval"]
        assert low < value < high and high / low < 1.05  # finite, and narrow
    # a standard error of hundreds of decades across it (a non-deterministic FMU's
    # Jacobian): open intervals, where 10 ** (level + t se) raised OverflowError (exit 70)
    wild = Uncertainty(values=dict(truth), dof=u.dof)
    wild.cov = 1e4 * np.outer(unit, unit) + 1e6 * across @ across.T
    assert [f["interval"] for f in fixed_across(space, wild, v, ["C", "R1", "R2"])] == [
        [None, None],
        [None, None],
    ]
    # the warning that opens their intervals carries them
    u.intervals = {n: [0.9 * x, 1.1 * x] for n, x in truth.items()}
    u.std_error = {n: 0.1 * x for n, x in truth.items()}
    u.relative = {n: 10.0 for n in truth}
    u.combinations = [{"terms": {"lg C": -0.58, "lg R1": 0.58, "lg R2": 0.58},
                       "std_error": math.inf, "percent": math.inf, "determined": False,
                       "direction": list(v), "why": "profiled: flat"}]  # fmt: skip
    (warning,) = open_undetermined(space, u)
    assert "only the combinations across it are fixed: C R1 = 200 (" in warning
    assert "; C R2 = 500 (" in warning
    assert u.combinations[0]["fixed"] == fixed


def test_a_common_scale_with_a_member_made_linear_is_probed_and_named():
    """OpenModelica's ``Mass_Damper``, free response: the outputs see d / m and c / m only.

    On some CPUs' BLAS kernels the answer's damping fell below its first levels, so
    :meth:`Space.near` made it linear. The combination's relative error was then left
    undefined (only log members counted), it was never probed, stayed "determined", and
    exit 0 came with open intervals and no warning; its products were not named either.
    """
    levels = {"damper.d": [3.162, 31.62], "mass.m": [0.1, 1.0], "spring.c": [1e3, 4e4]}
    x = {"damper.d": 2.19, "mass.m": 0.365, "spring.c": 3654.0}
    space = Space(levels, {n: (0.0, math.inf) for n in levels}, LevelingOptions()).near(x)
    assert [bool(g) for g in space.log] == [False, True, True]  # d below its first levels
    # the common scale: one decade of each parameter, in the near space's coordinates
    v = np.array([x["damper.d"] * math.log(10.0), 1.0, 1.0]) / space.width
    unit = v / np.linalg.norm(v)
    across = np.linalg.svd(np.eye(3) - np.outer(unit, unit))[0][:, :2]
    fisher = 1e-2 * np.outer(unit, unit) + 1e8 * across @ across.T  # weak along the scale
    values, vectors = np.linalg.eigh(fisher)
    u = Uncertainty(values=dict(x))
    u.cov = np.linalg.inv(fisher)
    u.dof = {n: 100.0 for n in levels}
    (weak,) = [c for c in _combinations(space, values, vectors, u) if c["std_error"] > 1]
    assert math.isfinite(weak["percent"]) and weak["percent"] >= probe.LOOSE  # probed
    fixed = fixed_across(space, u, np.asarray(weak["direction"]), list(levels))
    assert [f["name"] for f in fixed] == ["damper.d mass.m^-1", "damper.d spring.c^-1"]
    ratios = [x["damper.d"] / x["mass.m"], x["damper.d"] / x["spring.c"]]
    assert [f["value"] for f in fixed] == pytest.approx(ratios, rel=1e-9)
    for f, value in zip(fixed, ratios, strict=True):
        low, high = f["interval"]
        assert low < value < high and high / low < 1.01


@pytest.mark.skipif(not pythonfmu_available(), reason="needs pythonfmu and a shared libpython")
def test_a_symmetry_that_holds_for_other_inputs_too_is_called_structural(tmp_path):
    """The lag with tau = R C: scaling R by k and C by 1/k changes nothing for any input,
    so the report can say that no experiment of this kind separates them (issue 45)."""
    fmu = build_pythonfmu(tmp_path, "RCLag", rc=True)
    t = np.round(np.arange(0.0, 2.0 + 1e-9, 0.02), 10)
    u = np.where(t < 0.7, 1.0, 0.2) + 0.3 * np.sin(5 * t)
    y = np.zeros_like(t)
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(tmp_path / "d.csv", index=False)
    study = Study(
        fmu=fmu,
        parameters=[Parameter("R", [0.5, 2.0], min=0.0), Parameter("C", [0.1, 0.5], min=0.0)],
        experiments=[
            Experiment(tmp_path / "d.csv", inputs={"u": "u"}, outputs={"y": "y"}, noise={"y": 0.01})
        ],
        cost="sse",
        replicates=1,
    )
    x = {"R": 1.0, "C": 0.3}
    with serial_evaluator(study) as ev:
        level = 0.01  # the residuals' RMS at the answer, in the cost's units
        assert structural(ev, x, [{"R": 2.0, "C": 0.15}, {"R": 0.5, "C": 0.6}], level) is True
        assert structural(ev, x, [{"R": 1.1, "C": 0.3}], level) is False  # tau moved 10 %
        assert structural(ev, x, [], level) is None


def test_the_products_pair_the_parameter_that_moves_against_the_others_and_use_their_names():
    """JModelica's Simple2R1C in the study's order (R1, R2, C), along a direction the
    solver's noise tilted (C's weight 0.652 against 0.537 and 0.535): the products are
    C R1 and C R2 (not R1 R2^-1 and R1 C), and their values are those of the products
    their names show (the study had reported R1 C = 202.11 against a truth of 200)."""
    levels = {"R1": [0.02, 0.6], "R2": [0.02, 0.6], "C": [500.0, 8000.0]}
    space = Space(levels, {n: (0.0, math.inf) for n in levels}, LevelingOptions())
    values = {"R1": 0.049701, "R2": 0.12428, "C": 4026.0}
    v = np.array([0.537, 0.535, -0.652])
    u = Uncertainty(values=dict(values))
    u.cov = 1e-8 * np.eye(3)
    u.dof = {n: 100.0 for n in levels}
    fixed = fixed_across(space, u, v, ["R1", "R2", "C"])
    assert [f["name"] for f in fixed] == ["C R1", "C R2"]
    assert fixed[0]["value"] == pytest.approx(4026.0 * 0.049701, rel=1e-12)
    assert fixed[1]["value"] == pytest.approx(4026.0 * 0.12428, rel=1e-12)


def test_a_flat_combination_takes_its_direction_from_the_refitted_probes():
    """The probes' re-fitted points lie on the valley, so the chord between them is its
    direction; the differences' eigenvector was tilted 3 degrees. On Mass_Damper the
    tilt named the combination across the scale ``damper.d mass.m^-0.974``, with an
    interval that excluded the true d / m."""
    space, x, ev, jac, u = _case(curved=0.0)
    probe_combinations(ev, space, u, x, 0.0, 4.0, jac)
    v = np.asarray(u.combinations[1]["direction"])
    assert v == pytest.approx([math.sqrt(0.5), math.sqrt(0.5)], abs=1e-9)
    assert u.combinations[1]["terms"] == {"lg a": 0.707, "lg b": 0.707}


class _Bent(_Flat):
    """Exactly flat along (1, 1) too, but across it the slope falls away from the answer
    (``30 / (1 + 10 |p|)``, ``p`` the distance along): the answer's Jacobian overstates
    it, and each chord step corrects only part of the offset, as a common scale with an
    offset that must follow it did on Mass_Damper (rises 5.1, 0.03, 0 after 3, 4, 5)."""

    def residuals(self, s: np.ndarray) -> np.ndarray:
        d = s - self.space.to_s({"a": 3.0, "b": 3.0})
        along, across = (d[0] + d[1]) / math.sqrt(2), (d[0] - d[1]) / math.sqrt(2)
        return 30.0 * WEIGHTS * across / (1 + 10 * abs(along)) * math.sqrt(2)


def test_a_probe_refits_until_the_cost_stops_falling():
    space, x, _, jac, u = _case(curved=0.0)
    ev = _Bent(space, 0.0)
    tilt = math.radians(10.0)
    u.combinations[1]["direction"] = [math.cos(math.pi / 4 + tilt), math.sin(math.pi / 4 + tilt)]
    jac = jac[: WEIGHTS.size]
    probe_combinations(ev, space, u, x, 0.0, 4.0, jac)
    assert u.combinations[1]["determined"] is False
    assert u.intervals == {"a": [None, None], "b": [None, None]}
    assert ev.calls <= 2 * probe.REFITS + 1


def test_a_chord_far_from_the_direction_does_not_replace_it():
    """A probe clipped at a bound gives a chord far off the valley: the differences'
    direction is kept (only a tilt of up to about 25 degrees is corrected)."""
    space, _, _, _, _ = _case(curved=0.0)
    v = np.array([math.sqrt(0.5), math.sqrt(0.5)])
    c = {"direction": list(v), "terms": {"lg a": 0.707, "lg b": 0.707}}
    probe._along(space, c, [{"a": 30.0, "b": 3.0}, {"a": 3.0, "b": 3.0}], v)  # 45 degrees
    assert c["direction"] == list(v)
    probe._along(space, c, [{"a": 30.0, "b": 25.0}, {"a": 3.0, "b": 3.0}], v)  # 2 degrees
    assert c["direction"] != list(v) and c["direction"][0] > c["direction"][1]
