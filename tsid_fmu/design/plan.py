"""What a design works with: the study at its answer, the template, the candidate inputs.

The designed signals are *data columns*, the ones a rig's controller sets (a motor
force, a stage position), and a candidate experiment is built as the template
experiment would be from a data file: its ``derived`` channels (a velocity
``der(x_o)``), its input and output mappings, its hold, its initial states and its
sensors' noise. So a column whose derivatives the model takes as inputs gets smooth
signals only (a sine or a multisine where a step or a PRBS is asked for: a position
that jumps has no velocity), below the frequency where the data's ``der()`` stops being
accurate (:func:`_cap`), and the columns not designed are held at the template's first
sample.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from tsid_fmu.data.expressions import evaluate, names_used
from tsid_fmu.design.signals import Signal, candidates
from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.spec import EvaluationSpec, PreparedExperiment
from tsid_fmu.search.space import Space
from tsid_fmu.study.definition import Study, fields_of
from tsid_fmu.study.designopts import DesignOptions, check_samples
from tsid_fmu.study.prepare import load_experiment, prepare
from tsid_fmu.study.schema import Experiment
from tsid_fmu.study.toml import read_design
from tsid_fmu.uncertainty.fidelity import chosen_cs_tolerance, chosen_interface

__all__ = ["Plan", "at_bounds", "candidate_spec", "make_plan", "unused"]


@dataclass
class Plan:
    """The study at its answer, the template experiment and the candidate inputs."""

    study: Study
    options: DesignOptions
    spec: EvaluationSpec
    space: Space
    """The search coordinates near the answer (:meth:`~tsid_fmu.search.space.Space.near`:
    a log parameter below its smallest first level, an offset at 0, is linear there)."""
    x: dict[str, float]
    template: PreparedExperiment
    source: Experiment
    held: dict[str, float]
    time: np.ndarray
    columns: list[str]
    limits: list[tuple[float, float]]
    band: tuple[float, float]
    signals: list[Signal]
    sigma: np.ndarray
    follow: dict[str, list[float]]
    """First levels of the study the prediction is for (:func:`follow_up_levels`)."""
    levels: dict[str, list[float]]
    """The study's first levels of the parameters the answer has (:func:`unused`)."""


def _options(result: Any, options: DesignOptions | None) -> DesignOptions:
    if options is not None:
        return options
    source = getattr(result.study, "source", None)
    return read_design(source) if source is not None else DesignOptions()


def unused(result: Any, study: Study) -> list[str]:
    """Return the study's Real parameters that the result's chosen structure does not use.

    A structure in which a parameter has no effect (a Stribeck velocity under Coulomb
    friction) gives it no value (:mod:`tsid_fmu.structure`): the design leaves it out,
    as the answer does. Only a result that chose a structure has such parameters; a
    parameter missing from any other result is another study's (:func:`_same_parameters`).
    """
    structure = getattr(result, "structure", None)
    params = getattr(result, "params", None)
    if not study.choice_names or not isinstance(structure, Mapping):
        return []
    if not isinstance(params, Mapping):
        return []
    if any(n not in params for n in study.choice_names):
        return []
    return [n for n in study.first_levels() if n not in params]


def _same_parameters(result: Any, study: Study, left: Sequence[str] = ()) -> None:
    """Refuse a result that lacks some of the study's parameters (another study's result).

    ``left`` are those the chosen structure does not use (:func:`unused`).
    """
    params = getattr(result, "params", None)
    if not isinstance(params, Mapping):
        raise TypeError("design: result must be an identification result (tsid_fmu.load)")
    have = [str(n) for n in params]
    want = [*(n for n in study.first_levels() if n not in left), *study.choice_names]
    missing = [n for n in want if n not in have]
    if missing:
        extra = [n for n in have if n not in want]
        besides = f"; the result has {', '.join(extra)}, which the study does not" if extra else ""
        raise StudyError(
            f"design: the result's parameters differ from the study's: it has no "
            f"{', '.join(missing)}{besides} (is it this study's result?)"
        )


def _template(study: Study, spec: EvaluationSpec, name: str) -> tuple[PreparedExperiment, Any]:
    names = [e.name for e in spec.experiments]
    if name and name not in names:
        raise StudyError(
            f"[design] experiment {name!r} is not an identification experiment ({', '.join(names)})"
        )
    k = names.index(name) if name else 0
    source = next(e for e in study.experiments if e.name == names[k])
    return spec.experiments[k], source


