"""Does the FMU reproduce its runs? A probe of reset and determinism, once per FMU file.

tsid simulates one FMU instance many times and resets it between runs; FMPy's
``simulate_fmu`` instantiates afresh for every run, so its users never meet an FMU whose
reset is broken. 20-sim 4.6's ``fmi2Reset`` keeps the clock where the last run left it:
every later ``fmi2DoStep`` does nothing, the outputs stay at the initial state, and a
study "converges" at the start values. :func:`probe` simulates the first experiment at
one parameter set (the study's start point) on the evaluators' own code path
(:class:`~tsid_fmu.evaluate.runner.SetRunner`):

1. on a fresh instance, then on the same instance after reset: the same outputs (to
   :data:`TOLERANCE` of each output's range) mean reset works and the runs repeat --
   two simulations, the price for a conforming FMU;
2. otherwise on a new session whose instance is made afresh for every run, twice: the
   same outputs as the first run mean the reset is broken and fresh instances work
   (``fresh``: the study instantiates afresh for every run); different ones mean the
   FMU does not reproduce its runs at all (``deterministic`` False: its costs are not
   reproducible and no verdict can be earned).

The verdict is kept in memory per process, by the FMU file's SHA-256 and the interface
(:func:`cached`, :func:`remember`); the study writes it to ``result.json``
(``result.conformance``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from tsid_fmu.errors import SimulationError, TsidError
from tsid_fmu.evaluate.runner import SetRunner
from tsid_fmu.evaluate.spec import EvaluationSpec

__all__ = [
    "DEFAULT_SAMPLES",
    "TOLERANCE",
    "cached",
    "fmu_digest",
    "info_line",
    "judge",
    "probe",
    "probe_defaults",
    "problem",
    "remember",
    "warnings",
]

TOLERANCE = 1e-9
"""Largest difference of two runs that still counts as the same, relative to each
output's range over the first run (exactly equal is typical)."""

DEFAULT_SAMPLES = 101
"""Samples of a probe at an FMU's defaults (:func:`probe_defaults`)."""

_lock = threading.Lock()
_verdicts: dict[tuple[str, str], dict[str, Any]] = {}
_digests: dict[tuple[str, int, int], str] = {}


