"""Study definitions: what to identify, from which data, with which method.

A study is a plain object (:class:`Study`) that scripts build directly, or that
:func:`load_study` reads from a TOML file such as::

    [study]
    name = "LSEA SISO"
    fmu = "../../fmus/LSEA_SISO.fmu"          # relative to the study file
    start_values = { V_z = 0.001 }             # fixed FMU parameters

    [data]                                     # or several [[experiments]]
    file = "measured.csv"
    time = "time"
    derived = { F_o = "F_of - F_or" }          # channels computed from columns
    inputs = { F_m = "F_m" }                   # FMU input = data column
    outputs = { F_o = "F_o" }                  # FMU output = data column

    [method]
    array = "L25"                              # default: smallest that fits
    cost = "iae"
    replicates = 2
    input_noise = 0.01
    seed = 1
    max_iterations = 12

    [leveling]                                 # see tsid_fmu.leveling.LevelingOptions
    tolerance = 0.005

    [parameters]
    F_cm = { levels = [10, 50, 80, 100, 110], min = 0, unit = "N" }

Every key is checked: a misspelt key, a wrong type, levels outside the bounds are each
a :class:`~tsid_fmu.errors.StudyError` naming the file and the key.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from tsid_fmu.arrays import select_array
from tsid_fmu.errors import ArrayError, StudyError
from tsid_fmu.leveling import LevelingOptions
from tsid_fmu.scoring import COSTS

MAX_REPLICATES = 1000
"""Upper bound on noise replicates per row."""

__all__ = [
    "MAX_REPLICATES",
    "ContributionOptions",
    "Experiment",
    "Parameter",
    "Phase",
    "Study",
    "load_study",
]


@dataclass
class Parameter:
    """An FMU parameter to identify, with its first-iteration levels and bounds.

    Parameters
    ----------
    name : str
        Name of the FMU variable (causality ``parameter``).
    levels : sequence of float
        Levels of the first iteration; any explicit, distinct values (the SISO paper's
        Table I uses uneven ones such as 10, 50, 80, 100, 110).
    min, max : float
        Physical bounds that later levels never cross.
    unit : str
        Unit shown in reports.
    """

    name: str
    levels: list[float]
    min: float = -math.inf
    max: float = math.inf
    unit: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise StudyError(f"parameter name must be a non-empty string, got {self.name!r}")
        try:
            self.levels = [float(v) for v in self.levels]
        except (TypeError, ValueError) as exc:
            raise StudyError(
                f"parameter {self.name!r}: levels must be numbers, got {self.levels!r}"
            ) from exc
        if len(self.levels) < 2:
            raise StudyError(f"parameter {self.name!r}: needs at least 2 levels")
        if any(not math.isfinite(v) for v in self.levels):
            raise StudyError(f"parameter {self.name!r}: levels must be finite numbers")
        if len(set(self.levels)) != len(self.levels):
            raise StudyError(f"parameter {self.name!r}: levels must be distinct, got {self.levels}")
        self.levels = sorted(self.levels)
        if not math.isfinite(self.levels[-1] - self.levels[0]):
            raise StudyError(
                f"parameter {self.name!r}: levels {self.levels} span beyond float range"
            )
        self.min, self.max = float(self.min), float(self.max)
        if self.min >= self.max:
            raise StudyError(f"parameter {self.name!r}: min {self.min} is not below max {self.max}")
        outside = [v for v in self.levels if v < self.min or v > self.max]
        if outside:
            raise StudyError(
                f"parameter {self.name!r}: levels {outside} lie outside the bounds "
                f"[{self.min}, {self.max}]"
            )

    @property
    def bounds(self) -> tuple[float, float]:
        """Physical bounds ``(min, max)``."""
        return (self.min, self.max)


@dataclass
class Experiment:
    """One measured experiment: a data file and how its columns map to the FMU.

    Parameters
    ----------
    data : str or Path or pandas.DataFrame
        The measured data (file path, or a frame for scripts and notebooks).
    inputs : mapping of str to str
        FMU input name -> data column that drives it.
    outputs : mapping of str to str
        FMU output name -> data column it is compared with.
    name : str
        Label used in reports; default the data file's stem.
    time_column : str
        Name of the time column.
    derived : mapping of str to str
        New channel name -> expression over columns, e.g. ``{"F_o": "F_of - F_or"}``.
    weights : mapping of str to float, optional
        Weight of each output in the cost (default 1).
    start_values : mapping of str to float
        FMU values fixed for this experiment only.
    sample_time : float, optional
        Expected sample time; a file with another one is refused.
    role : {"identify", "validate"}
        ``validate`` experiments are not fitted; after identification the model is
        simulated against them and their cost reported (the MISO paper's check with
        both inputs together, its Fig. 18).
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

    def __post_init__(self) -> None:
        if self.weights is not None:
            bad = {k: v for k, v in self.weights.items() if not (math.isfinite(v) and v >= 0)}
            if bad:
                raise StudyError(f"weights must be finite and >= 0, got {bad}")
        if self.sample_time is not None and not (
            math.isfinite(self.sample_time) and self.sample_time > 0
        ):
            raise StudyError(f"sample_time must be a finite time > 0, got {self.sample_time}")
        if self.role not in ("identify", "validate"):
            raise StudyError(f"experiment role must be 'identify' or 'validate', not {self.role!r}")
        if not self.name:
            is_path = isinstance(self.data, (str, Path))
            self.name = Path(self.data).stem if is_path else "experiment"
        if not self.outputs:
            raise StudyError(f"experiment {self.name!r}: no outputs to compare with the data")
        if self.weights is not None:
            unknown = set(self.weights) - set(self.outputs)
            if unknown:
                raise StudyError(
                    f"experiment {self.name!r}: weights given for {sorted(unknown)}, "
                    f"which are not outputs ({sorted(self.outputs)})"
                )


