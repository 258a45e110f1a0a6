"""What a study is: the FMU, the parameters, the experiments and the method.

Scripts and notebooks build a :class:`Study` directly; :meth:`Study.from_toml` reads
one from a TOML file such as::

    [study]
    name = "LSEA SISO"
    fmu = "../../fmus/LSEA_SISO.fmu"          # relative to the study file
    start_values = { V_z = 0.001 }             # fixed FMU parameters

    [data]                                     # or several [[experiments]]
    file = "measured.csv"
    derived = { F_o = "F_of - F_or" }          # channels computed from columns
    inputs = { F_m = "F_m" }                   # FMU input = data column
    outputs = { F_o = "F_o", x_m = "x_m" }     # FMU variable = data column

    [method]
    array = "L25"
    cost = "sse"

    [parameters]
    F_cm = { levels = [10, 50, 80, 100, 110], min = 0, unit = "N" }
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tsid_fmu.doe.arrays import select_array
from tsid_fmu.errors import ArrayError, StudyError
from tsid_fmu.study.checks import check_choice, check_number, check_text
from tsid_fmu.study.choice import Choice, ModelChoice, resolve_choices, variables_of
from tsid_fmu.study.copies import Copy, expand, plan_copies
from tsid_fmu.study.schema import (
    IDENTIFY,
    ContributionOptions,
    Experiment,
    Method,
    Parameter,
    Phase,
)
from tsid_fmu.study.toml import read_study_file, write_study_file

__all__ = ["Study", "fields_of", "load_study"]


def fields_of(study: Study) -> dict[str, Any]:
    """Return the study's fields as keyword arguments of :class:`Study`."""
    return {f.name: getattr(study, f.name) for f in dataclasses.fields(study)}


_METHOD_FIELDS = frozenset(f.name for f in dataclasses.fields(Method))


def _list_of(value: Any, kinds: tuple[type, ...], what: str) -> list[Any]:
    """Return ``value`` as a list of ``kinds``; TypeError naming ``what`` otherwise."""
    names = " or ".join(k.__name__ for k in kinds)
    if isinstance(value, str | bytes | Mapping) or not hasattr(value, "__iter__"):
        raise TypeError(f"Study {what} must be a list of {names}, got {value!r}")
    items = list(value)
    for item in items:
        if not isinstance(item, kinds):
            raise TypeError(
                f"Study {what} must be a list of {names}, got a {type(item).__name__}: {item!r}"
            )
    return items


