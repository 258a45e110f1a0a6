"""Evaluate parameter sets: simulate each experiment and replicate, score against the data.

This is the step of the Taguchi loop that costs time: one simulation per array row,
replicate and experiment. :class:`Evaluator` owns one :class:`~tsid_fmu.fmu.FMUSession`
per experiment (extracted and instantiated once, reset between runs) and the replicate
inputs (measured input plus seeded white Gaussian noise, the SISO paper's robustness
step). A row whose simulation fails is scored ``inf`` and its reason kept; it never stops
the study.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from tsid_fmu.data import MeasuredData, load_data
from tsid_fmu.errors import FMUError, SimulationError, StudyError, TsidError
from tsid_fmu.fmu import FMUSession
from tsid_fmu.scoring import NOISE_POWER, Cost, noise_level
from tsid_fmu.study import Experiment, Study

__all__ = [
    "Evaluation",
    "Evaluator",
    "PreparedExperiment",
    "output_weights",
    "prepare_experiment",
    "prepare_experiments",
]


@dataclass
class PreparedExperiment:
    """An experiment's data arranged for simulation.

    Attributes
    ----------
    experiment : Experiment
        The study's definition.
    data : MeasuredData
        The loaded data.
    time : numpy.ndarray
        Sample times.
    inputs : numpy.ndarray or None
        Measured inputs, shape ``(n, n_inputs)``, in the order of ``input_names``.
    measured : numpy.ndarray
        Measured outputs, shape ``(n, n_outputs)``, in the order of ``output_names``.
    replicate_inputs : list of numpy.ndarray
        Inputs of each replicate (with noise); one entry if the study has no noise.
    noise : numpy.ndarray
        Noise level of each measured output, estimated from the data
        (:func:`tsid_fmu.scoring.noise_level`).
    """

    experiment: Experiment
    data: MeasuredData
    time: np.ndarray
    input_names: list[str]
    output_names: list[str]
    inputs: np.ndarray | None
    measured: np.ndarray
    replicate_inputs: list[np.ndarray | None] = field(default_factory=list)
    noise: np.ndarray = field(default_factory=lambda: np.zeros(0))


def prepare_experiment(
    experiment: Experiment, index: int, replicates: int, input_noise: float, seed: int
) -> PreparedExperiment:
    """Load an experiment's data and make its replicate inputs.

    Replicate ``r`` of experiment ``index`` adds Gaussian noise drawn from
    ``numpy.random.default_rng([seed, index, r])`` with a standard deviation of
    ``input_noise`` times each input's own standard deviation, so the same study always
    sees the same noise, whatever order rows run in.
    """
    if isinstance(experiment.data, MeasuredData):
        data = experiment.data
    elif hasattr(experiment.data, "columns") and hasattr(experiment.data, "iloc"):
        data = MeasuredData.from_frame(
            experiment.data, time_column=experiment.time_column, source=experiment.name
        )
    else:
        data = load_data(
            experiment.data,
            time_column=experiment.time_column,
            derived=experiment.derived or None,
            sample_time=experiment.sample_time,
        )
    input_names = list(experiment.inputs)
    output_names = list(experiment.outputs)
    inputs = data.columns(list(experiment.inputs.values())) if input_names else None
    measured = data.columns(list(experiment.outputs.values()))
    reps: list[np.ndarray | None]
    if inputs is None or input_noise == 0:
        reps = [inputs]
    else:
        scale = input_noise * np.std(inputs, axis=0)
        reps = []
        for r in range(replicates):
            rng = np.random.default_rng([seed, index, r])
            reps.append(inputs + rng.standard_normal(inputs.shape) * scale)
    # read-only copies: the session checks these arrays once, not at every simulation
    time = _frozen_copy(data.time)
    frozen = _frozen_copy(inputs)
    reps = [frozen if a is inputs else _frozen_copy(a) for a in reps]
    inputs = frozen
    return PreparedExperiment(
        experiment=experiment,
        data=data,
        time=time,
        input_names=input_names,
        output_names=output_names,
        inputs=inputs,
        measured=measured,
        replicate_inputs=reps,
        noise=noise_level(measured),
    )


def _frozen_copy(a: np.ndarray | None) -> np.ndarray | None:
    if a is None:
        return None
    out = np.array(a, dtype=np.float64, order="C", copy=True)
    out.flags.writeable = False
    return out


@dataclass
class Evaluation:
    """Costs of a batch of parameter sets.

    Attributes
    ----------
    costs : numpy.ndarray
        Shape ``(n_sets, n_replicates)``: cost of each set and replicate, summed over
        the experiments; ``inf`` where a simulation failed.
    errors : list of str or None
        Why each set failed (first failure), or None.
    nfev : int
        Simulations run for this batch.
    """

    costs: np.ndarray
    errors: list[str | None]
    nfev: int

    @property
    def mean_costs(self) -> np.ndarray:
        """Mean cost over the replicates of each set (``inf`` if any failed)."""
        return self.costs.mean(axis=1)


def prepare_experiments(
    study: Study, experiments: Sequence[int] | None = None
) -> list[PreparedExperiment]:
    """Prepare a study's experiments (all, or those with the given indices)."""
    indices = range(len(study.experiments)) if experiments is None else experiments
    return [
        prepare_experiment(study.experiments[i], i, study.replicates, study.input_noise, study.seed)
        for i in indices
    ]