def _time(template: PreparedExperiment, opts: DesignOptions) -> np.ndarray:
    t = np.asarray(template.time, dtype=float)
    dt = opts.sample_time or float(np.median(np.diff(t)))
    duration = opts.duration or float(t[-1] - t[0])
    n = check_samples(duration, dt)  # bounded before any array is made
    return np.round(t[0] + dt * np.arange(n + 1), 12)


def _band(opts: DesignOptions, t: np.ndarray) -> tuple[float, float]:
    """Return the allowed band: ``[design] band``, checked against the record, or the default.

    A record of ``T`` seconds at ``dt`` carries frequencies from ``1 / T`` (one period)
    to the Nyquist frequency ``1 / (2 dt)``; the default band runs from two periods a
    record to a twentieth of the sample rate, and needs a record of more than 40 samples.
    """
    dt, span = float(t[1] - t[0]), float(t[-1] - t[0])
    if opts.band:
        lo, hi = float(opts.band[0]), float(opts.band[1])
        if hi > 0.5 / dt:
            raise StudyError(
                f"[design] band: f_max {hi:.6g} Hz is above the Nyquist frequency "
                f"{0.5 / dt:.6g} Hz of the sample time {dt:.6g} s (lower it, or give a "
                "shorter [design] sample_time)"
            )
        if lo < 1.0 / span * (1 - 1e-9):
            raise StudyError(
                f"[design] band: f_min {lo:.6g} Hz is below {1.0 / span:.6g} Hz, one period "
                f"in the record of {span:.6g} s (raise it, or give a longer [design] duration)"
            )
        return lo, hi
    lo, hi = 2.0 / span, 1.0 / (20 * dt)
    if not lo < hi:
        raise StudyError(
            f"[design] sample_time: the record of {span:.6g} s at {dt:.6g} s has {t.size - 1} "
            "samples, too few for the default band (two periods a record to a twentieth of "
            "the sample rate needs more than 40): give [design] band, or a longer duration or "
            "a shorter sample_time"
        )
    return lo, hi


def _input_columns(source: Experiment, frame: pd.DataFrame) -> list[str]:
    """Return the data columns the FMU's inputs come from, directly or through derived ones."""
    out: list[str] = []
    for channel in source.inputs.values():
        used = names_used(source.derived[channel]) if channel in source.derived else {channel}
        out += [c for c in sorted(used) if c in frame.columns and c not in out]
    return out


def _derivatives(source: Experiment, column: str) -> list[str]:
    """Return the derived channels that feed an input and differentiate ``column``."""
    feeds = set(source.inputs.values())
    return [
        expr
        for name, expr in source.derived.items()
        if name in feeds and "der(" in expr and column in names_used(expr)
    ]


DER_ERROR = 1e-3
"""Largest relative error of a derived channel's ``der()`` that a proposed signal may
carry (:func:`_cap`)."""


CHECKED_PERIOD = 2000
"""Samples a period below which :func:`_cap` checks ``der()`` at that frequency instead:
the Savitzky-Golay error falls as the square of the samples a period (3 % at 100, so
about 8e-5 at 2000, below :data:`DER_ERROR`), and a check at 1e-5 Hz sampled at 1 kHz
needed 3.6 GB (issue 66, finding 11); now at most 4 periods of 2000 samples, ten times
finer."""