@dataclass
class Phase:
    """One phase of a phased identification: a group of parameters, some experiments.

    Parameters
    ----------
    parameters : list of str
        Parameters identified in this phase; the others stay at their current values.
    experiments : list of str
        Names of the experiments fitted in this phase (default: every ``identify`` one).
    name : str
        Label (default ``phase N``).
    array : str, optional
        Orthogonal array of this phase (default: the smallest that fits).
    max_iterations : int, optional
        Iteration limit of this phase (default: the study's).
    """

    parameters: list[str]
    experiments: list[str] = field(default_factory=list)
    name: str = ""
    array: str | None = None
    max_iterations: int | None = None


@dataclass
class ContributionOptions:
    """Contribution analyses of the MISO paper that plan the phases automatically.

    Parameters
    ----------
    enabled : bool
        Run the input and parameter contribution analyses and identify in phases.
    group_ratio : float
        Gap between the contributions of consecutive parameters that starts a new group
        (see :func:`tsid_fmu.contribution.group_parameters`). Default 1.75.
    min_percent : float
        A parameter contributing less than this (% of error variation) to an
        experiment is left for the next experiment's phases. Default 1.
    values : mapping of str to list of float
        Three values per parameter for the one-at-a-time runs (default: lowest,
        middle and highest first-iteration level).
    compare_ungrouped : bool
        Also identify all parameters in one array on all experiments and report the
        difference in cost and simulations (why grouping exists).
    refine_jointly : bool
        After the phases, one more phase refines all parameters together on all
        identification experiments, from three levels within ``refine_span`` of the
        phase results. Single-input experiments often fix only ratios of parameters (a
        force-only test of a spring-mass plant is unchanged when mass, damping and
        stiffness scale together); fitting the experiments together pins them down.
        Default true.
    refine_span : float
        Relative half-width of the joint refinement's first levels. Default 0.2.
    """

    enabled: bool = False
    group_ratio: float = 1.75
    min_percent: float = 1.0
    values: dict[str, list[float]] = field(default_factory=dict)
    compare_ungrouped: bool = False
    refine_jointly: bool = True
    refine_span: float = 0.2

    def __post_init__(self) -> None:
        if not 0 < self.refine_span < 1:
            raise StudyError(f"refine_span must be between 0 and 1, got {self.refine_span}")
        if not self.group_ratio > 1:
            raise StudyError(f"group_ratio must be > 1, got {self.group_ratio}")
        if not self.min_percent >= 0:
            raise StudyError(f"min_percent must be >= 0, got {self.min_percent}")
        for name, vals in self.values.items():
            if len(vals) != 3 or len(set(vals)) != 3:
                raise StudyError(f"contribution values of {name!r} must be 3 distinct numbers")


