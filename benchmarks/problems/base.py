"""What a benchmark problem is, and the helpers the problem modules share.

A :class:`Problem` is an identification task the way a lab would hand it over: an FMU,
measured data made by an *independent* simulator of the same equations (never by the
FMU itself), the mapping of columns to FMU inputs and outputs, the first parameter
levels, and -- unlike a real lab -- the truth and the true sensor noise, so that a
benchmark can score the answer.

Each problem module has a factory ``<name>(seed: int = 1) -> Problem`` (``seed`` seeds
the sensor noise only: the excitation is always the same) that builds the FMU into
:data:`CACHE` if needed, and a self-check (``python benchmarks/problems/<name>.py``).
The sample instants and the exact zero-order-hold solution are those of the examples'
data generators (``examples/_datagen.py``).

This module deliberately has no ``from __future__ import annotations``: its dataclasses
then work even when the module is loaded from a file path without being registered in
``sys.modules``.
"""

import hashlib
import importlib.util
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[2]
#: Where FMUs built on demand are kept (ignored by git).
CACHE = REPO / "benchmarks" / ".cache"


@dataclass
class ProblemExperiment:
    """One experiment: logged data and how its columns map onto the FMU.

    Attributes
    ----------
    name : str
        Experiment name.
    data : pandas.DataFrame
        The data as a lab would log them (a ``time`` column first).
    inputs : dict of str to str
        FMU input name -> column (or derived name).
    outputs : dict of str to str
        FMU output (or local) variable -> column (or derived name).
    derived : dict of str to str
        Derived column -> expression, e.g. ``{"F_o": "F_of - F_or"}``;
        ``"der(x_o)"`` and ``"der(x_o, 2)"`` ask for time derivatives of a column.
    """

    name: str
    data: pd.DataFrame
    inputs: dict[str, str]
    outputs: dict[str, str]
    derived: dict[str, str] = field(default_factory=dict)


@dataclass
class Problem:
    """A benchmark identification problem with its truth.

    Attributes
    ----------
    name : str
        Problem name.
    fmu : pathlib.Path
        The FMU to identify.
    truth : dict of str to float
        The parameter values the data were made with.
    parameters : dict of str to dict
        Name -> ``{"levels": [5 floats], "min": float, "max": float, "unit": str}``
        (``max`` may be ``math.inf``).
    experiments : list of ProblemExperiment
        The experiments (all used for identification unless ``notes`` say otherwise).
    noise : dict of str to float
        True sigma of each compared output (keys as in ``outputs``), in its units.
    start_values : dict of str to float
        Values to apply on every run before the parameters (fixed FMU parameters).
    notes : str
        What a benchmark author should know about this problem.
    """

    name: str
    fmu: Path
    truth: dict[str, float]
    parameters: dict[str, dict]
    experiments: list[ProblemExperiment]
    noise: dict[str, float]
    start_values: dict[str, float] = field(default_factory=dict)
    notes: str = ""


