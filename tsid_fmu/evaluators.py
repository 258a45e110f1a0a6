"""One evaluator per sub-problem of a study: its parameters, experiments and fixed values.

:func:`tsid_fmu.identify.identify` makes one :class:`StudyEvaluators` per study (and
structure identification one per candidate structure, :mod:`tsid_fmu.search.structure.compare`);
the stages ask it for the evaluator of each sub-problem, shared between them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from tsid_fmu.evaluate.factory import check_runner, in_process, make_evaluator
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.evaluate.timelimit import TimeLimit
from tsid_fmu.study.definition import Study
from tsid_fmu.study.prepare import prepare

__all__ = ["StudyEvaluators"]


class StudyEvaluators:
    """One evaluator per sub-problem (parameters, experiments, fixed values), shared."""

    def __init__(self, study: Study, runner: dict[str, Any], given: Evaluator | None) -> None:
        workers, timeout = check_runner(runner.get("workers"), runner.get("timeout"))
        runner = {**runner, "workers": workers, "timeout": timeout}
        self.study, self.runner, self.given = study, runner, given
        self.pool: dict[tuple, Evaluator] = {}
        self.specs: dict[tuple, EvaluationSpec] = {}
        self.interface: str | None = None  # chosen by the fidelity check
        self.cs_tolerance: float | None = None  # adopted by the fidelity check
        self.fresh = False  # a fresh instance for every run (the FMU's reset is broken)
        self.conformance: dict[str, Any] | None = None  # the FMU probe's verdict
        self.children: list[StudyEvaluators] = []  # those of a study's candidate structures

    def use(self, interface: str) -> None:
        """Simulate every sub-problem with ``interface`` from now on."""
        self.interface = interface
        self.specs = {k: dataclasses.replace(s, interface=interface) for k, s in self.specs.items()}

    def use_cs_tolerance(self, tolerance: float | None) -> None:
        """Pass ``tolerance`` to the FMU's own Co-Simulation solver from now on (None: keep)."""
        if tolerance is None:
            return
        self.cs_tolerance = tolerance
        self.specs = {
            k: dataclasses.replace(s, cs_tolerance=tolerance) for k, s in self.specs.items()
        }

    def use_fresh(self) -> None:
        """Instantiate afresh for every run from now on (:mod:`tsid_fmu.conformance`)."""
        self.fresh = True
        self.specs = {k: dataclasses.replace(s, fresh=True) for k, s in self.specs.items()}

    def _key(
        self, params: list[str], exps: list[str], fixed: Mapping[str, float], fraction: float = 1.0
    ) -> tuple:
        return (tuple(params), tuple(exps), tuple(sorted(fixed.items())), fraction)

    def spec(
        self, params: list[str], exps: list[str], fixed: Mapping[str, float]
    ) -> EvaluationSpec:
        """Return the spec of a sub-problem: ``fixed`` values set, the others not.

        A fixed copy of a per-experiment parameter sets its variable in its own
        experiment only (the arrays hold the copies so, :mod:`tsid_fmu.study.copies`).
        """
        key = self._key(params, exps, fixed)
        if key not in self.specs:
            base = prepare(self.study, exps, params)
            held = {k: v for k, v in fixed.items() if k not in params}
            copies = {c.name: c for c in self.study.copies if c.name in held}
            start = {**base.start_values, **{k: v for k, v in held.items() if k not in copies}}

            def own(experiment: str) -> dict[str, float]:
                return {
                    c.variable: held[n] for n, c in copies.items() if c.experiment == experiment
                }

            experiments = tuple(
                dataclasses.replace(e, start_values={**e.start_values, **own(e.name)})
                for e in base.experiments
            )
            self.specs[key] = dataclasses.replace(
                base,
                start_values=start,
                experiments=experiments,
                interface=self.interface or base.interface,
                cs_tolerance=self.cs_tolerance or base.cs_tolerance,
                fresh=self.fresh,
            )
        return self.specs[key]

    def key(self, study: Study, exps: list[str]) -> tuple:
        """Return the key of the evaluator of every parameter on ``exps``."""
        return self._key(study.parameter_names, exps, {})

    def check_limit(self, ev: Evaluator | None) -> dict[str, Any]:
        """How a check outside the evaluators simulates: isolated, under which limit.

        In a child process under the study's time limit per simulation (``ev``'s, once
        it has one; else the limit before any simulation), unless the study runs in
        this process (one worker with ``timeout=0``).
        """
        if in_process(self.runner["workers"], self.runner["timeout"], self.runner["scheduler"]):
            return {"isolate": False, "time_limit": None}
        limit = getattr(ev, "time_limit", None) if ev is not None else None
        if limit is None:
            limit = TimeLimit(self.runner["timeout"]).seconds()
        return {"isolate": True, "time_limit": limit}

    def get(self, params: list[str], exps: list[str], fixed: Mapping[str, float]) -> Evaluator:
        """Return the (shared) evaluator of a sub-problem, or the one given to the study."""
        if self.given is not None:
            return self.given
        key = self._key(params, exps, fixed)
        if key not in self.pool:
            self.pool[key] = make_evaluator(self.spec(params, exps, fixed), **self.runner)
        return self.pool[key]

    def shortened(self, params: list[str], exps: list[str], fraction: float) -> Evaluator | None:
        """Return an evaluator of the first ``fraction`` of each experiment's samples.

        None where the study was given an evaluator (it cannot be shortened).
        """
        if self.given is not None:
            return None
        key = self._key(params, exps, {}, fraction)
        if key not in self.pool:
            spec = self.spec(params, exps, {}).head(fraction)
            self.pool[key] = make_evaluator(spec, **self.runner)
        return self.pool[key]

    def retried(self) -> list[str]:
        """Return one warning for the sets that crashed a worker, then passed in a fresh one."""
        notes = [n for ev in self.pool.values() for n in getattr(ev, "retried", [])]
        if not notes:
            return []
        return [
            f"{len(notes)} parameter set(s) crashed their worker process and succeeded when "
            f"run again in a fresh one (the FMU crashes now and then); first: {notes[0]}"
        ]

    @property
    def nfev(self) -> int:
        """Simulations run so far by the evaluators of the study."""
        if self.given is not None:
            return int(self.given.nfev)
        own = sum(int(ev.nfev) for ev in self.pool.values())
        return own + sum(child.nfev for child in self.children)

    def rounds(self, workers: int) -> int | None:
        """Return the rounds of parallel simulation so far on ``workers`` workers.

        See :meth:`~tsid_fmu.evaluate.memo.MemoEvaluator.rounds`; None for an evaluator
        given to the study that does not count them.
        """
        pool = [self.given] if self.given is not None else list(self.pool.values())
        if not all(hasattr(ev, "rounds") for ev in pool):
            return None
        own = sum(int(ev.rounds(workers)) for ev in pool)
        children = [child.rounds(workers) for child in self.children]
        return None if None in children else own + sum(c or 0 for c in children)

    def close(self) -> None:
        """Close every evaluator made (and those of the candidate structures)."""
        for child in self.children:
            child.close()
        for ev in self.pool.values():
            ev.close()
        self.pool.clear()