def _cap(expressions: list[str], column: str, dt: float, band: tuple[float, float]) -> float:
    """Return the highest frequency at which ``der()`` of ``column`` is accurate.

    The Savitzky-Golay derivative (:mod:`tsid_fmu.data.derivative`) smooths: at 1 kHz
    its 21-sample window gives the second derivative of a 10 Hz sine 3 % low, and the
    MISO example's stage designed up to 10 Hz gave answers whose intervals excluded the
    truth on 10 of 10 seeds, with no warning (the residuals stayed at the noise). Each
    expression is evaluated on a sine sampled as the data are and on one sampled ten
    times finer; the band of a differentiated column ends below the first frequency
    where they differ by more than :data:`DER_ERROR` of the derivative's amplitude.
    """
    cap = band[1]
    checked: set[float] = set()
    for f_band in np.geomspace(band[0], band[1], 40):
        # below CHECKED_PERIOD samples a period the smoothing errs less than it does
        # there (its error grows with the frequency): check there, in bounded memory
        f = max(float(f_band), 1.0 / (CHECKED_PERIOD * dt))
        if f in checked:
            continue
        checked.add(f)
        n = max(round(4 / (f * dt)), 400)
        for expr in expressions:
            coarse, fine = (
                evaluate(expr, {name: np.sin(2 * np.pi * f * dt / k * np.arange(n * k))
                                if name == column else np.zeros(n * k)
                                for name in names_used(expr)}, sample_time=dt / k)[::k]
                for k in (1, 10)
            )  # fmt: skip
            mid = slice(n // 4, 3 * n // 4)
            if np.max(np.abs(coarse - fine)[mid]) > DER_ERROR * np.max(np.abs(fine[mid])):
                return float(min(cap, f_band))
    return float(cap)


def _limits(
    source: Experiment, frame: pd.DataFrame, opts: DesignOptions
) -> tuple[list[str], list[tuple[float, float]]]:
    columns = _input_columns(source, frame)
    if opts.inputs:
        unknown = [n for n in opts.inputs if n not in columns]
        if unknown:
            raise StudyError(
                f"[design] inputs: {', '.join(unknown)} is not a data column that feeds an "
                f"input of experiment {source.name!r} ({', '.join(columns) or 'none'})"
            )
        names = list(opts.inputs)
        return names, [(opts.inputs[n][0], opts.inputs[n][1]) for n in names]
    varied = [c for c in columns if np.ptp(frame[c].to_numpy(float)) > 0]
    if not varied:
        raise StudyError(
            f"experiment {source.name!r}: no data column drives an FMU input, or none varies: "
            "there is nothing to design (give [design] inputs)"
        )
    return varied, [(float(frame[c].min()), float(frame[c].max())) for c in varied]


def _sigma(result: Any, template: PreparedExperiment) -> np.ndarray:
    known = (getattr(result, "noise", None) or {}).get(template.name, {})
    return np.array(
        [float(known.get(n, s)) for n, s in zip(template.output_names, template.scale, strict=True)]
    )


FOLLOW_UP = (0.5, 0.7, 1.0, 1.4, 2.0)
"""First levels of the study with the proposal added, as factors of the answer."""


def follow_up_levels(
    study: Study, x: dict[str, float], intervals: Mapping[str, Any] | None = None
) -> dict[str, list[float]]:
    """First levels of the study the prediction is for: around the answer.

    Each parameter's answer times :data:`FOLLOW_UP` (half to twice it), inside its
    bounds; the study's own levels where the bounds merge two of them (an answer of 0, or
    one pressed against a bound). The prediction must be made for the first
    levels the study will have: the intervals' resolution and the finite differences'
    steps are fractions of a first range, and where the model has events (dry friction)
    the steps change the intervals. On the SISO example, predicted with the study's own
    levels and achieved from these, F_vm's interval was 1.36 times the predicted one on
    every noise seed; predicted with these, 1.08 (1.14 with the noise centred:
    ``benchmarks/design.py``).

    An answer nearer zero than its 95 % interval is wide (``intervals``, the study's)
    gets levels that span that interval instead, centred on the answer: half to twice
    an answer of 0.01 whose interval is -0.5 .. 0.5 lie on one side of zero, and exclude
    most of what the data allow.
    """
    bounds = study.bounds()
    intervals = intervals or {}
    out = {}
    for name, own in study.first_levels().items():
        if name not in x:  # not used by the chosen structure (unused)
            continue
        low, high = bounds[name]
        value = x[name]
        factors = [value * f for f in FOLLOW_UP]
        iv = at_bounds(intervals.get(name), low, high)
        if _finite_pair(iv):
            a, b = float(iv[0]), float(iv[1])
            if abs(value) < 0.5 * (b - a):
                reach = max(value - a, b - value)
                factors = [value + reach * f for f in (-1.0, -0.5, 0.0, 0.5, 1.0)]
                # near a bound (an offset at 0) the bound cuts the span: even over what is left
                ends = min(max(factors[0], low), high), min(max(factors[-1], low), high)
                if ends != (factors[0], factors[-1]):
                    factors = list(np.linspace(ends[0], ends[1], len(FOLLOW_UP)))
        levels = sorted(min(max(v, low), high) for v in factors)
        distinct = len(set(levels)) == len(FOLLOW_UP) and all(np.isfinite(levels))
        out[name] = levels if distinct else list(own)
    return out


def at_bounds(iv: Any, low: float, high: float) -> Any:
    """Return interval ``iv`` with an open end (``None``) at a finite bound on its side.

    The study's interval is open below where the data allow the parameter down to its
    bound: an offset whose answer is 0 and whose bound is 0 is ``open .. 0.003``.
    """
    if not isinstance(iv, list | tuple) or len(iv) != 2:
        return iv
    a = low if iv[0] is None and math.isfinite(low) else iv[0]
    b = high if iv[1] is None and math.isfinite(high) else iv[1]
    return [a, b]


def _finite_pair(iv: Any) -> bool:
    """Whether ``iv`` is a closed interval: two finite numbers (not an open end, ``None``)."""
    return (
        isinstance(iv, list | tuple)
        and len(iv) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in iv)
        and all(math.isfinite(v) for v in iv)
    )


