"""From a study to what the evaluators need: loaded data, weights, replicate inputs."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tsid_fmu.data.measured import MeasuredData, load_data
from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.cost import NOISE_POWER, noise_level
from tsid_fmu.evaluate.serial import SerialEvaluator
from tsid_fmu.evaluate.spec import EvaluationSpec, PreparedExperiment
from tsid_fmu.evaluate.variants import variants_of
from tsid_fmu.evaluate.windows import select, window_ranges
from tsid_fmu.fmu.delay import delay_input
from tsid_fmu.study.definition import Study
from tsid_fmu.study.initial import check_settable, initial_values
from tsid_fmu.study.schema import Experiment

__all__ = [
    "NOISE_FLOOR",
    "data_noise",
    "load_experiment",
    "prepare",
    "prepare_experiment",
    "serial_evaluator",
    "solver_settings",
    "weight_norms",
]

NOISE_FLOOR = 1e-3
"""An output that shows no noise has its residuals scaled as if its noise were this
fraction of its RMS value (only with ``weighting = "none"``; ``"noise"`` refuses it)."""


def load_experiment(experiment: Experiment) -> MeasuredData:
    """Load (and check) an experiment's data with its derived channels."""
    data = experiment.data
    if isinstance(data, MeasuredData):
        return data
    derived = experiment.derived or None
    if hasattr(data, "columns") and hasattr(data, "iloc"):
        return MeasuredData.from_frame(
            data,
            time_column=experiment.time_column,
            source=experiment.name,
            derived=derived,
            sample_time=experiment.sample_time,
        )
    return load_data(
        data,
        time_column=experiment.time_column,
        derived=derived,
        sample_time=experiment.sample_time,
    )


def _frozen(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=np.float64, order="C", copy=True)
    out.flags.writeable = False
    return out


def data_noise(measured: np.ndarray) -> np.ndarray:
    """Return each column's noise (:func:`~tsid_fmu.evaluate.cost.noise_level`), 0 if unseen.

    The noise is seen in second differences, so data of fewer than 3 samples show none:
    their outputs count as noise-free, as constant ones do (the estimate was NaN, with
    numpy's "Mean of empty slice" warnings on stderr).
    """
    measured = np.asarray(measured, dtype=float)
    if measured.shape[0] >= 3:
        return noise_level(measured)
    return np.zeros(measured.shape[1] if measured.ndim == 2 else 1)


def resolution_noise(y: np.ndarray) -> float:
    """Return the noise level below which a column is noise-free: its float round-off.

    64 round-offs (``2**-52``) of the column's largest value: a simulation written at
    full precision shows less. Rounding to a coarser grid (a sensor's or a file's
    decimals) acts as noise (:func:`~tsid_fmu.evaluate.noise.noise_level`) and is not
    refused. This replaces a fixed 1e-6 of the range, which refused real sensor noise of
    a designed record (1.4e-6 of its range) as noise-free.
    """
    y = np.asarray(y, dtype=float)
    finite = y[np.isfinite(y)]
    top = float(np.max(np.abs(finite))) if finite.size else 0.0
    return max(64 * np.finfo(float).eps * top, 1e-300)


def weight_norms(study: Study) -> tuple[float, float]:
    """Return the largest output weight and the largest window weight of a study.

    Only the ratios of weights mean something: multiplying every weight by one
    constant must not change the answer, its intervals or its verdict. The thresholds
    of the search compare costs with costs, but a few compare them with the noise
    floor, and SciPy's tolerances hold a few absolute figures; so every output weight
    is divided by the largest one of the study (every experiment's, 1 where not
    given), and every window weight likewise. Costs are reported in those units: the
    largest weight counts 1.
    """
    outputs = [float((e.weights or {}).get(n, 1.0)) for e in study.experiments for n in e.outputs]
    windows = [float(w) for e in study.experiments for w in (e.window_weights or (1.0,))]
    return max(outputs, default=1.0), max(windows, default=1.0)


def _weights_and_scale(
    study: Study, experiment: Experiment, measured: np.ndarray, norm: float
) -> tuple[np.ndarray, np.ndarray]:
    """Each output's cost weight and residual scale, from the noise seen in the data.

    ``norm`` is the study's largest output weight (:func:`weight_norms`).
    """
    names = list(experiment.outputs)
    user = np.array([(experiment.weights or {}).get(n, 1.0) for n in names], dtype=float)
    user = user / norm
    sigma = data_noise(measured)
    sigma = np.array([experiment.noise.get(n, s) for n, s in zip(names, sigma, strict=True)])
    rms = np.sqrt(np.mean(measured**2, axis=0))
    # noise-free: at most what the data's own resolution makes (a noise-free simulation
    # written with so many decimals); a noise the study states is never refused
    stated = np.array([n in experiment.noise for n in names])
    floor = np.array([resolution_noise(measured[:, j]) for j in range(len(names))])
    quiet = ~(sigma > floor) & ~stated
    if study.method.weighting == "noise" and quiet.any():
        flat = [n for n, q in zip(names, quiet, strict=True) if q]
        raise StudyError(
            f'experiment {experiment.name!r}: weighting = "noise" needs noisy outputs, but '
            f"{', '.join(flat)} shows no noise; give its sensor noise (noise = {{...}}) or "
            'weights, or set weighting = "none"'
        )
    sigma = np.where(quiet, np.maximum(NOISE_FLOOR * rms, 1e-300), sigma)
    weights = (
        user
        if study.method.weighting == "none"
        else (user / sigma ** NOISE_POWER[study.method.cost])
    )
    # residuals are scaled so that, for the sse cost, their sum of squares is the cost
    with np.errstate(divide="ignore"):
        if study.method.cost == "sse":
            scale = 1.0 / np.sqrt(weights)
        else:
            scale = sigma / np.sqrt(user)
    return weights, scale


