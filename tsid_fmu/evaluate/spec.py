"""What an evaluator needs: the FMU, the parameter names and the prepared experiments.

An :class:`EvaluationSpec` is the whole input of the evaluation layer. It holds names and
read-only arrays only (no study, no data files), so it pickles unchanged to worker
processes and Dask clusters; the study layer builds it from a study (data loaded, noise
replicates drawn, weights and residual scales chosen). The only file it names is the FMU.

Replicate 1 of every experiment is its measured input itself; replicates 2..R use
:attr:`PreparedExperiment.noisy_inputs`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.cost import Cost
from tsid_fmu.evaluate.variants import Variants
from tsid_fmu.evaluate.windows import (
    Ranges,
    check_ranges,
    head_ranges,
    scored_metrics,
    select,
    weighted_rows,
    window_cost,
)
from tsid_fmu.fmu.delay import check_delays

__all__ = ["EvaluationSpec", "PreparedExperiment", "frozen_array"]

HOLDS = ("previous", "linear")
INTERFACES = ("auto", "cs", "me")
_NAN = float("nan")


def frozen_array(a: object, *, ndim: int | None = None) -> np.ndarray:
    """Return ``a`` as a read-only, C-contiguous float64 array (copied unless already so).

    An array that is already all of these, and whose bases are read-only too, is returned
    as it is, so that its identity (by which :class:`~tsid_fmu.fmu.FMUSession`
    remembers the arrays it has checked) is kept. ``ndim=2`` makes a 1-D array a column.
    """
    if (
        isinstance(a, np.ndarray)
        and a.dtype == np.float64
        and a.flags.c_contiguous
        and (ndim is None or a.ndim == ndim)
        and _read_only(a)
    ):
        return a
    arr = np.asarray(a, dtype=np.float64)
    if ndim == 2 and arr.ndim == 1:
        arr = arr.reshape(-1, 1)
    out = np.array(arr, dtype=np.float64, order="C", copy=True)
    out.flags.writeable = False
    return out


def _read_only(a: np.ndarray) -> bool:
    """Return True if neither ``a`` nor any array it is a view of can be written."""
    base: object = a
    while isinstance(base, np.ndarray):
        if base.flags.writeable:
            return False
        base = base.base
    return True


@dataclass(frozen=True, eq=False)
class PreparedExperiment:
    """One experiment's data, arranged for simulation and scoring.

    Parameters
    ----------
    name : str
        Names the experiment in error messages (``"<name>: <message>"``).
    time : numpy.ndarray
        Sample times, shape ``(n,)``.
    input_names : tuple of str
        FMU input variables, in the column order of ``inputs``.
    output_names : tuple of str
        FMU variables compared with ``measured``, in its column order.
    inputs : numpy.ndarray or None
        The measured inputs, shape ``(n, n_in)``; None when the FMU takes no input.
    measured : numpy.ndarray
        The measured outputs, shape ``(n, n_out)``.
    weights : numpy.ndarray
        Shape ``(n_out,)``, finite and >= 0: the final weight of each output's cost in the
        experiment's total (any noise weighting already applied by the caller).
    scale : numpy.ndarray
        Shape ``(n_out,)``, finite and > 0: residuals are ``(simulated - measured) /
        scale``; normally each output's noise level
        (:func:`tsid_fmu.evaluate.cost.noise_level`).
    noisy_inputs : tuple of numpy.ndarray, optional
        Inputs of replicates 2..R (the measured input plus noise), each shaped like
        ``inputs``. Empty when the study has one replicate; an experiment with fewer
        than R - 1 repeats its last one.
    start_values : mapping of str to float, optional
        FMU values fixed for this experiment (over the spec's ``start_values``).
    hold : mapping of str to str, optional
        Per input: ``"previous"`` (zero-order hold, the default) or ``"linear"``.
    windows : tuple of (int, int), optional
        The sample ranges ``[start, stop)`` that are scored, increasing and disjoint
        (:mod:`tsid_fmu.evaluate.windows`); empty (the default): every sample. The
        whole record is simulated either way.
    window_weights : tuple of float, optional
        Weight of each window's cost (default 1 each).
    copies : mapping of str to str, optional
        This experiment's own parameters: parameter name (of the spec's
        ``parameter_names``) -> the FMU variable it sets in this experiment only (a
        per-experiment parameter's copy, :mod:`tsid_fmu.study.copies`). The other
        experiments ignore it.

    Raises
    ------
    StudyError
        The arrays do not fit together, or a weight or scale is out of range.

    Notes
    -----
    Every array is stored read-only, float64 and C-contiguous (copied if it was not), and
    the mappings as plain dicts, so that the experiment pickles as it is.
    """

    name: str
    time: np.ndarray
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    inputs: np.ndarray | None
    measured: np.ndarray
    weights: np.ndarray
    scale: np.ndarray
    noisy_inputs: tuple[np.ndarray, ...] = ()
    start_values: Mapping[str, float] = field(default_factory=dict)
    hold: Mapping[str, str] = field(default_factory=dict)
    windows: Ranges = ()
    window_weights: tuple[float, ...] = ()
    copies: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "copies", {str(k): str(v) for k, v in self.copies.items()})
        put(self, "name", str(self.name))
        put(self, "windows", tuple((int(a), int(b)) for a, b in self.windows))
        weights = self.window_weights or (1.0,) * len(self.windows)
        put(self, "window_weights", tuple(float(w) for w in weights))
        put(self, "input_names", tuple(str(n) for n in self.input_names))
        put(self, "output_names", tuple(str(n) for n in self.output_names))
        put(self, "time", frozen_array(self.time))
        put(self, "measured", frozen_array(self.measured, ndim=2))
        if self.inputs is not None:
            put(self, "inputs", frozen_array(self.inputs, ndim=2))
        put(self, "noisy_inputs", tuple(frozen_array(a, ndim=2) for a in self.noisy_inputs))
        put(self, "weights", frozen_array(np.reshape(self.weights, -1)))
        put(self, "scale", frozen_array(np.reshape(self.scale, -1)))
        put(self, "start_values", {str(k): float(v) for k, v in self.start_values.items()})
        put(self, "hold", {str(k): str(v) for k, v in self.hold.items()})
        self._check_shapes()
        self._check_weights()
        wrong = check_ranges(self.windows, self.window_weights, len(self.time))
        if wrong:
            raise self._fail(wrong)

    def __setstate__(self, state: dict) -> None:
        # numpy arrays come out of a pickle writeable: make them read-only again, so that
        # a worker's FMU sessions check them once, not at every simulation
        for value in state.values():
            for a in value if isinstance(value, tuple) else (value,):
                if isinstance(a, np.ndarray):
                    a.flags.writeable = False
        self.__dict__.update(state)

    def _fail(self, message: str) -> StudyError:
        return StudyError(f"experiment {self.name!r}: {message}")

    def _check_shapes(self) -> None:
        n = self.time.shape[0] if self.time.ndim == 1 else -1
        if self.time.ndim != 1 or n < 2:
            raise self._fail(f"time must be 1-D with at least 2 samples, got {self.time.shape}")
        n_out = len(self.output_names)
        if n_out == 0 or self.measured.shape != (n, n_out):
            raise self._fail(
                f"measured must have shape ({n}, {n_out}) for outputs "
                f"{list(self.output_names)}, got {self.measured.shape}"
            )
        n_in = len(self.input_names)
        if self.inputs is None:
            if n_in or self.noisy_inputs:
                raise self._fail("inputs are missing for " + ", ".join(self.input_names))
        elif self.inputs.shape != (n, n_in):
            raise self._fail(
                f"inputs must have shape ({n}, {n_in}) for {list(self.input_names)}, "
                f"got {self.inputs.shape}"
            )
        for k, a in enumerate(self.noisy_inputs):
            if self.inputs is None or a.shape != self.inputs.shape:
                raise self._fail(
                    f"noisy_inputs[{k}] has shape {a.shape}, the inputs {self.inputs.shape}"
                )
        for name, how in self.hold.items():
            if name not in self.input_names or how not in HOLDS:
                raise self._fail(
                    f"hold {name!r} = {how!r}: give an input ({', '.join(self.input_names)}) "
                    f"and one of {', '.join(HOLDS)}"
                )

    def _check_weights(self) -> None:
        n_out = len(self.output_names)
        w, s = self.weights, self.scale
        if w.shape != (n_out,) or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise self._fail(f"weights must be {n_out} finite values >= 0, got {w.tolist()}")
        if s.shape != (n_out,) or not np.all(np.isfinite(s)) or not np.all(s > 0):
            raise self._fail(f"scale must be {n_out} finite values > 0, got {s.tolist()}")

    def scored(self, a: np.ndarray) -> np.ndarray:
        """Return the rows of ``a`` (one per sample) that the windows score."""
        return select(self.windows, a)

    def weighted(self, a: np.ndarray) -> np.ndarray:
        """Return the scored rows of ``a``, each times the square root of its window's weight.

        Applied to residuals and to their derivatives alike, it makes their sum of
        squares the windows' weighted cost (the rows of an evaluator's residuals).
        """
        return weighted_rows(self.windows, self.window_weights, a)

    def output_costs(self, cost: Cost, simulated: np.ndarray) -> np.ndarray:
        """Return the cost of each output on the scored samples (unweighted by output)."""
        return window_cost(
            self.windows, self.window_weights, cost, self.time, self.measured, simulated
        )

    def fit_metrics(self, simulated: np.ndarray) -> dict[str, dict[str, float]]:
        """Return :func:`~tsid_fmu.evaluate.cost.metrics` of each output on the scored samples."""
        return scored_metrics(
            self.windows, self.time, self.measured, simulated, list(self.output_names)
        )

    @property
    def n_scored(self) -> int:
        """Samples the windows score (every sample without windows)."""
        return sum(b - a for a, b in self.windows) if self.windows else len(self.time)

    @property
    def weighted_samples(self) -> float:
        """Scored samples, each counted with its window's weight."""
        if not self.windows:
            return float(len(self.time))
        pairs = zip(self.windows, self.window_weights, strict=True)
        return float(sum(w * (b - a) for (a, b), w in pairs))

    @property
    def n_replicates(self) -> int:
        """Replicates this experiment provides: 1 + ``len(noisy_inputs)``."""
        return 1 + len(self.noisy_inputs)

    def replicate_inputs(self, r: int) -> np.ndarray | None:
        """Return the inputs of replicate ``r`` (0-based: 0 is the measured input)."""
        if r == 0 or not self.noisy_inputs:
            return self.inputs
        return self.noisy_inputs[min(r, len(self.noisy_inputs)) - 1]

    def replicate_plan(self, n_replicates: int) -> tuple[int, ...]:
        """For each replicate, the first replicate with the very same inputs.

        A replicate whose entry is not itself needs no simulation of its own: its cost is
        that of the earlier one (an experiment with fewer noisy inputs than the study's
        replicates, or without inputs at all).
        """
        plan: list[int] = []
        for r in range(n_replicates):
            u = self.replicate_inputs(r)
            plan.append(next(s for s in range(r + 1) if self.replicate_inputs(s) is u))
        return tuple(plan)


