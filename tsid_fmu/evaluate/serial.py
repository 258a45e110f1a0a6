"""Evaluate parameter sets in this process (temporary minimal version; see branch h4)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from tsid_fmu.fmu import FMUSession
from tsid_fmu.errors import FMUError, SimulationError, TsidError
from tsid_fmu.evaluate.cost import Cost
from tsid_fmu.evaluate.protocol import Evaluation, Simulated
from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = ["SerialEvaluator"]


class SerialEvaluator:
    """Score parameter sets with one FMU session per experiment, in this process."""

    def __init__(self, spec: EvaluationSpec) -> None:
        self.spec = spec
        self._nfev = 0
        self._cache: dict[tuple, tuple[np.ndarray, str | None, np.ndarray | None]] = {}
        self._known: set[tuple] = set()
        self.sessions: list[FMUSession] = []
        self.cost = Cost(spec.cost)
        try:
            for e in spec.experiments:
                self.sessions.append(
                    FMUSession(
                        spec.fmu,
                        inputs=list(e.input_names),
                        outputs=list(e.output_names),
                        parameters=list(spec.parameter_names),
                        interface=spec.interface,
                        step_size=spec.step_size,
                        start_values={**spec.start_values, **e.start_values},
                    )
                )
        except BaseException:
            self.close()
            raise

    @property
    def nfev(self) -> int:
        return self._nfev

    @property
    def n_replicates(self) -> int:
        return self.spec.n_replicates

    def _one(self, params: Mapping[str, float]) -> tuple[np.ndarray, str | None, np.ndarray | None]:
        key = tuple(float(params[n]) for n in self.spec.parameter_names)
        if key in self._cache:
            return self._cache[key]
        counted = self._nfev
        costs = np.zeros(self.n_replicates)
        error, parts = None, []
        for exp, session in zip(self.spec.experiments, self.sessions, strict=True):
            runs = [exp.inputs, *exp.noisy_inputs]
            for r in range(self.n_replicates):
                u = runs[min(r, len(runs) - 1)]
                self._nfev += 1
                try:
                    y = session.simulate(exp.time, u, params)
                except (SimulationError, FMUError) as exc:
                    error = f"{exp.name}: {exc}"
                    break
                value = float(np.dot(self.cost.per_output(exp.time, exp.measured, y), exp.weights))
                costs[r] += value if math.isfinite(value) else math.inf
                if r == 0:
                    parts.append(((y - exp.measured) / exp.scale).ravel())
            if error:
                break
        result = (
            (np.full(self.n_replicates, math.inf), error, None)
            if error
            else (costs, None, np.concatenate(parts) if np.all(np.isfinite(costs)) else None)
        )
        self._cache[key] = result
        if key in self._known:
            self._nfev = counted
        return result

    def mark_known(self, parameter_sets: Sequence[Mapping[str, float]]) -> None:
        """Parameter sets an interrupted run simulated already: not counted again."""
        self._known.update(
            tuple(float(p[n]) for n in self.spec.parameter_names) for p in parameter_sets
        )

    def evaluate(
        self,
        parameter_sets: Sequence[Mapping[str, float]],
        progress: Callable[[int, int], None] | None = None,
    ) -> Evaluation:
        before = self._nfev
        rows = []
        for i, p in enumerate(parameter_sets):
            rows.append(self._one(p))
            if progress:
                progress(i + 1, len(parameter_sets))
        costs = np.array([r[0] for r in rows]).reshape(len(rows), self.n_replicates)
        return Evaluation(costs, [r[1] for r in rows], self._nfev - before, [r[2] for r in rows])

    def simulate(
        self, parameter_sets: Sequence[Mapping[str, float]], *, count: bool = True
    ) -> list[list[Simulated]]:
        out = []
        for p in parameter_sets:
            row = []
            for exp, session in zip(self.spec.experiments, self.sessions, strict=True):
                self._nfev += int(count)
                try:
                    row.append(Simulated(exp.name, session.simulate(exp.time, exp.inputs, p), None))
                except TsidError as exc:
                    row.append(Simulated(exp.name, None, str(exc)))
            out.append(row)
        return out

    def close(self) -> None:
        for s in self.sessions:
            try:
                s.close()
            except TsidError:
                pass
        self.sessions = []

    def __enter__(self) -> SerialEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
