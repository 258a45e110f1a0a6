"""The study's FMU conformance probe: run it once per FMU file, act on it, report it.

:func:`check_conformance` runs :func:`~tsid_fmu.evaluate.conformance.probe` at the
study's start point on its first identification experiment, before the stages (in a
child process under the study's time limit where the study isolates its checks, so that
an FMU that crashes or hangs only leaves the probe undone). An FMU whose reset is broken
is then simulated on a fresh instance for every run; one that does not reproduce its
runs ends the study with exit status 1 (:data:`~tsid_fmu.status.Verdict.FMU`).
:func:`record_conformance` writes the verdict to the result's ``conformance`` and the
warnings.
"""

from __future__ import annotations

from typing import Any

from tsid_fmu.errors import SimulationError
from tsid_fmu.evaluate.conformance import cached, fmu_digest, probe, remember, warnings
from tsid_fmu.evaluate.isolated import IsolatedCalls
from tsid_fmu.evaluators import StudyEvaluators
from tsid_fmu.search.taguchi.iteration import ProgressCallback
from tsid_fmu.study.definition import Study
from tsid_fmu.uncertainty.fidelity import start_point

__all__ = ["PROBE_RUNS", "check_conformance", "record_conformance"]

PROBE_RUNS = 4
"""Most simulations of one probe (its time limit is this many times the study's)."""


def check_conformance(
    study: Study, evaluators: StudyEvaluators, callback: ProgressCallback | None
) -> dict[str, Any] | None:
    """Probe the study's FMU (or take this process's verdict on the same file); act on it.

    Returns the verdict (``None`` where the study was given its evaluator). A broken
    reset makes every later evaluator of the study instantiate afresh for every run.
    """
    if evaluators.given is not None:
        return None
    exps = study.identify_names()
    spec = evaluators.spec(study.parameter_names, exps, {})
    record = cached(fmu_digest(spec.fmu), spec.interface)
    if record is not None:
        record["cached"] = True
    else:
        record = _probe(study, evaluators, spec, exps)
        remember(record)
    evaluators.conformance = record
    if record.get("fresh"):
        evaluators.use_fresh()
    if callback and (warnings(record) or not record.get("cached")):
        callback("conformance", {"message": f"FMU conformance: {record['message']}"})
    return record


def _probe(study: Study, evaluators: StudyEvaluators, spec: Any, exps: list[str]) -> dict:
    limit = evaluators.check_limit(evaluators.pool.get(evaluators.key(study, exps)))
    x = start_point(study)
    if not limit["isolate"]:
        return probe(spec, x)
    seconds = limit["time_limit"]
    calls = IsolatedCalls(None if seconds is None else PROBE_RUNS * seconds, spec.fmu.name)
    try:
        return calls.call(probe, spec, x)
    except SimulationError as exc:  # the child crashed or hung: the study finds out itself
        return {
            "probed": False,
            "sha256": fmu_digest(spec.fmu),
            "interface": spec.interface,
            "simulations": 0,
            "reason": str(exc),
            "message": f"not probed: {exc}",
        }
    finally:
        calls.close()


def record_conformance(result: Any, record: dict[str, Any] | None) -> None:
    """Put the verdict into ``result.conformance`` and its warnings first."""
    if record is not None:
        result.conformance = record
        result.warnings[:0] = warnings(record)
