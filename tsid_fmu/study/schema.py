"""The parts of a study: parameters, experiments, method, phases, contribution options.

Scripts and notebooks build these objects directly; :mod:`tsid_fmu.study.toml` reads
and writes them as TOML. Every value is checked when the object is made, so a wrong
study fails at once with a :class:`~tsid_fmu.errors.StudyError` naming the key.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.errors import StudyError
from tsid_fmu.evaluate.cost import COSTS
from tsid_fmu.study.checks import (
    DEFAULT_SAMPLED,
    check_bound,
    check_choice,
    check_number,
    check_text,
    check_uncertainty,
    check_weight_size,
    check_whole,
    check_windows,
)
from tsid_fmu.study.phasing import ContributionOptions, Phase

__all__ = [
    "FROM_DATA",
    "IDENTIFY",
    "MAX_REPLICATES",
    "ContributionOptions",
    "Experiment",
    "Method",
    "Parameter",
    "Phase",
    "initial_column",
]

MAX_REPLICATES = 1000
"""Upper bound on replicates per row."""


@dataclass
class Parameter:
    """An FMU parameter to identify, with its first-iteration levels and bounds.

    Parameters
    ----------
    name : str
        Name of the FMU variable: a parameter (causality ``parameter``), or a continuous
        state whose start value is its initial value (``initial="exact"``), to identify
        that initial value. ``"delay(<input>)"`` is no FMU variable: it delays that input
        by so many seconds before each simulation (:mod:`tsid_fmu.fmu.delay`).
    levels : sequence of float
        Levels of the first iteration; any explicit, distinct values (the SISO paper's
        Table I uses uneven ones such as 10, 50, 80, 100, 110).
    min, max : float
        Physical bounds that later levels never cross.
    unit : str
        Unit shown in reports.
    per_experiment : bool
        Identify one value per identification experiment (a nuisance parameter such
        as each test's initial position) instead of one shared by all: the study
        identifies a copy ``name[<experiment>]`` for each experiment that does not fix
        the variable itself (:mod:`tsid_fmu.study.copies`).
    """

    name: str
    levels: list[float]
    min: float = -math.inf
    max: float = math.inf
    unit: str = ""
    per_experiment: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.isprintable() or not self.name:
            raise StudyError(f"parameter name must be a non-empty printable string: {self.name!r}")
        if isinstance(self.levels, str | bytes) or not hasattr(self.levels, "__iter__"):
            raise StudyError(f"parameter {self.name!r}: levels must be a list of numbers")
        self.levels = sorted(
            check_number(v, f"parameter {self.name!r}: levels") for v in self.levels
        )
        if len(self.levels) < 2:
            raise StudyError(f"parameter {self.name!r}: needs at least 2 levels")
        if len(set(self.levels)) != len(self.levels):
            raise StudyError(f"parameter {self.name!r}: levels must be distinct, got {self.levels}")
        if not math.isfinite(self.levels[-1] - self.levels[0]):
            raise StudyError(
                f"parameter {self.name!r}: levels {self.levels} span beyond float range"
            )
        self.min = check_bound(self.min, f"parameter {self.name!r}: min", -math.inf)
        self.max = check_bound(self.max, f"parameter {self.name!r}: max", math.inf)
        if self.min >= self.max:
            raise StudyError(f"parameter {self.name!r}: min {self.min} is not below max {self.max}")
        outside = [v for v in self.levels if v < self.min or v > self.max]
        if outside:
            raise StudyError(
                f"parameter {self.name!r}: levels {outside} lie outside the bounds "
                f"[{self.min}, {self.max}]"
            )
        if not isinstance(self.unit, str):
            raise StudyError(f"parameter {self.name!r}: unit must be a string")
        if not isinstance(self.per_experiment, bool):
            raise StudyError(f"parameter {self.name!r}: per_experiment must be true or false")

    @property
    def bounds(self) -> tuple[float, float]:
        """Physical bounds ``(min, max)``."""
        return (self.min, self.max)


@dataclass
class Experiment:
    """One measured experiment: data and how its columns map to the FMU.

    Parameters
    ----------
    data : str or Path or pandas.DataFrame
        The measured data (file path, or a frame for scripts and notebooks). A path is
        kept resolved (absolute, without ``..`` or links), as read from the current
        folder.
    inputs : mapping of str to str
        FMU input variable -> data column (or derived channel) that drives it.
    outputs : mapping of str to str
        FMU variable -> data column (or derived channel) it is compared with.
    name : str
        Label used in reports; default the data file's stem.
    time_column : str
        Name of the time column.
    derived : mapping of str to str
        New channel -> expression over columns (see :mod:`tsid_fmu.data.expressions`),
        e.g. ``{"F_o": "F_of - F_or", "v_o": "der(x_o)"}``.
    weights : mapping of str to float, optional
        Weight of each output's cost (default 1), on top of the study's weighting.
    start_values : mapping of str to float
        FMU values fixed for this experiment only.
    sample_time : float, optional
        Expected sample time; a file with another one is refused.
    role : {"identify", "validate"}
        ``validate`` experiments are not fitted; after identification the model is
        simulated against them and their cost reported (the MISO paper's check with
        both inputs together).
    hold : mapping of str to str
        How each input's samples are held between communication points: ``"previous"``
        (a controller's output, the default) or ``"linear"`` (a measured continuous
        signal, interpolated).
    noise : mapping of str to float
        Known noise standard deviation of an output's sensor (e.g. an encoder's
        quantisation, ``step / sqrt(12)``), in the output's units; outputs not listed
        get an estimate from the data (:func:`tsid_fmu.evaluate.cost.noise_level`).
    windows : list of [t0, t1]
        Time spans (seconds) that are scored, in time order and disjoint; default the
        whole record. The whole record is still simulated from its start: a window only
        chooses the samples that the cost, the residuals, the noise estimate and every
        diagnostic see (:mod:`tsid_fmu.evaluate.windows`).
    warmup : float or list of float
        Seconds at the start of each window (of the record, without windows) that are
        simulated but not scored; one value for every window or one per window.
    window_weights : list of float, optional
        Weight of each window's cost (default 1 each).
    initial : mapping of str to str
        Initial states set from the data: FMU variable -> ``"from_data:<column>"`` (the
        column's, or derived channel's, value at the record's first sample) or
        ``"from_data"`` (the column this experiment compares that variable with, when
        it is one of its outputs). The variable must be settable before initialisation:
        a parameter (such as a state's ``x0``) or a state whose start value is its
        initial value (``initial="exact"``). ``"identify"`` identifies the value per
        experiment instead: the study's parameter of that name (which gives its range)
        becomes a per-experiment parameter (:mod:`tsid_fmu.study.copies`).
    """

    data: Any
    inputs: dict[str, str] = field(default_factory=dict)
    outputs: dict[str, str] = field(default_factory=dict)
    name: str = ""
    time_column: str = "time"
    derived: dict[str, str] = field(default_factory=dict)
    weights: dict[str, float] | None = None
    start_values: dict[str, float] = field(default_factory=dict)
    sample_time: float | None = None
    role: str = "identify"
    hold: dict[str, str] = field(default_factory=dict)
    noise: dict[str, float] = field(default_factory=dict)
    windows: list[list[float]] = field(default_factory=list)
    warmup: float | list[float] = 0.0
    window_weights: list[float] | None = None
    initial: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.data, str | os.PathLike) and not hasattr(self.data, "columns"):
            raise TypeError(
                f"Experiment data must be a file path or a pandas DataFrame, got {self.data!r}"
            )
        for key in ("inputs", "outputs", "derived", "start_values", "hold", "noise", "initial"):
            value = getattr(self, key)
            if value is None:  # None for "none", as a Python user writes it
                setattr(self, key, {})
            elif not isinstance(value, Mapping):
                raise TypeError(
                    f"Experiment {key} must be a mapping (dict), got {type(value).__name__}: "
                    f"{value!r}"
                )
            else:
                setattr(self, key, dict(value))
        if isinstance(self.data, str | os.PathLike):
            # one spelling per file, so that equal studies compare equal (and the TOML
            # written by Study.to_toml reads back to the same study)
            self.data = Path(self.data).resolve()
        if not self.name:
            is_path = isinstance(self.data, Path)
            self.name = self.data.stem if is_path else "experiment"
        where = f"experiment {self.name!r}"
        check_text(self.name, f"{where}: name")
        if not self.outputs:
            raise StudyError(f"{where}: no outputs to compare with the data")
        if self.weights is not None:
            self.weights = {
                k: check_number(v, f"{where}: weights of {k}") for k, v in self.weights.items()
            }
            if any(v < 0 for v in self.weights.values()):
                raise StudyError(f"{where}: weights must be >= 0, got {self.weights}")
            check_weight_size(self.weights.values(), f"{where}: weights")
            unknown = set(self.weights) - set(self.outputs)
            if unknown:
                raise StudyError(
                    f"{where}: weights given for {sorted(unknown)}, which are not outputs "
                    f"({sorted(self.outputs)})"
                )
            if all(self.weights.get(k, 1.0) == 0 for k in self.outputs):
                raise StudyError(f"{where}: every output has weight 0, so every cost would be 0")
        if self.sample_time is not None:
            self.sample_time = check_number(self.sample_time, f"{where}: sample_time")
            if self.sample_time <= 0:
                raise StudyError(f"{where}: sample_time must be > 0, got {self.sample_time}")
        self.role = check_choice(self.role, f"{where}: role", ("identify", "validate"))
        self.start_values = {
            k: check_number(v, f"{where}: start value {k}") for k, v in self.start_values.items()
        }
        self.noise = {k: check_number(v, f"{where}: noise of {k}") for k, v in self.noise.items()}
        bad = sorted(k for k, v in self.noise.items() if k not in self.outputs or v <= 0)
        if bad:
            raise StudyError(f"{where}: noise must be > 0 and given for outputs only: {bad}")
        for name, how in self.hold.items():
            if name not in self.inputs:
                raise StudyError(f"{where}: hold given for {name!r}, which is not an input")
            check_choice(how, f"{where}: hold of {name}", ("previous", "linear"))
        self.windows, self.warmup, self.window_weights = check_windows(
            self.windows, self.warmup, self.window_weights, where
        )
        self._check_initial(where)

    def _check_initial(self, where: str) -> None:
        for name, how in self.initial.items():
            label = f"{where}: initial {name!r}"
            if name in self.start_values:
                raise StudyError(f"{label} is also fixed in start_values; give one of them")
            if how == IDENTIFY:
                continue
            column = initial_column(self, name)
            if column is None:
                raise StudyError(
                    f'{label} must be "from_data:<column>", "from_data" (for an output) or '
                    f'"identify" (one value per experiment), got {how!r}'
                )
            if not column:
                raise StudyError(
                    f'{label} = "from_data": {name!r} is not an output of this experiment; '
                    'name the column: "from_data:<column>"'
                )


FROM_DATA = "from_data"
"""An experiment's ``initial`` value that sets a state from the data's first sample."""

IDENTIFY = "identify"
"""An experiment's ``initial`` value that identifies the state per experiment."""


def initial_column(experiment: Experiment, name: str) -> str | None:
    """Return the data column that sets the initial value ``name`` of ``experiment``.

    ``""`` for a plain ``"from_data"`` on a variable that is no output of the experiment;
    None for a value that is not ``from_data`` at all.
    """
    how = experiment.initial.get(name)
    if not isinstance(how, str):
        return None
    if how == FROM_DATA:
        return experiment.outputs.get(name, "")
    head, colon, column = how.partition(":")
    return column.strip() if head == FROM_DATA and colon and column.strip() else None


@dataclass
class Method:
    """How to identify: the cost, the arrays, replicates, stages and limits.

    Parameters
    ----------
    array : str, optional
        Orthogonal array (e.g. ``"L25"``) of the first levels, and of later iterations
        whose factors it fits; default (and otherwise) the smallest that fits.
    cost : str
        The study's one objective (:data:`tsid_fmu.evaluate.cost.COSTS`): ``"sse"``
        (default, the MISO paper's; with ``weighting = "noise"`` the Gaussian
        maximum-likelihood cost, which the intervals and the refinement stage assume),
        ``"iae"`` (the SISO paper's), ``"ise"``, ``"rmse"``, ``"nrmse"``. Every stage
        minimises it and compares parameter sets by it on the measured inputs. The
        defaults of ``cost``, ``weighting`` and ``replicates`` are those ``tsid init``
        writes.
    weighting : {"noise", "none"}
        ``noise`` (default) divides each output's cost by its noise level (squared for
        ``sse``/``ise``), as a maximum-likelihood fit does: the experiment's ``noise``
        where given (a sensor's known resolution), else estimated from the data; an
        output that shows no noise (simulated data without noise) is refused: give its
        ``noise`` or ``weights``, or set ``weighting = "none"``. ``none`` uses the output
        weights as given.
    replicates : int
        Runs per array row: the measured inputs, plus ``replicates - 1`` copies with
        white noise added to the inputs (the SISO paper's robustness step, with 2; its
        S/N is over all of them). Default 1: the measured inputs only.
    input_noise : float
        Standard deviation of the replicates' input noise, relative to each input's
        standard deviation. Default 0.01.
    seed : int
        Seed of the replicate noise.
    max_iterations : int
        Most Taguchi iterations (arrays) per stage or phase. Default 20.
    max_simulations : int, optional
        Most simulations of the Taguchi stage (checked between iterations).
    selection : {"auto", "main_effects", "best_run"}
        Where the next levels are centred: ``main_effects`` on the predicted optimum of
        the S/N main effects (SISO paper), ``best_run`` on the best run (MISO paper),
        ``auto`` (default) on whichever of the two, and the current centre, has the
        lowest cost.
    rotate : bool
        From the second iteration on, let the factors be the principal axes of the cost
        surface estimated from the array runs (parameters that act in combination become
        one factor). Default true.
    max_reruns : int
        Re-runs from the next-best run when continuing from the best did not lower the
        cost (MISO paper). Default 2.
    refine : {"auto", "least_squares", "none"}
        What follows the Taguchi stage. ``"auto"`` (default): with the ``sse`` cost, the
        adaptive pipeline of :mod:`tsid_fmu.search.local.adaptive` (the Taguchi stage hands
        over to a trust-region least-squares refinement after its first array; an
        answer that is not shown to be an optimum, or a poor fit, sends the search
        back to the arrays and then to restarts from the next-best runs); with
        another cost, as ``"none"``.
        ``"least_squares"``: the Taguchi stage runs to its own end, then the refinement
        (``"sse"`` only). ``"none"``: the Taguchi stage alone, then the local probe test
        of its answer. In every case the study converges (exit status 0) only where a
        stationarity test holds at its answer (:mod:`tsid_fmu.search.verdict`).
    refine_max_nfev : int, optional
        Most simulations of the refinement stage; default ``30 (p + 1)`` times the
        number of identification experiments (about thirty Jacobians).
    start : {"fmu", "centre"}
        The start point the Taguchi stage scores before its first array, beside the
        centre of the first levels (:mod:`tsid_fmu.search.taguchi.start`): ``"fmu"`` (default)
        the FMU's start values of the parameters; ``"centre"`` the centre alone (an FMU
        whose start values are placeholders, or a benchmark whose FMU holds the truth).
    interface : {"auto", "cs", "me"}, optional
        FMI interface to simulate with (the same as ``[study] interface``, which it
        replaces; giving both with different values is an error). ``"auto"`` (the
        default) checks the solver's fidelity at the start point
        (:mod:`tsid_fmu.uncertainty.fidelity`) and uses Model Exchange where the
        Co-Simulation's solver error matters and Model Exchange is closer to an accurate
        solution; else Co-Simulation.
    step : float, optional
        Largest communication step in seconds (Co-Simulation) or the solver's step hint
        (Model Exchange); the same as ``[study] step_size``. Default: the data's sample
        interval.
    tolerance : float
        Relative tolerance of the Model Exchange solver. Default 1e-10: a simulation
        default such as FMPy's 1e-5 leaves errors near or above the noise of good data
        (the solver's absolute tolerance is this times each state's nominal value, often
        1, whatever the state's size), and the parameters absorb them.
    cs_tolerance : float, optional
        Relative tolerance of a Co-Simulation FMU's own solver, passed to
        ``fmi2SetupExperiment`` (``toleranceDefined``) or FMI 3's
        ``fmi3EnterInitializationMode``. Default: none passed, and the FMU's solver
        runs at its exporter's default (Dymola's CS solvers at the tolerance set when the
        FMU was exported), unless the solver-fidelity check at the start point finds that
        default too loose and ``1e-8`` close enough to its reference (a smaller step at
        ``1e-10``): the study then passes ``1e-8`` and says so
        (:func:`~tsid_fmu.uncertainty.fidelity.choose_cs_tolerance`). A value given here
        is kept; the check then proposes a tighter one where it matters.
    fidelity : bool
        Check the solver's fidelity at the start point and at the answer (a few
        simulations with a reference solver each; see ``interface``). Default true.
        ``false`` skips both checks: ``"auto"`` then simulates with Co-Simulation where
        the FMU has it, and ``result.fidelity`` says that nothing was checked.
    uncertainty, uncertainty_replicates : str, int
        Sampled intervals beside the primary ones (:mod:`tsid_fmu.uncertainty.sampled`,
        ``sse`` only): ``"bootstrap"`` (block bootstrap of the residuals) or
        ``"monte_carlo"`` (AR noise), that many re-fits (default 100, at least 20).
        Default ``"analytic"``: none.
    leveling : LevelingOptions
        Re-leveling thresholds and rules.
    """

    array: str | None = None
    cost: str = "sse"
    weighting: str = "noise"
    replicates: int = 1
    input_noise: float = 0.01
    seed: int = 0
    max_iterations: int = 20
    max_simulations: int | None = None
    selection: str = "auto"
    rotate: bool = True
    max_reruns: int = 2
    refine: str = "auto"
    refine_max_nfev: int | None = None
    start: str = "fmu"
    interface: str | None = None
    step: float | None = None
    tolerance: float = 1e-10
    cs_tolerance: float | None = None
    fidelity: bool = True
    uncertainty: str = "analytic"
    uncertainty_replicates: int = DEFAULT_SAMPLED
    leveling: LevelingOptions = field(default_factory=LevelingOptions)

    def __post_init__(self) -> None:
        if not isinstance(self.cost, str) or self.cost.lower() not in COSTS:
            raise StudyError(
                f"unknown cost {self.cost!r}; choose one of {', '.join(sorted(COSTS))}"
            )
        self.cost = self.cost.lower()
        if self.weighting not in ("none", "noise"):
            raise StudyError(f'weighting must be "none" or "noise", got {self.weighting!r}')
        self.replicates = check_whole(self.replicates, "replicates", 1, MAX_REPLICATES)
        self.input_noise = check_number(self.input_noise, "input_noise")
        if self.input_noise < 0:
            raise StudyError(f"input_noise must be >= 0, got {self.input_noise}")
        self.seed = check_whole(self.seed, "seed", 0)
        self.max_iterations = check_whole(self.max_iterations, "max_iterations", 1)
        if self.max_simulations is not None:
            self.max_simulations = check_whole(self.max_simulations, "max_simulations", 1)
        self.selection = check_choice(
            self.selection, "selection", ("auto", "main_effects", "best_run")
        )
        for flag in ("rotate", "fidelity"):
            if not isinstance(getattr(self, flag), bool):
                raise StudyError(f"{flag} must be true or false, got {getattr(self, flag)!r}")
        self.max_reruns = check_whole(self.max_reruns, "max_reruns", 0)
        self.refine = check_choice(self.refine, "refine", ("auto", "none", "least_squares"))
        if self.refine == "least_squares" and self.cost != "sse":
            raise StudyError(
                f'refine = "least_squares" minimises the sse cost; the study uses {self.cost!r}'
            )
        self.start = check_choice(self.start, "start", ("fmu", "centre"))
        if self.refine_max_nfev is not None:
            self.refine_max_nfev = check_whole(self.refine_max_nfev, "refine_max_nfev", 1)
        if self.interface is not None:
            self.interface = check_choice(self.interface, "interface", ("auto", "cs", "me"))
        if self.step is not None:
            self.step = check_number(self.step, "step")
            if self.step < 1e-9:
                raise StudyError(f"step must be at least 1e-9 s, got {self.step}")
        if not 0 < check_number(self.tolerance, "tolerance") < 1:
            raise StudyError(f"tolerance must be between 0 and 1, got {self.tolerance}")
        if self.cs_tolerance is not None:
            self.cs_tolerance = check_number(self.cs_tolerance, "cs_tolerance")
            if not 0 < self.cs_tolerance < 1:
                raise StudyError(f"cs_tolerance must be between 0 and 1, got {self.cs_tolerance}")
        self.uncertainty, self.uncertainty_replicates = check_uncertainty(
            self.uncertainty, self.uncertainty_replicates, self.cost
        )
        if not isinstance(self.leveling, LevelingOptions):
            raise StudyError("leveling must be a LevelingOptions")
