"""Identical runs are identical: the order rows finish in changes nothing (issue 49).

A study's simulations, ``nfev``, trail and result must not depend on how many workers
ran it or in which order their rows came back. The memo's caches are the one place
where that order could leak in: an LRU that took results as they finished dropped
other sets, which then ran again and counted.
"""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest
from spec_helpers import experiment, lag_frame, make_spec

import tsid_fmu.evaluate.serial as serial_module
from tsid_fmu import identify
from tsid_fmu.evaluate import SerialEvaluator

REPO = Path(__file__).resolve().parents[1]


class _Shuffled(SerialEvaluator):
    """A serial evaluator whose rows come back in a seeded random order."""

    def __init__(self, spec, *, seed: int, **kwargs) -> None:
        super().__init__(spec, **kwargs)
        self._rng = random.Random(seed)

    def _run_jobs(self, jobs, on_result) -> None:
        order = list(range(len(jobs)))
        self._rng.shuffle(order)
        for index in order:
            on_result(index, self._runner.run_job(jobs[index]))


@pytest.fixture(scope="module")
def spec(lag_crash_fmus):
    return make_spec(
        lag_crash_fmus["lag"],
        ["tau", "x0"],
        [experiment(lag_frame(1), {"u": "u"}, {"y": "y"}, name="a", index=0)],
        cost="sse",
    )


def _history(ev) -> tuple[list, list]:
    """Evaluate overlapping batches through a cache of 4 sets: the nfev of each call."""
    batches = [[{"tau": 0.01 * (i + j + 1), "x0": 0.0} for j in range(6)] for i in range(5)]
    counts = [ev.evaluate(batch).nfev for batch in batches]
    sims = [len(ev.simulate(batch[:3])) for batch in batches]
    counts += [ev.evaluate(batch[::-1]).nfev for batch in batches]
    return counts, sims


def test_the_finish_order_does_not_change_what_is_simulated(spec):
    with SerialEvaluator(spec, residual_cache=4) as ev:
        expected = _history(ev)
        nfev = ev.nfev
    for seed in range(5):
        with _Shuffled(spec, seed=seed, residual_cache=4) as ev:
            assert _history(ev) == expected, seed
            assert ev.nfev == nfev


def _result(out: Path) -> dict:
    data = json.loads((out / "result.json").read_text(encoding="utf-8"))
    data.pop("digest", None)
    return json.loads(json.dumps(data, sort_keys=True), parse_float=str, object_hook=_timeless)


def _timeless(obj: dict) -> dict:
    return {k: v for k, v in obj.items() if k != "seconds"}


@pytest.mark.slow
def test_the_siso_study_is_the_same_whatever_order_its_rows_finish_in(tmp_path, monkeypatch):
    study = REPO / "examples" / "lsea_siso" / "study.toml"
    plain = identify(study, tmp_path / "plain", plots=False, workers=1, timeout=0)
    real = serial_module.SerialEvaluator
    batches = []

    class Reversed(real):
        def _run_jobs(self, jobs, on_result) -> None:
            batches.append(len(jobs))
            for index in reversed(range(len(jobs))):
                on_result(index, self._runner.run_job(jobs[index]))

    monkeypatch.setattr(serial_module, "SerialEvaluator", Reversed)
    import tsid_fmu.evaluate.factory as factory

    monkeypatch.setattr(factory, "SerialEvaluator", Reversed, raising=False)
    flipped = identify(study, tmp_path / "flipped", plots=False, workers=1, timeout=0)
    assert sum(n > 1 for n in batches) > 10  # the arrays' rows did come back reversed
    assert flipped.nfev == plain.nfev
    assert flipped.x.tolist() == plain.x.tolist()
    assert _result(tmp_path / "flipped") == _result(tmp_path / "plain")