def output_weights(study: Study, prepared: PreparedExperiment) -> np.ndarray:
    """Weight of each output's cost in an experiment's total.

    The experiment's ``weights`` (default 1); with ``study.weighting == "noise"`` each is
    divided by the output's noise level estimated from the data, to the power the cost
    kind needs (:data:`tsid_fmu.scoring.NOISE_POWER`).

    Raises
    ------
    StudyError
        Noise weighting was asked for but an output looks noise-free.
    """
    names = prepared.output_names
    w = np.array([(prepared.experiment.weights or {}).get(n, 1.0) for n in names], dtype=float)
    if study.weighting == "noise":
        sigma = prepared.noise
        span = np.ptp(prepared.measured, axis=0)
        # below a millionth of the range even a 16-bit converter's quantisation: no noise
        flat = [n for n, s, r in zip(names, sigma, span, strict=True) if not s > 1e-6 * r]
        if flat:
            raise StudyError(
                f'experiment {prepared.experiment.name!r}: weighting = "noise" needs noisy '
                f"outputs, but {', '.join(flat)} shows no noise; give weights instead"
            )
        w = w / sigma ** NOISE_POWER[Cost(study.cost).kind]
    return w


class Evaluator:
    """Score parameter sets of a study against its measured experiments.

    Parameters
    ----------
    study : Study
        The study (FMU, experiments, cost, replicates, noise, fixed start values).
    experiments : sequence of int, optional
        Indices of the experiments to use (default: all).

    Notes
    -----
    Use as a context manager, or call :meth:`close`, so the FMU sessions free their
    instances and extracted folders.
    """

    def __init__(self, study: Study, experiments: Sequence[int] | None = None) -> None:
        self.study = study
        self.prepared = prepare_experiments(study, experiments)
        self.cost = Cost(study.cost)
        self.nfev = 0
        self.sessions: list[FMUSession] = []
        try:
            for p in self.prepared:
                start = dict(study.start_values)
                start.update(p.experiment.start_values)
                self.sessions.append(
                    FMUSession(
                        study.fmu,
                        inputs=p.input_names,
                        outputs=p.output_names,
                        parameters=study.parameter_names,
                        interface=study.interface,
                        step_size=study.step_size,
                        start_values=start,
                    )
                )
        except BaseException:
            self.close()
            raise
        self._weights = [output_weights(study, p) for p in self.prepared]

    @property
    def n_replicates(self) -> int:
        """Replicates per parameter set (1 when the study adds no noise)."""
        return max(len(p.replicate_inputs) for p in self.prepared)

    def evaluate(
        self,
        parameter_sets: Sequence[Mapping[str, float]],
        progress: Callable[[int, int], None] | None = None,
        *,
        clean: bool = False,
    ) -> Evaluation:
        """Simulate and score each parameter set.

        Parameters
        ----------
        parameter_sets : sequence of mapping
            Parameter values by name, one mapping per set.
        progress : callable, optional
            Called as ``progress(done, total)`` after each set.
        clean : bool
            Score the measured inputs themselves (one column of costs, no added noise)
            instead of the noise replicates.

        Returns
        -------
        Evaluation
            Costs per set and replicate, and failure reasons.
        """
        n_rep = 1 if clean else self.n_replicates
        costs = np.zeros((len(parameter_sets), n_rep))
        errors: list[str | None] = [None] * len(parameter_sets)
        nfev = 0
        for i, params in enumerate(parameter_sets):
            for p, session, w in zip(self.prepared, self.sessions, self._weights, strict=True):
                for r in range(n_rep):
                    if errors[i] is not None:
                        costs[i, r] = math.inf
                        continue
                    u = (
                        p.inputs
                        if clean
                        else p.replicate_inputs[min(r, len(p.replicate_inputs) - 1)]
                    )
                    nfev += 1
                    try:
                        y = session.simulate(p.time, u, params)
                    except (SimulationError, FMUError) as exc:
                        errors[i] = f"{p.experiment.name}: {exc}"
                        costs[i, :] = math.inf
                        continue
                    per_output = self.cost.per_output(p.time, p.measured, y)
                    value = float(np.dot(per_output, w))
                    costs[i, r] += value if math.isfinite(value) else math.inf
            if progress is not None:
                progress(i + 1, len(parameter_sets))
        self.nfev += nfev
        return Evaluation(costs=costs, errors=errors, nfev=nfev)

    def simulate_clean(
        self, params: Mapping[str, float]
    ) -> list[tuple[PreparedExperiment, np.ndarray | None, str | None]]:
        """Simulate each experiment with its measured (noise-free) input.

        Returns
        -------
        list of tuple
            ``(prepared experiment, simulated outputs or None, error or None)``.
        """
        out = []
        for p, session in zip(self.prepared, self.sessions, strict=True):
            self.nfev += 1
            try:
                out.append((p, session.simulate(p.time, p.inputs, params), None))
            except TsidError as exc:
                out.append((p, None, str(exc)))
        return out

    def simulate_clean_many(
        self, parameter_sets: Sequence[Mapping[str, float]]
    ) -> list[list[tuple[PreparedExperiment, np.ndarray | None, str | None]]]:
        """:meth:`simulate_clean` for several parameter sets."""
        return [self.simulate_clean(p) for p in parameter_sets]

    def close(self) -> None:
        """Free the FMU sessions."""
        for s in self.sessions:
            try:
                s.close()
            except TsidError:
                pass
        self.sessions = []

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