@dataclass
class Study:
    """Everything an identification needs.

    Parameters
    ----------
    fmu : str or Path
        The FMU file.
    parameters : list of Parameter
        Parameters to identify.
    experiments : list of Experiment
        Measured experiments (one for a SISO study).
    array : str, optional
        Orthogonal array name (e.g. ``"L25"``); default: the smallest that fits.
    cost : str
        Cost kind (see :data:`tsid_fmu.scoring.COSTS`), default ``"iae"``.
    replicates : int
        Noise replicates per row (S/N over replicates), default 2 as in the SISO paper.
    input_noise : float
        Standard deviation of the white Gaussian noise added to each input for the
        replicates, relative to that input's standard deviation. Default 0.01.
    seed : int
        Seed of the replicate noise, so a study is reproducible.
    max_iterations : int
        Upper bound on iterations, default 12.
    canonical : int
        After the Taguchi iterations, up to this many iterations on canonical factors
        (the principal axes of the local cost surface, see :mod:`tsid_fmu.canonical`)
        for parameters that act only in combination. Default 0 (off). In a phased
        study they follow the joint refinement.
    weighting : {"none", "noise"}
        ``noise`` divides each output's cost by its noise level estimated from the
        measured data (:func:`tsid_fmu.scoring.noise_level`), squared for ``sse`` and
        ``ise``, so outputs and experiments with different noise count as they would in
        a maximum-likelihood fit; ``none`` (default) uses the output weights as given.
    selection : {"auto", "main_effects", "best_run"}
        How the next levels are centred. ``main_effects`` takes each parameter's best
        S/N level (SISO paper); ``best_run`` the levels of the best run seen (MISO paper,
        Table 3); ``auto`` (default) takes the main-effects optimum unless its
        confirmation run is worse than the best run, which shows that interactions
        mislead the additive model, and then continues from the best run.
    leveling : LevelingOptions
        Re-leveling thresholds.
    start_values : mapping of str to float
        FMU values fixed for every run (not identified).
    interface : {"auto", "cs", "me"}
        FMI interface to simulate with.
    step_size : float, optional
        Communication step; default the data's sample time.
    name : str
        Label for reports.
    source : Path, optional
        The study file this came from (errors and reports name it).
    """

    fmu: Path
    parameters: list[Parameter]
    experiments: list[Experiment]
    array: str | None = None
    cost: str = "iae"
    replicates: int = 2
    input_noise: float = 0.01
    seed: int = 0
    max_iterations: int = 12
    selection: str = "auto"
    leveling: LevelingOptions = field(default_factory=LevelingOptions)
    start_values: dict[str, float] = field(default_factory=dict)
    interface: str = "auto"
    step_size: float | None = None
    name: str = "study"
    source: Path | None = None
    phases: list[Phase] = field(default_factory=list)
    contribution: ContributionOptions = field(default_factory=ContributionOptions)
    max_reruns: int = 2
    canonical: int = 0
    weighting: str = "none"

    def __post_init__(self) -> None:
        where = f"{self.source}: " if self.source else ""
        self.fmu = Path(self.fmu)
        if not self.parameters:
            raise StudyError(f"{where}no parameters to identify")
        names = [p.name for p in self.parameters]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise StudyError(f"{where}parameter(s) listed twice: {', '.join(dupes)}")
        if not self.experiments:
            raise StudyError(f"{where}no experiment (data) given")
        if self.cost.lower() not in COSTS:
            raise StudyError(
                f"{where}unknown cost {self.cost!r}; choose one of {', '.join(sorted(COSTS))}"
            )
        self.cost = self.cost.lower()
        if int(self.replicates) != self.replicates or not 1 <= self.replicates <= MAX_REPLICATES:
            raise StudyError(
                f"{where}[method] replicates must be an integer from 1 to {MAX_REPLICATES}, "
                f"got {self.replicates}"
            )
        if int(self.seed) != self.seed or self.seed < 0:
            raise StudyError(f"{where}[method] seed must be an integer >= 0, got {self.seed}")
        if self.step_size is not None and not (
            math.isfinite(self.step_size) and self.step_size >= 1e-9
        ):
            raise StudyError(
                f"{where}[study] step_size must be a finite time of at least 1e-9 s, "
                f"got {self.step_size}"
            )
        bad_start = {k: v for k, v in self.start_values.items() if not math.isfinite(v)}
        if bad_start:
            raise StudyError(f"{where}[study] start_values must be finite numbers: {bad_start}")
        if not (self.input_noise >= 0 and math.isfinite(self.input_noise)):
            raise StudyError(f"{where}input_noise must be >= 0, got {self.input_noise}")
        if int(self.max_iterations) != self.max_iterations or self.max_iterations < 1:
            raise StudyError(
                f"{where}max_iterations must be a positive integer, got {self.max_iterations}"
            )
        if int(self.canonical) != self.canonical or self.canonical < 0:
            raise StudyError(
                f"{where}canonical must be a non-negative integer, got {self.canonical}"
            )
        if self.weighting not in ("none", "noise"):
            raise StudyError(f'{where}weighting must be "none" or "noise", got {self.weighting!r}')
        if self.selection not in ("auto", "main_effects", "best_run"):
            raise StudyError(
                f"{where}selection must be 'auto', 'main_effects' or 'best_run', "
                f"not {self.selection!r}"
            )
        if self.interface not in ("auto", "cs", "me"):
            raise StudyError(
                f"{where}interface must be 'auto', 'cs' or 'me', not {self.interface!r}"
            )
        exp_names = [e.name for e in self.experiments]
        dupes = sorted({n for n in exp_names if exp_names.count(n) > 1})
        if dupes:
            raise StudyError(f"{where}experiment name(s) used twice: {', '.join(dupes)}")
        if not any(e.role == "identify" for e in self.experiments):
            raise StudyError(f"{where}no experiment has role 'identify'")
        for i, ph in enumerate(self.phases):
            ph.name = ph.name or f"phase {i + 1}"
            unknown = sorted(set(ph.parameters) - set(names))
            if unknown or not ph.parameters:
                raise StudyError(
                    f"{where}{ph.name}: parameters {unknown or '[]'} are not study parameters"
                )
            bad = sorted(set(ph.experiments) - set(exp_names))
            if bad:
                raise StudyError(f"{where}{ph.name}: unknown experiments {bad}; have {exp_names}")
        unknown_values = sorted(set(self.contribution.values) - set(names))
        if unknown_values:
            raise StudyError(f"{where}[contribution] values for unknown {unknown_values}")
        clash = sorted(set(names) & set(self.start_values))
        if clash:
            raise StudyError(f"{where}{', '.join(clash)} both identified and fixed in start_values")
        try:
            select_array([len(p.levels) for p in self.parameters], name=self.array)
        except ArrayError as exc:
            raise ArrayError(f"{where}[method] array: {exc}") from None

    @property
    def parameter_names(self) -> list[str]:
        """Names of the identified parameters, in study order."""
        return [p.name for p in self.parameters]

    def first_levels(self) -> dict[str, list[float]]:
        """Levels of the first iteration by parameter name."""
        return {p.name: list(p.levels) for p in self.parameters}

    def bounds(self) -> dict[str, tuple[float, float]]:
        """Physical bounds by parameter name."""
        return {p.name: p.bounds for p in self.parameters}