def make_plan(result: Any, options: DesignOptions | None) -> Plan:
    """Check the study and build everything the design needs, before any simulation."""
    if options is not None and not isinstance(options, DesignOptions):
        raise TypeError(f"design: options must be DesignOptions, not {type(options).__name__}")
    study = getattr(result, "study", None)
    if study is None:
        raise StudyError("design: the result has no study attached (load it with its study)")
    if not isinstance(study, Study):
        raise TypeError(f"design: result.study must be a Study, not {type(study).__name__}")
    if study.variants is not None and study.variants.name not in study.start_values:
        raise StudyError("design: a study that chooses among FMU files is not designed yet")
    if study.copies:
        raise StudyError("design: a study with per-experiment parameters is not designed yet")
    opts = _options(result, options)
    left = unused(result, study)
    _same_parameters(result, study, left)
    levels = {n: v for n, v in study.first_levels().items() if n not in left}
    spec = prepare(study, parameters=list(levels))  # the unused ones are not set
    fixed = {n: float(result.params[n]) for n in study.choice_names}
    fidelity = getattr(result, "fidelity", None)  # the solver chosen, as tsid simulate --result
    spec = dataclasses.replace(
        spec,
        start_values={**spec.start_values, **fixed},
        interface=chosen_interface(fidelity) or spec.interface,
        cs_tolerance=spec.cs_tolerance or chosen_cs_tolerance(fidelity),
    )
    searched = Space(levels, study.bounds(), study.method.leveling)
    x = {n: float(result.params[n]) for n in searched.names}
    space = searched.near(x)
    template, source = _template(study, spec, opts.experiment)
    frame = load_experiment(source).frame
    columns, limits = _limits(source, frame, opts)
    t = _time(template, opts)
    band = _band(opts, t)
    raw = [c for c in frame.columns if c not in source.derived and c != source.time_column]
    held = {str(c): float(frame[c].iloc[0]) for c in raw}
    ders = [_derivatives(source, c) for c in columns]
    caps = [
        _cap(d, c, float(t[1] - t[0]), band) if d else band[1]
        for c, d in zip(columns, ders, strict=True)
    ]
    signals = candidates(t, limits, band, opts.kinds, opts.bands, opts.seed,
                         smooth=[bool(d) for d in ders], caps=caps)  # fmt: skip
    follow = follow_up_levels(study, x, getattr(result, "intervals", None))
    return Plan(study, opts, spec, space, x, template, source, held, t, columns, limits,
                (float(band[0]), float(band[1])), signals, _sigma(result, template),
                follow, levels)  # fmt: skip


def candidate_spec(plan: Plan, signals: list[np.ndarray]) -> EvaluationSpec:
    """Return a spec with one experiment per candidate input (``signals[k]``, ``(n, m)``).

    Each is the template experiment on a data frame whose designed columns hold the
    signal and whose other columns hold the template's first sample; its sensors'
    noise is stated (``plan.sigma``), so nothing is estimated from those columns.
    """
    src = plan.source
    noise = dict(zip(src.outputs, plan.sigma.tolist(), strict=True))
    experiments = []
    for k, values in enumerate(signals):
        data = {src.time_column: plan.time, **{c: np.full(plan.time.size, v)
                                               for c, v in plan.held.items()}}  # fmt: skip
        for i, c in enumerate(plan.columns):
            data[c] = values[:, i]
        experiments.append(
            dataclasses.replace(
                src,
                data=pd.DataFrame(data),
                name=f"design {k + 1}",
                noise=noise,
                windows=[],
                warmup=0.0,
                window_weights=None,
                sample_time=None,
                role="identify",
            )
        )
    study = Study(**{**fields_of(plan.study), "experiments": experiments, "phases": []})
    spec = prepare(study, parameters=list(plan.levels))
    return dataclasses.replace(
        spec, start_values=plan.spec.start_values, interface=plan.spec.interface
    )
