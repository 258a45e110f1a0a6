"""The evaluation layer's contract: replicate 1 on the measured inputs, residuals, the memo,
counters that do not depend on the number of workers, and the automatic time limit."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest
from spec_helpers import experiment, lag_frame, make_spec

from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate import (
    Cost,
    Evaluator,
    PoolEvaluator,
    PreparedExperiment,
    SerialEvaluator,
    TimeLimit,
    make_evaluator,
)
from tsid_fmu.evaluate import timelimit as timelimit_module
from tsid_fmu.fmu import FMUSession


def _frame(seed: int) -> pd.DataFrame:
    return lag_frame(seed, 401, omega=12, step_at=0.2, window=30)


@pytest.fixture(scope="module")
def spec(lag_crash_fmus):
    """Experiment "a" with two noisy replicates, "b" without noise (R = 3 for both)."""
    return make_spec(
        lag_crash_fmus["lag"],
        ["tau", "x0"],
        [
            experiment(
                _frame(1),
                {"u": "u"},
                {"y": "y"},
                name="a",
                replicates=3,
                input_noise=0.02,
                seed=4,
                scale=[0.01],
            ),
            experiment(
                _frame(2), {"u": "u"}, {"y": "y2"}, name="b", index=1, weights=[2.0], scale=[0.02]
            ),
        ],
        cost="sse",
    )


GOOD = {"tau": 0.03, "x0": 0.1}


def test_replicate_one_is_the_measured_input_and_residuals_are_scaled(spec):
    with SerialEvaluator(spec) as ev:
        assert isinstance(ev, Evaluator) and ev.n_replicates == 3
        got = ev.evaluate([GOOD])
    cost = Cost("sse")
    column0, residuals = 0.0, []
    noisy = 0.0
    for e in spec.experiments:
        with FMUSession(spec.fmu, e.input_names, e.output_names, parameters=["tau", "x0"]) as s:
            y = s.simulate(e.time, e.inputs, GOOD)
            y_noisy = s.simulate(e.time, e.replicate_inputs(1), GOOD)
        column0 += float(np.dot(cost.per_output(e.time, e.measured, y), e.weights))
        noisy += float(np.dot(cost.per_output(e.time, e.measured, y_noisy), e.weights))
        residuals.append(((y - e.measured) / e.scale).ravel())
    assert got.costs.shape == (1, 3)
    assert got.costs[0, 0] == column0  # bit for bit: the same sums in the same order
    assert got.costs[0, 1] == noisy and got.costs[0, 1] != got.costs[0, 0]
    r = got.residuals[0]
    assert r.dtype == np.float64 and not r.flags.writeable
    np.testing.assert_array_equal(r, np.concatenate(residuals))
    # "b" has no noisy inputs: its replicates 2 and 3 are its measured input, run once
    assert got.nfev == 3 + 1
    assert spec.n_simulations == 4


def test_a_failed_set_has_no_residuals_and_names_the_experiment(spec):
    with SerialEvaluator(spec) as ev:
        got = ev.evaluate([{"tau": -1.0, "x0": 0.0}, GOOD])
    assert np.all(np.isinf(got.costs[0])) and got.residuals[0] is None
    assert got.errors[0].startswith("a: ") and "tau must be positive" in got.errors[0]
    assert got.errors[1] is None and got.residuals[1] is not None
    assert got.nfev == 1 + 4  # a failed set stops at its first failure


def test_no_parameter_set_is_simulated_twice(spec):
    seen = []
    other = {"tau": 0.04, "x0": 0.0}
    with SerialEvaluator(spec, residual_cache=2) as ev:
        first = ev.evaluate([GOOD, other, dict(GOOD)], progress=lambda d, t: seen.append((d, t)))
        assert first.nfev == 2 * 4  # the duplicate in the batch ran once
        assert seen == [(1, 3), (2, 3), (3, 3)]
        np.testing.assert_array_equal(first.costs[0], first.costs[2])
        assert first.residuals[0] is first.residuals[2]
        again = ev.evaluate([other, GOOD])
        assert again.nfev == 0 and ev.nfev == 8
        np.testing.assert_array_equal(again.costs, first.costs[[1, 0]])
        # residuals are kept for 2 sets, least recently used out first: a new set pushes
        # out `other` (GOOD was used last), `other` then pushes out GOOD; each comes back
        # by running its measured inputs once more (2 simulations), costs from the memo
        ev.evaluate([{"tau": 0.06, "x0": 0.0}])
        assert ev.evaluate([other]).nfev == 2
        back = ev.evaluate([{"x0": 0.1, "tau": 0.03}])  # any order of names, same key
        assert back.nfev == 2 and ev.nfev == 8 + 4 + 2 + 2
        np.testing.assert_array_equal(back.residuals[0], first.residuals[0])
        np.testing.assert_array_equal(back.costs[0], first.costs[0])
        with pytest.raises(AttributeError):
            ev.nfev = 0  # read-only from outside


def test_simulate_counts_only_when_asked_and_never_twice(spec):
    with SerialEvaluator(spec) as ev:
        plot = ev.simulate([GOOD], count=False)
        assert ev.nfev == 0
        fit = ev.simulate([GOOD, GOOD])
        assert ev.nfev == 0  # the outputs of the plot are reused
        new = ev.simulate([{"tau": 0.02, "x0": 0.0}])
        assert ev.nfev == 2
        cost = ev.evaluate([GOOD])
    assert [s.experiment for s in plot[0]] == ["a", "b"]
    assert fit[0][0].outputs is plot[0][0].outputs and fit[1][1].outputs is plot[0][1].outputs
    assert new[0][0].error is None and not new[0][0].outputs.flags.writeable
    residual_a = (plot[0][0].outputs - spec.experiments[0].measured) / 0.01
    np.testing.assert_array_equal(cost.residuals[0][: residual_a.size], residual_a.ravel())


def test_parameter_sets_must_name_every_parameter(spec):
    with SerialEvaluator(spec) as ev:
        with pytest.raises(StudyError, match="no value for 'x0'"):
            ev.evaluate([{"tau": 0.1}])
        with pytest.raises(StudyError, match=r"unknown parameter 'k'.*tau, x0"):
            ev.evaluate([{"tau": 0.1, "x0": 0.0, "k": 1.0}])
        assert ev.nfev == 0


def test_spec_checks_its_arrays(spec):
    a = spec.experiments[0]
    with pytest.raises(StudyError, match="'a': scale must be 1 finite values > 0"):
        dataclasses.replace(a, scale=np.zeros(1))
    with pytest.raises(StudyError, match=r"'a': measured must have shape \(401, 1\)"):
        dataclasses.replace(a, measured=np.zeros((400, 1)))
    with pytest.raises(StudyError, match=r"noisy_inputs\[0\] has shape"):
        dataclasses.replace(a, noisy_inputs=(np.zeros((3, 1)),))
    with pytest.raises(StudyError, match="experiment names must be unique: a"):
        dataclasses.replace(spec, experiments=(a, a))
    with pytest.raises(StudyError, match="unknown cost 'mae'"):
        dataclasses.replace(spec, cost="mae")
    assert isinstance(a, PreparedExperiment) and not a.time.flags.writeable
    assert spec.n_replicates == 3 and a.replicate_plan(3) == (0, 1, 2)
    assert spec.experiments[1].replicate_plan(3) == (0, 0, 0)


# batches as a study sends them: new sets, a duplicate, a failing set, repeats, and sets
# seen before together with new ones
BATCHES = [
    [{"tau": t, "x0": x} for t in (0.01, 0.03, 0.1) for x in (-0.5, 0.0, 0.5)],
    [{"tau": 0.02, "x0": 0.1}, {"tau": -1.0, "x0": 0.0}, {"tau": 0.02, "x0": 0.1}],
    [{"tau": 0.03, "x0": 0.0}, {"tau": 0.05, "x0": 0.2}, {"tau": -1.0, "x0": 0.0}],
]


def _run_batches(ev):
    out = [ev.evaluate(b) for b in BATCHES]
    sims = ev.simulate([BATCHES[2][1], BATCHES[0][0]])
    return out, sims, ev.nfev


@pytest.fixture(scope="module")
def serial_batches(spec):
    with SerialEvaluator(spec) as ev:
        return _run_batches(ev)


def _assert_same(got, expected):
    (got, sims, nfev), (expected, expected_sims, expected_nfev) = got, expected
    assert nfev == expected_nfev
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_array_equal(g.costs, e.costs)
        assert g.errors == e.errors and g.nfev == e.nfev
        for a, b in zip(g.residuals, e.residuals, strict=True):
            assert (a is None and b is None) or np.array_equal(a, b)
    for s_got, s_exp in zip(sims, expected_sims, strict=True):
        for a, b in zip(s_got, s_exp, strict=True):
            assert a.experiment == b.experiment and a.error == b.error
            np.testing.assert_array_equal(a.outputs, b.outputs)


@pytest.mark.slow
def test_results_and_counters_do_not_depend_on_the_number_of_workers(spec, serial_batches):
    expected, _, expected_nfev = serial_batches
    assert [e.nfev for e in expected] == [9 * 4, 4 + 1, 4]
    assert expected_nfev == 9 * 4 + 5 + 4 + 4
    for workers, start in ((1, None), (2, "spawn"), (3, None)):
        with PoolEvaluator(spec, workers=workers, start_method=start) as ev:
            _assert_same(_run_batches(ev), serial_batches)


def test_an_interrupted_batch_leaves_the_pool_usable(spec, serial_batches):
    class Interrupt(Exception):
        pass

    def progress(done, total):
        if done == 2:
            raise Interrupt  # as Ctrl-C would, while other sets are running

    with PoolEvaluator(spec, workers=2) as ev:
        with pytest.raises(Interrupt):
            ev.evaluate(BATCHES[0], progress=progress)
        assert ev.nfev == 2 * 4  # the two sets finished are kept, and only they count
        got = ev.evaluate(BATCHES[0])
        assert got.nfev == 7 * 4 and ev.nfev == 9 * 4
    expected = serial_batches[0][0]
    np.testing.assert_array_equal(got.costs, expected.costs)
    for a, b in zip(got.residuals, expected.residuals, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_worker_killed_between_batches_fails_no_set(spec, serial_batches):
    import os
    import signal

    with PoolEvaluator(spec, workers=2) as ev:
        ev.evaluate(BATCHES[0][:2])
        for w in ev._pool.workers:  # e.g. the kernel's out-of-memory killer, while idle
            os.kill(w.process.pid, signal.SIGKILL)
            w.process.join(5)
        got = ev.evaluate(BATCHES[0][2:])
        assert got.errors == [None] * 7 and got.nfev == 7 * 4
    np.testing.assert_array_equal(got.costs, serial_batches[0][0].costs[2:])


@pytest.mark.slow
def test_dask_gives_the_same_results_and_counters(spec, serial_batches):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        with make_evaluator(spec, scheduler=cluster.scheduler_address) as ev:
            _assert_same(_run_batches(ev), serial_batches)


def test_time_limit_rule():
    auto = TimeLimit(None)
    assert auto.auto and auto.seconds() == timelimit_module.AUTO_FIRST_S
    auto.end_batch()  # nothing seen yet: stays open for the next batch
    auto.observe([0.01, 0.02, 0.5])
    assert auto.seconds() == 5.0  # 20 x 0.02 s is below the floor of 5 s
    auto.observe([1.0] * 4)
    assert auto.seconds() == 20.0  # 20 x the median (1 s)
    auto.end_batch()
    auto.observe([100.0] * 10)  # fixed after the first batch
    assert auto.seconds() == 20.0
    assert "time limit of 20 s per simulation exceeded (automatic" in auto.exceeded()
    assert TimeLimit(0).seconds() is None and TimeLimit(2.5).seconds() == 2.5
    for bad in (-1, math.nan, "x"):
        with pytest.raises(StudyError, match="timeout must be None"):
            TimeLimit(bad)


@pytest.mark.slow
def test_worker_processes_stop_a_hanging_fmu_by_default(lag_crash_fmus, monkeypatch):
    crash_spec = make_spec(
        lag_crash_fmus["crash"],
        ["gain"],
        [experiment(_frame(3), {"u": "u"}, {"y": "y"})],
        start_values={"hang_above": 30.0},
    )
    monkeypatch.setattr(timelimit_module, "AUTO_MIN_S", 0.5)  # the floor, for a short test
    sets = [{"gain": 1.0 + 0.1 * k} for k in range(4)] + [{"gain": 35.0}]
    with make_evaluator(crash_spec, workers=2) as ev:
        assert isinstance(ev, PoolEvaluator) and ev.time_limit == 300.0
        got = ev.evaluate(sets)
        assert ev.time_limit == 0.5
        after = ev.evaluate([{"gain": 2.0}])
    assert "time limit of 0.5 s per simulation exceeded (automatic" in got.errors[4]
    assert got.errors[:4] == [None] * 4 and np.all(np.isfinite(got.costs[:4]))
    assert got.nfev == 5 and after.errors == [None]
    with PoolEvaluator(crash_spec, workers=1, timeout=0) as ev:
        assert ev.time_limit is None


def test_evaluate_is_a_lower_layer_without_import_cycles():
    """evaluate/ imports only errors, the FMU layer and itself (function bodies included),
    and its modules import one another without a cycle."""
    import ast
    from pathlib import Path

    import tsid_fmu.evaluate

    folder = Path(tsid_fmu.evaluate.__file__).parent
    allowed = ("tsid_fmu.errors", "tsid_fmu.driver", "tsid_fmu.fastloop", "tsid_fmu.fmu")
    graph: dict[str, set[str]] = {}
    for path in sorted(folder.glob("*.py")):
        name = f"tsid_fmu.evaluate.{path.stem}".removesuffix(".__init__")
        tree = ast.parse(path.read_text())
        found = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        found |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        ours = {m for m in found if m.split(".")[0] == "tsid_fmu"}
        outside = {m for m in ours if not m.startswith("tsid_fmu.evaluate")}
        assert all(m.startswith(allowed) for m in outside), (name, outside)
        graph[name] = {m for m in ours if m.startswith("tsid_fmu.evaluate.")}
        assert sum(1 for _ in path.open()) <= 500, path.name

    def visit(node: str, stack: tuple[str, ...]) -> None:
        assert node not in stack, " -> ".join((*stack, node))
        for nxt in graph.get(node, ()):
            visit(nxt, (*stack, node))

    for node in graph:
        visit(node, ())


def test_rounds_count_each_batch_of_new_sets_once_per_round_of_workers(spec):
    """A batch of b new sets takes ceil(b / w) rounds on w workers; the memo's take none."""
    sets = [{"tau": 0.01 * (k + 1), "x0": 0.1} for k in range(5)]
    with SerialEvaluator(spec) as ev:
        ev.evaluate(sets)  # 5 new sets: one batch
        ev.evaluate(sets[:2])  # all in the memo: no round
        ev.evaluate([{"tau": 0.07, "x0": 0.1}])  # one new set
        assert ev.batches == [5, 1]
        assert [ev.rounds(w) for w in (1, 4, 16)] == [6, 2 + 1, 1 + 1]