# --------------------------------------------------------------------------- TOML

_TOP = {
    "study", "data", "experiments", "method", "leveling", "parameters", "phases",
    "contribution",
}  # fmt: skip
_PHASE = {"name", "parameters", "experiments", "array", "max_iterations"}
_CONTRIB = {
    "enabled", "group_ratio", "min_percent", "values", "compare_ungrouped", "refine_jointly",
    "refine_span",
}  # fmt: skip
_STUDY = {"name", "fmu", "start_values", "interface", "step_size"}
_DATA = {
    "file", "name", "time", "derived", "inputs", "outputs", "weights", "start_values",
    "sample_time", "role",
}  # fmt: skip
_METHOD = {
    "array", "cost", "replicates", "input_noise", "seed", "max_iterations", "selection",
    "max_reruns", "canonical", "weighting",
}  # fmt: skip
_PARAM = {"levels", "min", "max", "unit"}


def load_study(path: str | Path) -> Study:
    """Read a study from a TOML file.

    Parameters
    ----------
    path : str or Path
        The study file. Relative paths inside it are relative to its folder.

    Returns
    -------
    Study
        The validated study.

    Raises
    ------
    StudyError
        If the file is missing, is not TOML, or any key is unknown, mistyped or out of
        range; the message names the file and the key.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise StudyError(f"{path}: study file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(f"{path}: cannot read the study file ({exc})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"{path}: not valid TOML: {exc}") from None
    return study_from_dict(doc, base_dir=path.parent, source=path)


def study_from_dict(
    doc: Mapping[str, Any], base_dir: str | Path = ".", source: Path | None = None
) -> Study:
    """Build a :class:`Study` from the parsed TOML document (see :func:`load_study`)."""
    base = Path(base_dir)
    where = str(source) if source else "study"
    _check_keys(doc, _TOP, where, "the top level")

    st = _table(doc, "study", where, required=True)
    _check_keys(st, _STUDY, where, "[study]")
    fmu_name = _get(st, "fmu", str, where, "[study]", required=True)
    fmu = (base / fmu_name).resolve() if not Path(fmu_name).is_absolute() else Path(fmu_name)
    if not fmu.is_file():
        raise StudyError(f"{where}: [study] fmu: no such file {fmu}")

    if "data" in doc and "experiments" in doc:
        raise StudyError(f"{where}: give either [data] or [[experiments]], not both")
    if "data" in doc:
        raw_exps = [_table(doc, "data", where, required=True)]
        labels = ["[data]"]
    else:
        raw = doc.get("experiments")
        if not isinstance(raw, list) or not raw or not all(isinstance(e, dict) for e in raw):
            raise StudyError(f"{where}: needs a [data] table or one or more [[experiments]]")
        raw_exps = raw
        labels = [f"[[experiments]] #{i + 1}" for i in range(len(raw))]
    experiments = [
        _experiment(e, base, where, label, i)
        for i, (e, label) in enumerate(zip(raw_exps, labels, strict=True))
    ]

    method = _table(doc, "method", where)
    _check_keys(method, _METHOD, where, "[method]")
    lev = _table(doc, "leveling", where)
    lev_keys = {f.name for f in fields(LevelingOptions)}
    _check_keys(lev, lev_keys, where, "[leveling]")
    lev_types = {
        "significance_db": float, "tolerance": float, "shrink": float, "n_levels": int,
        "refine": bool, "selective": bool, "scale": str, "log_ratio": float,
        "min_contribution": float, "expand": float,
    }  # fmt: skip
    lev_args = {k: _get(lev, k, lev_types[k], where, "[leveling]") for k in lev}
    try:
        leveling = LevelingOptions(**lev_args)
    except StudyError as exc:
        raise StudyError(f"{where}: [leveling] {exc}") from None

    params_doc = _table(doc, "parameters", where, required=True)
    parameters = []
    for name, spec in params_doc.items():
        label = f"[parameters] {name}"
        if not isinstance(spec, dict):
            raise StudyError(
                f"{where}: {label} must be a table such as {{ levels = [1, 2, 3] }}, got {spec!r}"
            )
        _check_keys(spec, _PARAM, where, label)
        levels = _get(spec, "levels", list, where, label, required=True)
        try:
            parameters.append(
                Parameter(
                    name=name,
                    levels=levels,
                    min=_get(spec, "min", float, where, label, default=-math.inf),
                    max=_get(spec, "max", float, where, label, default=math.inf),
                    unit=_get(spec, "unit", str, where, label, default=""),
                )
            )
        except StudyError as exc:
            raise StudyError(f"{where}: {exc}") from None

    phases = []
    raw_phases = doc.get("phases", [])
    if not isinstance(raw_phases, list) or not all(isinstance(p, dict) for p in raw_phases):
        raise StudyError(f"{where}: phases must be given as [[phases]] tables")
    for i, ph in enumerate(raw_phases):
        label = f"[[phases]] #{i + 1}"
        _check_keys(ph, _PHASE, where, label)
        plist = _get(ph, "parameters", list, where, label, required=True)
        elist = _get(ph, "experiments", list, where, label, default=[])
        if not all(isinstance(x, str) for x in plist + elist):
            raise StudyError(f"{where}: {label} parameters and experiments must be names")
        phases.append(
            Phase(
                parameters=plist,
                experiments=elist,
                name=_get(ph, "name", str, where, label, default=""),
                array=_get(ph, "array", str, where, label, default=None),
                max_iterations=_get(ph, "max_iterations", int, where, label, default=None),
            )
        )
    ct = _table(doc, "contribution", where)
    _check_keys(ct, _CONTRIB, where, "[contribution]")
    raw_values = ct.get("values", {})
    if not isinstance(raw_values, dict) or not all(
        isinstance(v, list) and all(isinstance(x, (int, float)) for x in v)
        for v in raw_values.values()
    ):
        raise StudyError(f"{where}: [contribution] values must map names to lists of numbers")
    try:
        contribution = ContributionOptions(
            enabled=_get(ct, "enabled", bool, where, "[contribution]", default=bool(ct)),
            group_ratio=_get(ct, "group_ratio", float, where, "[contribution]", default=1.75),
            min_percent=_get(ct, "min_percent", float, where, "[contribution]", default=1.0),
            values={k: [float(x) for x in v] for k, v in raw_values.items()},
            compare_ungrouped=_get(
                ct, "compare_ungrouped", bool, where, "[contribution]", default=False
            ),
            refine_jointly=_get(ct, "refine_jointly", bool, where, "[contribution]", default=True),
            refine_span=_get(ct, "refine_span", float, where, "[contribution]", default=0.2),
        )
    except StudyError as exc:
        raise StudyError(f"{where}: [contribution] {exc}") from None

    try:
        return Study(
            fmu=fmu,
            parameters=parameters,
            experiments=experiments,
            array=_get(method, "array", str, where, "[method]", default=None),
            cost=_get(method, "cost", str, where, "[method]", default="iae"),
            replicates=_get(method, "replicates", int, where, "[method]", default=2),
            input_noise=_get(method, "input_noise", float, where, "[method]", default=0.01),
            seed=_get(method, "seed", int, where, "[method]", default=0),
            max_iterations=_get(method, "max_iterations", int, where, "[method]", default=12),
            selection=_get(method, "selection", str, where, "[method]", default="auto"),
            leveling=leveling,
            start_values=_number_map(st, "start_values", where, "[study]"),
            interface=_get(st, "interface", str, where, "[study]", default="auto"),
            step_size=_get(st, "step_size", float, where, "[study]", default=None),
            name=_get(st, "name", str, where, "[study]", default=fmu.stem),
            source=source,
            phases=phases,
            contribution=contribution,
            max_reruns=_get(method, "max_reruns", int, where, "[method]", default=2),
            canonical=_get(method, "canonical", int, where, "[method]", default=0),
            weighting=_get(method, "weighting", str, where, "[method]", default="none"),
        )
    except StudyError as exc:
        msg = str(exc)
        raise StudyError(msg if msg.startswith(where) else f"{where}: {msg}") from None


def _experiment(e: Mapping[str, Any], base: Path, where: str, label: str, index: int) -> Experiment:
    _check_keys(e, _DATA, where, label)
    file = _get(e, "file", str, where, label, required=True)
    data_path = Path(file) if Path(file).is_absolute() else (base / file)
    inputs = _string_map(e, "inputs", where, label)
    outputs = _string_map(e, "outputs", where, label)
    if not outputs:
        raise StudyError(f'{where}: {label} needs outputs = {{ FMU_OUTPUT = "column" }}')
    weights = _number_map(e, "weights", where, label) if "weights" in e else None
    try:
        return Experiment(
            data=data_path,
            inputs=inputs,
            outputs=outputs,
            name=_get(e, "name", str, where, label, default=data_path.stem or f"exp{index + 1}"),
            time_column=_get(e, "time", str, where, label, default="time"),
            derived=_string_map(e, "derived", where, label),
            weights=weights,
            start_values=_number_map(e, "start_values", where, label),
            sample_time=_get(e, "sample_time", float, where, label, default=None),
            role=_get(e, "role", str, where, label, default="identify"),
        )
    except StudyError as exc:
        raise StudyError(f"{where}: {label}: {exc}") from None


def _check_keys(table: Mapping[str, Any], allowed: set[str], where: str, label: str) -> None:
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(key, sorted(allowed), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise StudyError(
                f"{where}: unknown key {key!r} in {label}{hint} "
                f"(allowed: {', '.join(sorted(allowed))})"
            )


def _table(doc: Mapping[str, Any], key: str, where: str, required: bool = False) -> dict:
    value = doc.get(key)
    if value is None:
        if required:
            raise StudyError(f"{where}: missing table [{key}]")
        return {}
    if not isinstance(value, dict):
        raise StudyError(f"{where}: [{key}] must be a table, got {type(value).__name__}")
    return value


_TYPE_NAMES = {float: "a number", int: "an integer", str: "a string", bool: "true or false",
               list: "a list"}  # fmt: skip


def _get(
    table: Mapping[str, Any],
    key: str,
    kind: type,
    where: str,
    label: str,
    *,
    required: bool = False,
    default: Any = None,
) -> Any:
    if key not in table:
        if required:
            raise StudyError(f"{where}: {label} is missing the key {key!r}")
        return default
    value = table[key]
    ok = (
        isinstance(value, (int, float)) and not isinstance(value, bool)
        if kind is float
        else isinstance(value, int) and not isinstance(value, bool)
        if kind is int
        else isinstance(value, kind)
    )
    if not ok:
        raise StudyError(
            f"{where}: {label} {key} must be {_TYPE_NAMES.get(kind, kind.__name__)}, got {value!r}"
        )
    return float(value) if kind is float else value


def _string_map(table: Mapping[str, Any], key: str, where: str, label: str) -> dict[str, str]:
    value = table.get(key, {})
    if not isinstance(value, dict) or not all(isinstance(v, str) for v in value.values()):
        raise StudyError(f"{where}: {label} {key} must be a table of strings, got {value!r}")
    return dict(value)


def _number_map(table: Mapping[str, Any], key: str, where: str, label: str) -> dict[str, float]:
    value = table.get(key, {})
    if not isinstance(value, dict) or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value.values()
    ):
        raise StudyError(f"{where}: {label} {key} must be a table of numbers, got {value!r}")
    return {k: float(v) for k, v in value.items()}