def _noisy_inputs(study: Study, index: int, inputs: np.ndarray | None) -> tuple[np.ndarray, ...]:
    method = study.method
    if inputs is None or method.input_noise == 0 or method.replicates == 1:
        return ()
    scale = method.input_noise * np.std(inputs, axis=0)
    out = []
    for r in range(1, method.replicates):
        rng = np.random.default_rng([method.seed, index, r])
        out.append(_frozen(inputs + rng.standard_normal(inputs.shape) * scale))
    return tuple(out)


def prepare_experiment(
    study: Study, index: int, parameters: Sequence[str] | None = None
) -> PreparedExperiment:
    """Load experiment ``index`` of a study and arrange it for simulation.

    Of the per-experiment parameters' copies among ``parameters`` (default the study's
    ``parameter_names``), this experiment's own set their variables in it alone.

    Replicate ``r`` (``r >= 2``) of experiment ``index`` adds Gaussian noise drawn from
    ``numpy.random.default_rng([seed, index, r - 1])`` with a standard deviation of
    ``input_noise`` times each input's own standard deviation; replicate 1 is the
    measured input itself.
    """
    experiment = study.experiments[index]
    varied = set(study.parameter_names if parameters is None else parameters)
    data = load_experiment(experiment)
    inputs = data.columns(list(experiment.inputs.values())) if experiment.inputs else None
    measured = data.columns(list(experiment.outputs.values()))
    windows: tuple[tuple[int, int], ...] = ()
    if experiment.windows or experiment.warmup:
        windows = window_ranges(experiment.name, data.time, experiment.windows, experiment.warmup)
    copies = {c.name: c.variable for c in study.copies if c.experiment == experiment.name}
    where = f"experiment {experiment.name!r}: per-experiment parameter"
    check_settable(study.fmu, sorted({v for v in copies.values() if not delay_input(v)}), where)
    copies = {k: v for k, v in copies.items() if k in varied}
    # the noise, the weights and the residual scales come from the scored samples only
    output_norm, window_norm = weight_norms(study)
    weights, scale = _weights_and_scale(study, experiment, select(windows, measured), output_norm)
    return PreparedExperiment(
        name=experiment.name,
        time=_frozen(data.time),
        input_names=tuple(experiment.inputs),
        output_names=tuple(experiment.outputs),
        inputs=None if inputs is None else _frozen(inputs),
        measured=_frozen(measured),
        weights=weights,
        scale=scale,
        noisy_inputs=_noisy_inputs(study, index, inputs),
        # initial states from the data (study/initial.py), over the experiment's own
        start_values={**experiment.start_values, **initial_values(study.fmu, experiment, data)},
        hold=dict(experiment.hold),
        windows=windows,
        window_weights=tuple(w / window_norm for w in experiment.window_weights or ()),
        copies=copies,
    )


def solver_settings(study: Study) -> tuple[str, float | None]:
    """Return a study's interface and step: ``[method]``'s where given, else ``[study]``'s."""
    method = study.method
    interface = method.interface if method.interface is not None else study.interface
    return interface, method.step if method.step is not None else study.step_size


def prepare(
    study: Study,
    experiments: Sequence[str] | None = None,
    parameters: Sequence[str] | None = None,
    *,
    role: str = "identify",
) -> EvaluationSpec:
    """Build the evaluation spec of a study.

    Parameters
    ----------
    study : Study
        The study: its FMU, experiments and parameters.
    experiments : sequence of str, optional
        Names of the experiments to use; default every experiment with ``role``.
    parameters : sequence of str, optional
        Parameters varied (default all of the study's); the others are not set.
    role : {"identify", "validate"}
        Which experiments are used when ``experiments`` is not given.

    Returns
    -------
    EvaluationSpec
        What an evaluator simulates for each parameter set, and how it scores it.
    """
    if experiments is None:
        indices = [i for i, e in enumerate(study.experiments) if e.role == role]
    else:
        by_name = {e.name: i for i, e in enumerate(study.experiments)}
        indices = [by_name[n] for n in experiments]
    interface, step = solver_settings(study)
    names = tuple(study.parameter_names if parameters is None else parameters)
    model = study.variants
    return EvaluationSpec(
        fmu=study.fmu,
        parameter_names=names,
        experiments=tuple(prepare_experiment(study, i, names) for i in indices),
        cost=study.method.cost,
        start_values=dict(study.start_values),
        interface=interface,
        step_size=step,
        tolerance=study.method.tolerance,
        cs_tolerance=study.method.cs_tolerance,
        variants=None if model is None else variants_of(model.name, model.paths),
    )


def serial_evaluator(study: Study, experiments: Sequence[str] | None = None) -> SerialEvaluator:
    """Make an in-process evaluator of a study's experiments (for scripts and tests).

    ``prepared`` holds its prepared experiments (the spec's), as the first release's
    ``Evaluator(study)`` had.
    """
    ev = SerialEvaluator(prepare(study, experiments))
    ev.prepared = ev.spec.experiments  # type: ignore[attr-defined]
    return ev