@dataclass(frozen=True, eq=False)
class EvaluationSpec:
    """Everything an evaluator needs, explicit and picklable.

    Parameters
    ----------
    fmu : pathlib.Path
        The ``.fmu`` file.
    parameter_names : tuple of str
        The parameters every parameter set gives, in the order of the memo keys: FMU
        variables, or ``delay(<input>)`` (:mod:`tsid_fmu.fmu.delay`).
    experiments : tuple of PreparedExperiment
        The experiments, in the order their costs are summed and residuals concatenated.
    cost : str, optional
        Cost kind, one of :data:`tsid_fmu.evaluate.cost.COSTS` (default ``"sse"``).
    start_values : mapping of str to float, optional
        FMU values fixed for every experiment.
    interface : {"auto", "cs", "me"}, optional
        Co-Simulation or Model Exchange (``"auto"`` prefers Co-Simulation).
    step_size : float, optional
        Largest communication step (Co-Simulation) or solver step hint (Model Exchange).
    tolerance : float, optional
        Relative tolerance of the Model Exchange solver (default: the solver's own).
    variants : Variants, optional
        A choice among FMU files (:mod:`tsid_fmu.evaluate.variants`): each set is then
        simulated by the variant its value of the choice names (``fmu`` is the first).
    cs_tolerance : float, optional
        Relative tolerance of a Co-Simulation FMU's own solver (default: not passed).
    fresh : bool, optional
        Instantiate afresh for every run instead of resetting: the FMU's reset was found
        broken (:mod:`tsid_fmu.evaluate.conformance`). Default False.

    Raises
    ------
    StudyError
        No experiment, duplicate names, an unknown cost kind or interface.
    """

    fmu: Path
    parameter_names: tuple[str, ...]
    experiments: tuple[PreparedExperiment, ...]
    cost: str = "sse"
    start_values: Mapping[str, float] = field(default_factory=dict)
    interface: str = "auto"
    step_size: float | None = None
    tolerance: float | None = None
    variants: Variants | None = None
    cs_tolerance: float | None = None
    fresh: bool = False

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "fmu", Path(self.fmu))
        put(self, "parameter_names", tuple(str(n) for n in self.parameter_names))
        put(self, "experiments", tuple(self.experiments))
        put(self, "cost", Cost(self.cost).kind)
        put(self, "start_values", {str(k): float(v) for k, v in self.start_values.items()})
        if self.step_size is not None:
            put(self, "step_size", float(self.step_size))
            if not (math.isfinite(self.step_size) and self.step_size > 0):
                raise StudyError(f"step_size must be > 0, got {self.step_size}")
        if self.tolerance is not None and not 0 < self.tolerance < 1:
            raise StudyError(f"tolerance must be between 0 and 1, got {self.tolerance}")
        if self.interface not in INTERFACES:
            raise StudyError(f"interface must be one of {INTERFACES}, got {self.interface!r}")
        if self.cs_tolerance is not None and not 0 < self.cs_tolerance < 1:
            raise StudyError(f"cs_tolerance must be between 0 and 1, got {self.cs_tolerance}")
        if not self.experiments:
            raise StudyError("an evaluation needs at least one experiment")
        if not all(isinstance(e, PreparedExperiment) for e in self.experiments):
            raise StudyError("experiments must be PreparedExperiment objects")
        for what, names in (
            ("parameter", self.parameter_names),
            ("experiment", [e.name for e in self.experiments]),
        ):
            twice = sorted({n for n in names if list(names).count(n) > 1})
            if twice:
                raise StudyError(f"{what} names must be unique: {', '.join(twice)} repeated")
        owned = [c for e in self.experiments for c in e.copies]
        stray = sorted({c for c in owned if owned.count(c) > 1 or c not in self.parameter_names})
        if stray:
            raise StudyError(
                f"per-experiment parameter(s) {', '.join(stray)} must be parameters of the "
                "evaluation, each of one experiment"
            )
        for i, e in enumerate(self.experiments):  # delay(<input>): an input of every experiment
            names = [*self.start_values, *self.experiment_parameters(i), *e.start_values]
            check_delays(names, e.input_names, f"experiment {e.name!r}")

    def experiment_parameters(self, index: int) -> list[str]:
        """Return what experiment ``index`` sets from a parameter set: FMU variable names.

        The shared parameters, and the FMU variables of its own copies
        (:attr:`PreparedExperiment.copies`); the other experiments' copies not.
        """
        owned, mine = self.copied, self.experiments[index].copies
        return [mine.get(n, n) for n in self.parameter_names if n not in owned or n in mine]

    def experiment_values(self, index: int, parameters: Mapping[str, float]) -> dict[str, float]:
        """Return a parameter set as experiment ``index`` applies it: by FMU variable name.

        Its own copies set their variables; the other experiments' copies are left out.
        """
        owned, mine = self.copied, self.experiments[index].copies
        return {mine.get(k, k): v for k, v in parameters.items() if k not in owned or k in mine}

    @functools.cached_property
    def copied(self) -> frozenset[str]:
        """The parameters that are some experiment's own copy (computed once per spec).

        :meth:`experiment_values` runs once per simulation of a study with copies.
        """
        return frozenset(c for e in self.experiments for c in e.copies)

    def head(self, fraction: float, min_samples: int = 20) -> EvaluationSpec:
        """Return this spec with each experiment cut to the first ``fraction`` of its samples.

        Every experiment keeps at least ``min_samples`` samples (all, if it has fewer), and
        its weights and noise scales: the cost of a shortened spec is the same sum over
        fewer samples. The adaptive search scores such "horizons" to follow a minimum
        from short data, where an oscillating model's cost has few valleys, to the full
        record (:mod:`tsid_fmu.search.local.adaptive`).
        """
        if not 0 < fraction <= 1:
            raise StudyError(f"fraction must be in (0, 1], got {fraction}")
        cut = []
        for e in self.experiments:
            n = len(e.time)
            k = min(n, max(min_samples, math.ceil(fraction * n)))
            windows = e.windows
            if windows:  # the first fraction of the scored samples
                k, windows = head_ranges(windows, n, fraction, min_samples)
            cut.append(
                dataclasses.replace(
                    e,
                    windows=windows,
                    window_weights=e.window_weights[: len(windows)],
                    time=e.time[:k],
                    inputs=None if e.inputs is None else e.inputs[:k],
                    measured=e.measured[:k],
                    noisy_inputs=tuple(a[:k] for a in e.noisy_inputs),
                )
            )
        return dataclasses.replace(self, experiments=tuple(cut))

    @property
    def n_replicates(self) -> int:
        """Replicates per parameter set: 1 + the most noisy inputs of any experiment."""
        return 1 + max(len(e.noisy_inputs) for e in self.experiments)

    @property
    def n_simulations(self) -> int:
        """Most simulations one parameter set needs (experiments times replicates)."""
        n = self.n_replicates
        return sum(sum(s == r for r, s in enumerate(e.replicate_plan(n))) for e in self.experiments)

    def key(self, parameters: Mapping[str, float]) -> tuple[float, ...]:
        """Return a parameter set as the tuple of its float values, in parameter order.

        This tuple is what evaluators memoise by, and the set a simulation receives.

        Raises
        ------
        StudyError
            A parameter is missing, not a number, or not one of ``parameter_names``.
        """
        unknown = [n for n in parameters if n not in self.parameter_names]
        if unknown:
            raise StudyError(
                f"unknown parameter {unknown[0]!r} in a parameter set; the evaluation's "
                f"parameters are {', '.join(self.parameter_names) or 'none'}"
            )
        try:
            values = [float(parameters[n]) for n in self.parameter_names]
        except KeyError as exc:
            raise StudyError(f"a parameter set has no value for {exc.args[0]!r}") from None
        except (TypeError, ValueError) as exc:
            raise StudyError(f"a parameter value is not a number: {exc}") from None
        # one NaN object for every NaN, so that equal keys compare equal
        return tuple(v if v == v else _NAN for v in values)

    def values(self, key: Sequence[float]) -> dict[str, float]:
        """Return the parameter set of a :meth:`key` as a mapping."""
        return dict(zip(self.parameter_names, key, strict=True))