@dataclass(init=False)
class Study:
    """Everything an identification needs.

    Parameters
    ----------
    fmu : str or Path
        The FMU file (kept resolved: absolute, without ``..`` or links).
    parameters : list of Parameter
        Parameters to identify.
    experiments : list of Experiment
        Measured experiments (one for a SISO study).
    method : Method
        Cost, arrays, replicates, stages and limits.
    start_values : mapping of str to float
        FMU values fixed for every run (not identified).
    interface : {"auto", "cs", "me"}
        FMI interface to simulate with (``method.interface``, where given, replaces it).
    step_size : float, optional
        Communication step; default the data's sample time (``method.step``, where
        given, replaces it).
    name : str
        Label for reports.
    source : Path, optional
        The study file this came from (errors and reports name it). Not compared:
        two studies are equal when they would run alike, wherever they were read.
    phases : list of Phase
        Explicit phases (parameter groups identified in turn; MISO paper).
    contribution : ContributionOptions
        Plan the phases from the MISO paper's contribution analyses.
    choices : list of Choice
        Discrete factors (FMU Integer, Boolean or Enumeration variables) whose value is
        chosen from the data with the Real parameters (structure identification,
        :mod:`tsid_fmu.search.structure.arrays`). A :class:`Choice` given among ``parameters``
        is moved here.
    variants : ModelChoice, optional
        The choice among FMU files, kept where the structure is fixed (``choices``
        emptied, its number in ``start_values``); set from ``choices`` where it is one.
        ``fmu`` is then the file the model description is read from (default: the
        first variant).
    **method_options
        Method settings given directly (``cost="sse"``, ``replicates=2``, ...) replace
        those of ``method``; they read back as properties (``study.cost``). An unknown
        keyword is a ``TypeError``, as in SciPy.
    """

    fmu: Path
    parameters: list[Parameter]
    experiments: list[Experiment]
    method: Method = field(default_factory=Method)
    start_values: dict[str, float] = field(default_factory=dict)
    interface: str = "auto"
    step_size: float | None = None
    name: str = "study"
    source: Path | None = field(default=None, compare=False)  # where it was read, not what
    phases: list[Phase] = field(default_factory=list)
    contribution: ContributionOptions = field(default_factory=ContributionOptions)
    choices: list[Choice] = field(default_factory=list)
    variants: ModelChoice | None = None

    def __init__(
        self,
        fmu: str | Path,
        parameters: list[Parameter],
        experiments: list[Experiment],
        method: Method | None = None,
        start_values: dict[str, float] | None = None,
        interface: str = "auto",
        step_size: float | None = None,
        name: str = "study",
        source: Path | None = None,
        phases: list[Phase] | None = None,
        contribution: ContributionOptions | None = None,
        choices: list[Choice] | None = None,
        variants: ModelChoice | None = None,
        **method_options: Any,
    ) -> None:
        unknown = sorted(set(method_options) - _METHOD_FIELDS)
        if unknown:
            raise TypeError(f"Study() got unexpected keyword argument(s) {', '.join(unknown)}")
        method = method if method is not None else Method()
        if method_options:
            try:
                method = dataclasses.replace(method, **method_options)
            except StudyError as exc:
                where = f"{source}: " if source else ""
                raise StudyError(f"{where}{exc}") from None
        self.fmu = Path(fmu)
        parameters = _list_of(parameters, (Parameter, Choice, ModelChoice), "parameters")
        experiments = _list_of(experiments, (Experiment,), "experiments")
        given = list(parameters) if isinstance(parameters, list | tuple) else parameters
        self.parameters = (
            [p for p in given if not isinstance(p, Choice)] if isinstance(given, list) else given
        )
        moved = [p for p in given if isinstance(p, Choice)] if isinstance(given, list) else []
        self.choices = [*moved, *(choices or [])]
        models = [c for c in self.choices if isinstance(c, ModelChoice)]
        self.variants = models[0] if models else variants
        self.experiments = experiments
        self.method = method
        self.start_values = dict(start_values or {})
        self.interface = interface
        self.step_size = step_size
        self.name = name
        self.source = source
        self.phases = list(phases or [])
        self.contribution = contribution if contribution is not None else ContributionOptions()
        self._validate()

    def _validate(self) -> None:
        where = f"{self.source}: " if self.source else ""
        try:
            self._check()
        except ArrayError as exc:
            raise ArrayError(f"{where}[method] array: {exc}") from None
        except StudyError as exc:
            msg = str(exc)
            raise StudyError(msg if msg.startswith(where) else f"{where}{msg}") from None

    def _check(self) -> None:
        self.fmu = Path(self.fmu).resolve()  # one spelling per file: equal studies compare equal
        if not self.parameters:
            raise StudyError("no parameters to identify")
        names = [p.name for p in self.parameters]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise StudyError(f"parameter(s) listed twice: {', '.join(dupes)}")
        if not self.experiments:
            raise StudyError("no experiment (data) given")
        exp_names = [e.name for e in self.experiments]
        dupes = sorted({n for n in exp_names if exp_names.count(n) > 1})
        if dupes:
            raise StudyError(f"experiment name(s) used twice: {', '.join(dupes)}")
        if not any(e.role == "identify" for e in self.experiments):
            raise StudyError("no experiment has role 'identify'")
        if not isinstance(self.method, Method):
            raise StudyError(f"method must be a Method, got {type(self.method).__name__}")
        self.start_values = {
            k: check_number(v, f"[study] start_values {k}") for k, v in self.start_values.items()
        }
        self.interface = check_choice(self.interface, "interface", ("auto", "cs", "me"))
        check_text(self.name, "[study] name")
        if self.step_size is not None:
            self.step_size = check_number(self.step_size, "[study] step_size")
            if self.step_size < 1e-9:
                raise StudyError(f"[study] step_size must be at least 1e-9 s, got {self.step_size}")
        for key, mine, theirs in (
            ("interface", self.interface if self.interface != "auto" else None, "interface"),
            ("step_size", self.step_size, "step"),
        ):
            other = getattr(self.method, theirs)
            if mine is not None and other is not None and mine != other:
                raise StudyError(
                    f"[study] {key} = {mine!r} and [method] {theirs} = {other!r} disagree; "
                    f"give [method] {theirs} only"
                )
        clash = sorted(set(names) & set(self.start_values))
        if clash:
            raise StudyError(f"{', '.join(clash)} both identified and fixed in start_values")
        own = {p.name for p in self.parameters if p.per_experiment} | {
            n for e in self.experiments for n, how in e.initial.items() if how == IDENTIFY
        }
        for e in self.experiments:
            # an experiment may fix a per-experiment parameter itself (it then has no copy)
            clash = sorted(set(e.initial) & (set(names) - own))
            if clash:
                raise StudyError(
                    f"experiment {e.name!r}: initial {', '.join(map(repr, clash))} is set from "
                    "the data and also identified; give one of them"
                )
            fixed = sorted(n for n in set(e.initial) & set(self.start_values))
            if fixed:  # an experiment's own start_values are refused the same way
                raise StudyError(
                    f"experiment {e.name!r}: initial {', '.join(map(repr, fixed))} is also "
                    "fixed in [study] start_values; give one of them"
                )
        self._check_phases(names, exp_names)
        self._check_choices(names)
        self._check_variants()
        self._check_copies()
        factors = [len(p.levels) for p in self.shared_parameters]  # the arrays' factors
        select_array(factors + [len(c.choices) for c in self.choices], name=self.method.array)

    def _check_copies(self) -> None:
        """Check the per-experiment parameters (:mod:`tsid_fmu.study.copies`)."""
        copies = plan_copies(self.parameters, self.experiments)
        if not copies:
            return
        own = sorted({c.variable for c in copies})
        what = f"per-experiment parameter(s) {', '.join(own)}"
        named = [p.name for p in self.identified_parameters()]
        twice = sorted({n for n in named if named.count(n) > 1})
        if twice:
            raise StudyError(f"{what}: a copy's name is a parameter's too: {', '.join(twice)}")
        if not self.shared_parameters:
            raise StudyError(
                f"{what}: every parameter is per experiment, and the arrays run over the "
                "shared ones; identify at least one shared parameter, or set these from the "
                'data (initial = "from_data...")'
            )
        if self.phases or self.contribution.enabled or self.choices:
            raise StudyError(
                f"{what} cannot be combined with [[phases]], [contribution] or choices yet"
            )
        method = self.method
        if method.refine == "none" or (method.refine == "auto" and method.cost != "sse"):
            raise StudyError(
                f"{what} are fitted by the least-squares refinement, which [method] refine = "
                f"{method.refine!r} with cost = {method.cost!r} does not run; set "
                'refine = "least_squares", or cost = "sse" with refine = "auto"'
            )

    def _check_choices(self, names: list[str]) -> None:
        if not self.choices:
            return
        if not all(isinstance(c, Choice) for c in self.choices):
            raise StudyError("choices must be Choice objects")
        chosen = [c.name for c in self.choices]
        twice = sorted({n for n in chosen if chosen.count(n) > 1} | (set(chosen) & set(names)))
        if twice:
            raise StudyError(f"parameter(s) listed twice: {', '.join(twice)}")
        clash = sorted(set(chosen) & set(self.start_values))
        if clash:
            raise StudyError(f"{', '.join(clash)} both chosen (choices) and fixed in start_values")
        if self.phases or self.contribution.enabled:
            raise StudyError(
                "choices (structure identification) cannot be combined with [[phases]] or "
                "[contribution] yet: identify the structure first, then fix it in start_values"
            )
        # a variable a choice sets may be any variant's (the others lack it: no effect)
        models = [c for c in self.choices if isinstance(c, ModelChoice)]
        resolve_choices(models[0].paths if models else [self.fmu], self.choices)
        try:
            select_array(
                [len(p.levels) for p in self.parameters] + [len(c.choices) for c in self.choices]
            )
        except ArrayError as exc:
            raise ArrayError(
                f"{exc}; with choices, give the Real parameters 3 levels (L18 and L36 take "
                "2- and 3-level columns together, L50 one 2-level column beside 5-level ones)"
            ) from None

    def _check_variants(self) -> None:
        """Check a choice among FMU files against the study.

        ``[study] fmu``, where given, is one of the variants; every parameter is a
        variable of at least one variant (each variant sets those it has). A fixed
        choice (no longer among the choices) is a start value naming a variant.
        """
        v = self.variants
        if v is None:
            return
        if isinstance(v, ModelChoice):
            if self.fmu not in [p.resolve() for p in v.paths]:
                raise StudyError(
                    f"[study] fmu {self.fmu.name} is not one of the FMU variants of "
                    f"{v.name!r} ({', '.join(p.name for p in v.paths)}): leave it out, or "
                    "name one of them"
                )
            unknown = sorted(set(self.parameter_names) - variables_of(v.paths))
            if unknown:
                raise StudyError(
                    f"unknown parameter(s) {', '.join(map(repr, unknown))}: no FMU variant "
                    f"of {v.name!r} has such a variable ({', '.join(p.name for p in v.paths)})"
                )
        if v in self.choices:
            return
        if not isinstance(v, ModelChoice):
            raise StudyError(f"variants must be a ModelChoice, got {type(v).__name__}")
        value = self.start_values.get(v.name)
        if value not in v.values:
            raise StudyError(
                f"the FMU variant is fixed: [study] start_values {v.name} must be one of "
                f"{[int(x) for x in v.values]} ({', '.join(v.labels)}), got {value!r}"
            )

    def _check_phases(self, names: list[str], exp_names: list[str]) -> None:
        for i, ph in enumerate(self.phases):
            ph.name = check_text(ph.name or f"phase {i + 1}", f"[[phases]] #{i + 1} name")
            unknown = sorted(set(ph.parameters) - set(names))
            if unknown or not ph.parameters:
                raise StudyError(
                    f"{ph.name}: parameters {unknown or '[]'} are not study parameters"
                )
            bad = sorted(set(ph.experiments) - set(exp_names))
            if bad:
                raise StudyError(f"{ph.name}: unknown experiments {bad}; have {exp_names}")
        unknown_values = sorted(set(self.contribution.values) - set(names))
        if unknown_values:
            raise StudyError(f"[contribution] values for unknown {unknown_values}")

    def __getattr__(self, name: str) -> Any:
        # method settings read as attributes of the study: study.cost, study.seed, ...
        if name in _METHOD_FIELDS and "method" in self.__dict__:
            return getattr(self.__dict__["method"], name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def parameter_names(self) -> list[str]:
        """Names of the identified (Real) parameters, in study order.

        A per-experiment parameter is named by its copies, ``name[<experiment>]``.
        """
        return [p.name for p in self.identified_parameters()]

    @property
    def copies(self) -> list[Copy]:
        """The copies of the per-experiment parameters (:mod:`tsid_fmu.study.copies`)."""
        return plan_copies(self.parameters, self.experiments)

    @property
    def shared_parameters(self) -> list[Parameter]:
        """The parameters every experiment shares (those the arrays run over)."""
        own = {c.variable for c in self.copies}
        return [p for p in self.parameters if p.name not in own]

    def identified_parameters(self) -> list[Parameter]:
        """Return the parameters identified: each per-experiment one replaced by its copies."""
        return expand(self.parameters, self.copies)

    @property
    def simulated_fmu(self) -> Path:
        """The FMU file that simulates the study: the fixed variant's, else ``fmu``."""
        v = self.variants
        if v is None or v.name not in self.start_values:
            return self.fmu
        return v.paths[round(self.start_values[v.name])]

    def fmu_values(self, values: Mapping[str, float]) -> dict[str, float]:
        """Return ``values`` as :attr:`simulated_fmu` takes them.

        Without a fixed choice among FMU files, ``values`` as they are; with one, without
        the choice's number and the values of variables that variant does not have.
        """
        v = self.variants
        if v is None or v.name not in self.start_values:
            return dict(values)
        from tsid_fmu.evaluate.variants import variants_of

        index = round(self.start_values[v.name])
        return variants_of(v.name, v.paths).keep(index, values)

    @property
    def choice_names(self) -> list[str]:
        """Names of the discrete factors (:attr:`choices`), in study order."""
        return [c.name for c in self.choices]

    def first_levels(self) -> dict[str, list[float]]:
        """Levels of the first iteration by (identified) parameter name."""
        return {p.name: list(p.levels) for p in self.identified_parameters()}

    def bounds(self) -> dict[str, tuple[float, float]]:
        """Physical bounds by (identified) parameter name."""
        return {p.name: p.bounds for p in self.identified_parameters()}

    def identify_experiments(self) -> list[Experiment]:
        """Return the experiments that are fitted (role ``identify``)."""
        return [e for e in self.experiments if e.role == "identify"]

    def identify_names(self) -> list[str]:
        """Return the names of the experiments that are fitted (role ``identify``)."""
        return [e.name for e in self.identify_experiments()]

    @classmethod
    def from_toml(cls, path: str | Path) -> Study:
        """Read a study from a TOML file.

        Relative paths inside the file are relative to its folder. Every key is
        checked: a misspelt key, a wrong type, a value out of range is a
        :class:`~tsid_fmu.errors.StudyError` naming the file and the key.
        """
        path = Path(path)
        return cls(**read_study_file(path), source=path)

    def to_toml(self, path: str | Path) -> Path:
        """Write the study as TOML that :meth:`from_toml` reads back to an equal study.

        Data given as DataFrames are written as CSV files beside the TOML file.
        """
        return write_study_file(path, fields_of(self))


def load_study(path: str | Path) -> Study:
    """Read a study from a TOML file (the same as :meth:`Study.from_toml`)."""
    return Study.from_toml(path)