def load_module(path: Path, name: str) -> ModuleType:
    """Import a Python file by path (once; registered in ``sys.modules`` as ``name``)."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


#: ``examples/_datagen.py``, under the name the examples' generators import it by.
DATAGEN = load_module(REPO / "examples" / "_datagen.py", "_datagen")
#: Sample instants ``t_k = k / rate`` from 0 to ``duration`` (s), as the examples'.
sample_times = DATAGEN.sample_times
#: Exact response of a linear system to an input held per sample, as the examples'.
zoh_response = DATAGEN.zoh_response


def levels(low: float, high: float, n: int = 5) -> list[float]:
    """``n`` levels from ``low`` to ``high``: log-spaced when they span a decade or more."""
    if high / low >= 10.0 - 1e-12:
        values = np.geomspace(low, high, n)
    else:
        values = np.linspace(low, high, n)
    return [float(f"{v:.6g}") for v in values]


def parameter(
    low: float, high: float, unit: str, minimum: float = 0.0, maximum: float = math.inf
) -> dict:
    """One entry of :attr:`Problem.parameters` with levels from ``low`` to ``high``."""
    return {"levels": levels(low, high), "min": minimum, "max": maximum, "unit": unit}


def log_position(value: float, low: float, high: float) -> float:
    """Where ``value`` lies in ``[low, high]`` on a log scale (0 at low, 1 at high)."""
    return math.log(value / low) / math.log(high / low)


def cached_path(stem: str, source: str, suffix: str = ".fmu") -> Path:
    """Cache path of an artefact built from ``source`` (a new path when it changes)."""
    digest = hashlib.sha256(source.encode()).hexdigest()[:12]
    folder = CACHE / f"{stem}-{digest}"
    folder.mkdir(parents=True, exist_ok=True)
    return folder / f"{stem}{suffix}"


def cached_build(stem: str, source: str, build: Callable[[Path], Path]) -> Path:
    """The FMU ``stem`` built from ``source``, from the cache or built into it once.

    ``build(folder)`` makes the FMU in a scratch folder beside the cached one and returns
    its path; it is then moved into place atomically, so a concurrent build cannot leave
    half a file.
    """
    fmu = cached_path(stem, source)
    if not fmu.exists():
        with tempfile.TemporaryDirectory(dir=fmu.parent) as tmp:
            os.replace(build(Path(tmp)), fmu)
    return fmu


def ranged_problem(
    name: str,
    fmu: Path,
    experiment: ProblemExperiment,
    ranges: dict[str, tuple[float, float, str]],
    truth: dict[str, float],
    noise: dict[str, float],
    notes: str,
) -> Problem:
    """A problem with one experiment and first levels from ``ranges``.

    ``ranges`` maps each parameter to ``(low, high, unit)``: see :func:`parameter`.
    """
    return Problem(
        name=name,
        fmu=fmu,
        truth=dict(truth),
        parameters={k: parameter(lo, hi, unit) for k, (lo, hi, unit) in ranges.items()},
        experiments=[experiment],
        noise=dict(noise),
        start_values={},
        notes=notes,
    )


def simulate_fmu(
    fmu: Path,
    t: np.ndarray,
    inputs: dict[str, np.ndarray],
    outputs: list[str],
    params: dict[str, float],
    start_values: dict[str, float] | None = None,
) -> np.ndarray:
    """Run ``fmu`` once with inputs given per sample (held over each step)."""
    from tsid_fmu.fmu import FMUSession

    with FMUSession(
        fmu,
        inputs=list(inputs),
        outputs=outputs,
        parameters=list(params),
        start_values=start_values,
    ) as session:
        u = np.column_stack([inputs[k] for k in inputs]) if inputs else None
        return session.simulate(t, u, params)


def rms_over_sigma(a: np.ndarray, b: np.ndarray, sigma: float) -> tuple[float, float]:
    """RMS and maximum of ``a - b`` in units of ``sigma``."""
    d = np.asarray(a) - np.asarray(b)
    return float(np.sqrt(np.mean(d**2)) / sigma), float(np.max(np.abs(d)) / sigma)


def introduce(
    factory: Callable[[], Problem], build_fmu: Callable[[], Path] | None = None, what: str = ""
) -> Problem:
    """Start a self-check: build or find the FMU, make the problem, print both and timings.

    Parameters
    ----------
    factory : callable
        Makes the problem.
    build_fmu : callable, optional
        Builds the FMU into the cache (timed on its own); ``None`` for a committed FMU.
    what : str
        Appended to the generator's timing line.

    Returns
    -------
    Problem
        The problem ``factory`` made.
    """
    if build_fmu is not None:
        t0 = time.perf_counter()
        fmu = build_fmu()
        print(f"FMU {fmu} ({time.perf_counter() - t0:.1f} s to build or find)")
    t0 = time.perf_counter()
    problem = factory()
    print(f"generator: {time.perf_counter() - t0:.2f} s{what}")
    print(describe(problem))
    return problem


def describe(problem: Problem) -> str:
    """A few lines on ``problem``: truth, ranges, noise, experiments."""
    lines = [f"problem {problem.name}: FMU {problem.fmu}"]
    for name, value in problem.truth.items():
        spec = problem.parameters[name]
        lv = spec["levels"]
        pos = log_position(value, lv[0], lv[-1])
        lines.append(
            f"  {name:>4} truth {value:<10.6g} levels {lv} {spec['unit']} "
            f"(truth at {100 * pos:.0f} % of the log range)"
        )
    lines.append(
        "  sigma per compared output: "
        + ", ".join(f"{k} {v:.4g}" for k, v in problem.noise.items())
    )
    for exp in problem.experiments:
        lines.append(
            f"  experiment {exp.name}: {len(exp.data)} rows, columns {list(exp.data.columns)}, "
            f"inputs {exp.inputs}, outputs {exp.outputs}, derived {exp.derived}"
        )
    return "\n".join(lines)