def fmu_digest(path: Path) -> str:
    """Return the SHA-256 of the FMU file (of its model description for a folder)."""
    path = Path(path)
    file = path / "modelDescription.xml" if path.is_dir() else path
    st = file.stat()
    key = (str(file.resolve()), st.st_size, st.st_mtime_ns)
    with _lock:
        if key in _digests:
            return _digests[key]
    h = hashlib.sha256()
    with open(file, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    with _lock:
        _digests[key] = h.hexdigest()
    return _digests[key]


def cached(digest: str, interface: str) -> dict[str, Any] | None:
    """Return the verdict of an FMU file already probed in this process (a copy), or None."""
    with _lock:
        found = _verdicts.get((digest, interface))
    return None if found is None else dict(found)


def remember(record: dict[str, Any]) -> None:
    """Keep a verdict for the FMU file and interface it names (not one that was not probed)."""
    if record.get("probed"):
        with _lock:
            _verdicts[(record["sha256"], record["interface"])] = dict(record)


def _outputs(runner: SetRunner, params: Mapping[str, float]) -> np.ndarray:
    if runner.reuse is not None:  # per-experiment copies: simulate again, never reuse
        runner.reuse.clear()
    sim = runner.simulate(params).simulated[0]
    if sim.outputs is None:
        raise SimulationError(str(sim.error))
    return np.array(sim.outputs, dtype=float)


def _difference(a: np.ndarray, b: np.ndarray) -> float:
    """Return the largest difference of two runs relative to each output's range (0: same)."""
    if a.shape != b.shape:
        return float("inf")
    if np.array_equal(a, b, equal_nan=True):
        return 0.0
    scale = np.ptp(a, axis=0) if a.shape[0] else np.ones(a.shape[1])
    scale = np.where(scale > 0, scale, np.max(np.abs(a), axis=0, initial=0.0))
    scale = np.where(scale > 0, scale, 1.0)
    diff = np.abs(a - b) / scale
    return float(np.nanmax(np.where(np.isnan(diff), np.inf, diff)))


def _finite(value: float) -> float | None:
    """Return ``value`` for ``result.json`` (None for an infinite or NaN difference)."""
    return value if np.isfinite(value) else None


def _runs(spec: EvaluationSpec, params: Mapping[str, float], fresh: bool) -> list[np.ndarray]:
    runner = SetRunner(dataclasses.replace(spec, fresh=fresh))
    try:
        return [_outputs(runner, params), _outputs(runner, params)]
    finally:
        runner.close()


def probe(spec: EvaluationSpec, params: Mapping[str, float]) -> dict[str, Any]:
    """Probe reset and determinism of ``spec``'s FMU on its first experiment at ``params``.

    Parameters
    ----------
    spec : EvaluationSpec
        The evaluation (only its first experiment is simulated, on its measured inputs).
    params : mapping of str to float
        The parameter set (the study's start point).

    Returns
    -------
    dict
        ``probed`` (False where a simulation failed: ``reason`` says why), ``sha256``,
        ``interface``, ``reset`` (a reset instance reproduces a fresh one),
        ``deterministic`` (fresh instances reproduce each other), ``fresh`` (runs need a
        fresh instance each), ``difference`` (largest relative difference seen),
        ``simulations`` and ``message``.
    """
    one = dataclasses.replace(spec, experiments=spec.experiments[:1], fresh=False)
    return judge(spec.fmu, spec.interface, lambda fresh: _runs(one, params, fresh))


def probe_defaults(path: Path, interface: str = "auto") -> dict[str, Any]:
    """Probe an FMU without inputs at its own start values (for ``tsid info``).

    Its Real outputs over its default experiment (0 to 1 s where it declares none), at
    :data:`DEFAULT_SAMPLES` samples; see :func:`probe` for the record.
    """
    from tsid_fmu.fmu import FMUSession

    def runs(fresh: bool) -> list[np.ndarray]:
        with FMUSession(path, [], _outputs_of(path), interface=interface, fresh=fresh) as s:
            de = s.model_description.defaultExperiment
            t0 = float(getattr(de, "startTime", None) or 0.0)
            t1 = float(getattr(de, "stopTime", None) or t0 + 1.0)
            t = np.linspace(t0, t1, DEFAULT_SAMPLES)
            return [s.simulate(t, None, {}), s.simulate(t, None, {})]

    return judge(Path(path), interface, runs)


INFO_LIMIT = 60.0
"""Seconds ``tsid info --probe`` gives its probe (in a child process)."""


def info_line(path: Path, run: bool) -> str:
    """Return ``tsid info``'s conformance line: the probe at the FMU's defaults (``run``).

    An FMU with inputs needs data to be run: it is "not probed" here, and ``tsid
    identify`` probes it on the study's first experiment.
    """
    from tsid_fmu.evaluate.isolated import IsolatedCalls
    from tsid_fmu.fmu.info import read_fmu_description

    head = "Conformance      "
    md = read_fmu_description(Path(path))
    if any(v.causality == "input" for v in md.modelVariables):
        return head + "not probed: the FMU has inputs (tsid identify probes it on the data)"
    if not run:
        return head + "not probed (--probe: reset and determinism at the FMU's defaults)"
    calls = IsolatedCalls(INFO_LIMIT, Path(path).name)
    try:
        record = calls.call(probe_defaults, Path(path))
    except SimulationError as exc:
        return head + f"not probed: {exc}"
    finally:
        calls.close()
    return head + str(record["message"])


def _outputs_of(path: Path) -> list[str]:
    from tsid_fmu.fmu.info import read_fmu_description
    from tsid_fmu.fmu.variables import REAL_TYPES

    md = read_fmu_description(Path(path))
    return [v.name for v in md.modelVariables if v.causality == "output" and v.type in REAL_TYPES]


def judge(fmu: Path, interface: str, runs: Callable[[bool], list[np.ndarray]]) -> dict[str, Any]:
    """Return the probe's record from ``runs(fresh)``: two runs on one session each.

    ``runs(False)``: a fresh instance, then the same instance reset; ``runs(True)``
    (only where those differ): a new session with a fresh instance for each run.
    """
    record: dict[str, Any] = {
        "probed": False,
        "sha256": fmu_digest(fmu),
        "interface": interface,
        "simulations": 0,
    }
    try:
        first, again = runs(False)
        record["simulations"] = 2
        reset = _difference(first, again)
        record.update(probed=True, reset=reset <= TOLERANCE, difference=_finite(reset))
        if record["reset"]:
            record.update(deterministic=True, fresh=False)
            record["message"] = "a reset instance reproduces a fresh one (2 simulations)"
            return record
        fresh = runs(True)
        record["simulations"] = 4
    except TsidError as exc:
        record.update(probed=False, reason=f"a probe simulation failed: {exc}")
        record["message"] = f"not probed: {record['reason']}"
        return record
    worst = max(_difference(first, y) for y in fresh)
    record.update(deterministic=worst <= TOLERANCE, fresh=worst <= TOLERANCE)
    if record["deterministic"]:
        record["message"] = (
            f"the FMU's reset is broken (a run after reset differs from a fresh one by "
            f"{reset:.3g} of the output range); every run gets a fresh instance"
        )
    else:
        record["difference"] = _finite(max(reset, worst))
        record["message"] = (
            f"two identical runs on fresh instances differ by {worst:.3g} of the output "
            "range: the FMU is not deterministic, its costs are not reproducible"
        )
    return record


def problem(record: Mapping[str, Any] | None) -> str | None:
    """Return why the study cannot earn a verdict on this FMU, or None (it can)."""
    if record and record.get("probed") and record.get("deterministic") is False:
        return "its runs differ from each other"
    return None


def warnings(record: Mapping[str, Any] | None) -> list[str]:
    """Return the warnings of a probe: a broken reset, a non-deterministic FMU, no probe."""
    if not record:
        return []
    if not record.get("probed") or record.get("fresh") or record.get("deterministic") is False:
        return [f"FMU conformance: {record.get('message', '')}"]
    return []
