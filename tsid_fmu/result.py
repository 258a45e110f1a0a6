"""The outcome of an identification, in the style of :class:`scipy.optimize.OptimizeResult`.

The schema is the same for every kind of study (one Taguchi stage, phases, with or
without refinement): ``x`` (an array in the order of ``names``, the order of ``cov``
and ``jac`` too; ``params`` the same values by name, each with lmfit's ``stderr``,
``min``, ``max`` and tsid's ``interval`` and ``unit``), ``fun`` (always the study's
cost on the measured inputs of its identification experiments), ``nfev``,
``success``, ``status`` (the exit status), ``message``, the ``stages`` in order, and
the ``intervals``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import tsid_fmu.result_views as result_views
from tsid_fmu.errors import TsidError
from tsid_fmu.params import Parameters, describe
from tsid_fmu.result_mapping import ResultMapping, unshadowed
from tsid_fmu.search.record import IterationRecord
from tsid_fmu.search.stage import StageKind, StageResult
from tsid_fmu.study.definition import Study
from tsid_fmu.trail.files import strict
from tsid_fmu.uncertainty.intervals import Uncertainty
from tsid_fmu.uncertainty.sampled import Sampled

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["EXTRA_KEYS", "PAUSED", "RUNS_NOTE", "STATUS", "IdentificationResult", "register_views"]

PAUSED = 3
""":attr:`IdentificationResult.status` of a study paused for review (``--pause-after``)."""

STATUS = {0: "converged", 1: "stopped at a limit", 3: "paused for review"}
"""Meaning of :attr:`IdentificationResult.status`: the exit status of ``tsid identify``."""

RUNS_NOTE = (
    "one row per run of an orthogonal array (a parameter set), simulated on every "
    "identification experiment and replicate; nfev also counts the start points, one "
    "confirmation run per iteration, the refinement and the checks: see "
    "attrs['simulations'] or simulations_frame()"
)
"""What the rows of :meth:`IdentificationResult.to_pandas` are, beside ``nfev``."""

_VIEWS: dict[str, Callable[..., Any]] = {}

EXTRA_KEYS = ("fidelity", "structure", "conformance")
"""Attributes of :class:`IdentificationResult` kept under ``result.json``'s ``"extra"``.

The one place the JSON's ``extra`` is written (:meth:`IdentificationResult.to_dict`) and
read (:func:`tsid_fmu.load.load`); everything else reads the attributes.
"""


def register_views(**views: Callable[..., Any]) -> None:
    """Provide the notebook view and the ``plot_*`` figures of a result.

    The reports sit above this module and read the result; the result does not import
    them. :mod:`tsid_fmu.report.notebook` registers ``result_html``, ``plot_fit``,
    ``plot_convergence``, ``plot_main_effects`` and ``plot_parameters`` when it is
    imported (``import tsid_fmu`` imports it), each called with the result first.
    """
    _VIEWS.update(views)


def _view(name: str) -> Callable[..., Any]:
    try:
        return _VIEWS[name]
    except KeyError:
        raise TsidError(
            f"{name}: the reports are not loaded; import tsid_fmu.report first"
        ) from None


@unshadowed
@dataclass(eq=False)
class IdentificationResult(ResultMapping):
    """What an identification found, and the evidence for it.

    As in :class:`scipy.optimize.OptimizeResult`, :attr:`x` is an array; :attr:`params`
    (lmfit's name) holds the same values by name, and is what the constructor takes.
    :attr:`status` is the exit status ``tsid identify`` ends with, and
    :meth:`fit_report` is the report in lmfit's sections. It is a
    :class:`scipy.optimize.OptimizeResult`: ``res["x"]``, ``res.keys()``.

    Attributes
    ----------
    x : numpy.ndarray
        Identified values in the order of ``names`` (read-only; from ``params``).
    names : list of str
        The parameters, in the study's order.
    params : Parameters
        Identified value of each parameter, by name, in the study's order: each a
        :class:`~tsid_fmu.params.Param`, a float with lmfit's ``value``, ``stderr``,
        ``min``, ``max`` and ``vary``, and ``interval``, ``unit`` and ``weak``.
    fun : float
        The study's cost of ``x`` on the measured inputs of the identification
        experiments (the one objective every stage minimised).
    nfev : int
        Simulations used by the stages (the side-by-side comparison and plots not
        counted).
    success : bool
        True if the last stage converged.
    status : int
        The exit status of ``tsid identify`` (:data:`STATUS`): 0 converged, 1 stopped
        at a limit with a valid result, 3 paused for review.
    message : str
        The verdict in one sentence of at most 200 characters
        (:data:`tsid_fmu.status.MESSAGES`): "converged: the answer is stationary (149
        simulations)", "stopped at a limit (...): the answer may not be the optimum".
    account : list of str
        How the study got there: one line per stage, why it stopped, each clause said
        once, and the stationarity test's verdict (``tsid identify --verbose`` and the
        reports print it; :attr:`messages` has each stage's own message).
    nit : int
        Taguchi iterations (orthogonal arrays) run, over all stages.
    stages : list of StageResult
        The stages in order, each with its own answer, cost, simulations and message.
    intervals : dict
        95 % interval ``[low, high]`` per parameter (``None``: not determined).
    uncertainty : Uncertainty or None
        Standard errors, correlations, determined combinations.
    sampled : Sampled or None
        Bootstrap or Monte Carlo percentile intervals, beside :attr:`intervals` (which
        stay the primary ones), where ``[method] uncertainty`` asks for them; their
        re-fitted values by replicate: ``sampled.to_pandas()``.
    fit : dict
        Cost kinds and fit percentage per experiment and output at ``x``.
    noise : dict
        Noise level of each experiment's measured outputs: the one the cost weights by
        and the fit is compared with (the sensor noise the study states, else the
        estimate from the measured data).
    noise_source : dict
        Where each of those came from: ``"study"`` (stated) or ``"data"`` (estimated).
    validation : dict
        Cost and fit of the validation experiments at ``x`` (MISO superposition check).
    contribution : dict
        ANOVA percent contribution of each parameter per axis-aligned iteration.
    weak : dict
        Parameters the data determine poorly, with the reason.
    warnings : list of str
        Things a person should know (mismatch, limits, failed runs).
    structure : dict or None
        Structure identification: the chosen structure (``chosen``, ``values``,
        ``choices`` by factor, ``why``, those ``indistinguishable`` from it), as
        :meth:`~tsid_fmu.search.structure.compare.StructureResult.summary` gives it;
        ``None`` for a study without choices.
    fidelity : dict or None
        The interface used and the solver checks at the start point and the answer
        (:func:`tsid_fmu.uncertainty.fidelity.fidelity_record`).
    conformance : dict or None
        The FMU's conformance probe: whether a reset instance reproduces a fresh one,
        and two identical runs agree (:mod:`tsid_fmu.conformance`).
    comparison : dict or None
        The grouped study beside the ungrouped one (``compare_ungrouped``).
    on_bound : dict
        ``{name: "min" or "max"}`` for each parameter of the answer on a bound.
    rounds : dict or None
        The wall time of the study on 1, 4 and 16 workers, in rounds of simulations.
    structures : list of dict
        Structure identification: one row per candidate structure refined to its own
        optimum (structure, cost, k, AIC, BIC, LRT p, validation cost, chosen, why);
        :meth:`structures_frame` as a DataFrame. Empty for a study without choices. The
        discrete factors' chosen values are in ``params`` too, after the Real ones.
    study : Study or None
        The study identified.
    out_dir : Path or None
        Where the trail and report were written.
    cov : numpy.ndarray
        Covariance of the parameters the intervals use, ``(n, n)`` in the order of
        ``names`` (derived from ``uncertainty``; see the property).
    jac : numpy.ndarray or None
        Jacobian of the residuals at :attr:`x` with respect to the parameters, in
        parameter units, shape ``(n_residuals, len(names))``: the one the intervals were
        computed from (:func:`tsid_fmu.uncertainty.sensitivity.residual_jacobian`).
        A discrete choice's column is ``nan``. ``None`` where no intervals were
        computed. The results folder keeps it in
        ``jacobian.npy`` (its SHA-256 in ``result.json``), so that
        :func:`tsid_fmu.load` gives the same array back.
    """

    params: dict[str, float]
    fun: float
    nfev: int
    success: bool
    status: int
    message: str
    nit: int = 0
    account: list[str] = field(default_factory=list)
    stages: list[StageResult] = field(default_factory=list)
    intervals: dict[str, list[float | None]] = field(default_factory=dict)
    uncertainty: Uncertainty | None = None
    sampled: Sampled | None = None
    fit: dict[str, Any] = field(default_factory=dict)
    noise: dict[str, dict[str, float]] = field(default_factory=dict)
    noise_source: dict[str, dict[str, str]] = field(default_factory=dict)
    validation: dict[str, Any] = field(default_factory=dict)
    contribution: dict[str, list[float]] = field(default_factory=dict)
    weak: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    structure: dict[str, Any] | None = None
    fidelity: dict[str, Any] | None = None
    conformance: dict[str, Any] | None = None
    comparison: dict[str, Any] | None = None
    on_bound: dict[str, str] = field(default_factory=dict)
    rounds: dict[str, int] | None = None
    study: Study | None = None
    out_dir: Path | None = None
    structures: list[dict[str, Any]] = field(default_factory=list)
    jac: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.params, Parameters):
            self.params = Parameters(self.params)

    def describe_parameters(self) -> None:
        """Fill in each :attr:`params` entry's ``stderr``, ``interval``, ``unit`` and bounds.

        ``identify`` and ``load`` call it once the intervals are known.
        """
        self.params = describe(self)

    @property
    def messages(self) -> list[str]:
        """Each stage's message, ``"<stage>: <message>"``, in order."""
        return [f"{s.name}: {s.message}" for s in self.stages]

    @property
    def names(self) -> list[str]:
        """The parameters, in the order of :attr:`x` (the study's order)."""
        return list(self.params)

    @property
    def x(self) -> np.ndarray:
        """Identified values, a read-only 1-D array in the order of :attr:`names`.

        SciPy's convention; :attr:`params` holds the same values by name.
        """
        out = np.array([float(v) for v in self.params.values()], dtype=float)
        out.flags.writeable = False
        return out

    @property
    def cov(self) -> np.ndarray:
        """Covariance of the parameters, shape ``(n, n)`` in the order of :attr:`names`.

        In parameter units (squared), the covariance the intervals were computed from
        (the HAC sandwich, linearised at :attr:`x`), with each variance the square of the
        standard error reported (``uncertainty.std_error``), which the profile likelihood
        may have widened: ``sqrt(diag(cov))`` is the reported standard errors. A
        parameter the data do not determine has an infinite variance and ``nan``
        covariances. A discrete choice (structure identification) has a row and column
        of ``nan``: it has no variance. Where no intervals were computed (a paused
        study, or an answer whose cost is not finite) every entry is ``nan``, as
        SciPy's ``curve_fit`` fills ``pcov`` with ``inf`` where it cannot estimate it.
        Always ``(len(x), len(x))``.
        """
        u, size = self.uncertainty, len(self.params)
        chosen = (self.structure or {}).get("values") or {}
        names = [n for n in self.names if n not in chosen]  # discrete choices: no variance
        out = np.full((size, size), np.nan)
        if u is None or any(n not in u.std_error for n in names):
            return out
        se = np.array([float(u.std_error[n]) for n in names])
        corr = np.array(
            [[float(u.correlation.get(a, {}).get(b, 0.0)) for b in names] for a in names]
        )
        finite = np.isfinite(se)
        with np.errstate(invalid="ignore"):
            cov = corr * np.outer(se, se)
        cov[~np.outer(finite, finite)] = np.nan
        np.fill_diagonal(cov, se**2)
        at = [self.names.index(n) for n in names]
        out[np.ix_(at, at)] = cov
        return out

    @property
    def iterations(self) -> list[IterationRecord]:
        """Every Taguchi iteration of every stage, in order."""
        return [rec for st in self.stages for rec in st.records]

    def x_at(self, k: int) -> dict[str, float]:
        """Return the best parameter set known after Taguchi iteration ``k``.

        Parameters
        ----------
        k : int
            Position in :attr:`iterations`, 1-based as in the report (``iteration_01``);
            negative counts from the end (``-1``: the last).

        Returns
        -------
        dict
            Value of each parameter: the iteration's best set for those it varied, and
            for the others the answer of the stages before it (in a phased study), as
            the iteration ran. Parameters no stage had set by then are left out.

        Raises
        ------
        IndexError
            There is no iteration ``k``.
        """
        count = len(self.iterations)
        if not isinstance(k, int | np.integer) or isinstance(k, bool):
            raise TypeError(f"k must be an iteration number, got {k!r}")
        if k == 0 or not -count <= k <= count:
            raise IndexError(f"iteration {k}: the result has {count} (1 .. {count}, or -1 ..)")
        sets: list[dict[str, float]] = []
        known: dict[str, float] = {}
        for stage in self.stages:
            sets += [{**known, **rec.best_x} for rec in stage.records]
            if stage.kind != StageKind.CONTRIBUTION:
                known.update(stage.x)
        values = sets[int(k) - 1 if k > 0 else int(k)]
        return {n: float(values[n]) for n in self.params if n in values}

    def __repr__(self) -> str:
        keys = ["message", "success", "status", "fun", "names", "x", "nfev", "nit", "intervals"]
        width = max(map(len, keys))
        return "\n".join(f"{k.rjust(width)}: {getattr(self, k)!r}" for k in keys)

    def fit_report(self, min_correl: float = 0.1) -> str:
        """Return the report in lmfit's sections, as lmfit's ``fit_report``.

        ``[[Fit Statistics]]`` (method, function evaluations, data points, variables,
        chi-square, reduced chi-square, Akaike and Bayesian information criteria),
        ``[[Variables]]`` (value, standard error, 95 % interval, whether the data
        determine it) and ``[[Correlations]]`` (pairs above ``min_correl``), then the
        verdict. :meth:`text_report` is what ``tsid identify`` prints.

        Parameters
        ----------
        min_correl : float, optional
            Smallest absolute correlation listed (lmfit's default, 0.1).
        """
        return _view("fit_report")(self, min_correl)

    def text_report(self, verbose: bool = False) -> str:
        """Return the text ``tsid identify`` prints (``verbose``: ``--verbose``'s too).

        The parameters with their units, 95 % intervals, standard errors and flags, the
        stages, the structure chosen, the one-line verdict with the exit status, the
        cost, the warnings and the validation experiments; with ``verbose``, the
        :attr:`account` and the fit statistics.
        """
        return _view("text_report")(self, verbose)

    def _repr_html_(self) -> str:
        """Return the notebook view: headline, parameters with intervals, stages."""
        return _view("result_html")(self)

    def plot_fit(self) -> Any:
        """Return a matplotlib figure of measured vs simulated outputs and residuals.

        Simulates the study's FMU once at ``x`` (the study must be attached).
        """
        return _view("plot_fit")(self)

    def plot_convergence(self) -> Any:
        """Return a matplotlib figure of the best cost per iteration (one axis per measure)."""
        return _view("plot_convergence")(self)

    def plot_main_effects(self, iteration: int | IterationRecord = -1) -> Any:
        """Return a matplotlib figure of one iteration's S/N and mean-cost main effects.

        Parameters
        ----------
        iteration : int or IterationRecord
            Position in :attr:`iterations` (1-based; negative from the end), or a record.
        """
        return _view("plot_main_effects")(self, iteration)

    def plot_parameters(self) -> Any:
        """Return a matplotlib figure of each parameter's best value per iteration."""
        return _view("plot_parameters")(self)

    def to_dict(self) -> dict[str, Any]:
        """Return the result as strict-JSON data (the content of ``result.json``).

        Its keys are the attributes': ``names`` and ``x`` (a list in that order), and
        ``params`` (the same values by name), ``fun``, ``nfev``, ``success``,
        ``status``, ``message``, ``nit``, the ``stages``, the ``intervals`` and the rest.
        """
        return strict(
            {
                "names": self.names,
                "x": [float(v) for v in self.params.values()],
                "params": {k: float(v) for k, v in self.params.items()},
                "fun": self.fun,
                "nfev": self.nfev,
                "success": self.success,
                "status": self.status,
                "message": self.message,
                "account": list(self.account),
                "nit": self.nit,
                "stages": [s.to_dict() for s in self.stages],
                "intervals": self.intervals,
                "uncertainty": self.uncertainty.to_dict() if self.uncertainty else None,
                "sampled": self.sampled.to_dict() if self.sampled else None,
                "fit": self.fit,
                "noise": self.noise,
                "noise_source": self.noise_source,
                "validation": self.validation,
                "weak": self.weak,
                "warnings": self.warnings,
                "comparison": self.comparison,
                "extra": {k: getattr(self, k) for k in EXTRA_KEYS if getattr(self, k) is not None},
                **({"structures": self.structures} if self.structures else {}),
            }
        )

    def structures_frame(self) -> pd.DataFrame:
        """Return the structures table (structure identification), one row per structure.

        Columns: ``cost``, ``k`` (free Real parameters), ``AIC``, ``BIC``, ``LRT p`` and
        ``LRT against`` (nested structures), ``validation cost``, ``simulations``,
        ``chosen`` and ``why``; the formulas are in :mod:`tsid_fmu.search.structure.selection`.
        """
        import pandas as pd

        rows = self.structures
        return pd.DataFrame(list(rows)).set_index("structure") if rows else pd.DataFrame()

    def structures_table(self) -> pd.DataFrame:
        """Return the structures table as the reports show it (no dicts, "yes" chosen)."""
        return result_views.structures_table(self)

    def summary(self) -> dict[str, Any]:
        """Return the answer in brief, as strict JSON data (``tsid identify --json``).

        It follows ``tsid_fmu/schemas/result-summary.schema.json``: ``parameters`` (per
        name its ``value``, 95 % ``interval`` and ``unit``, why it is ``weak``, and its
        ``sampled_interval`` where the study asks for one),
        ``fun``, ``nfev``, ``nit``, ``status``, ``success``, ``message``, the ``stages``
        (name, kind, cost, simulations, iterations, status, message), the ``warnings``
        and ``out_dir``. Non-finite numbers are ``null``.
        """
        return result_views.summary(self)

    def to_pandas(self) -> pd.DataFrame:
        """Return every run of every Taguchi iteration as one DataFrame.

        It has fewer rows than :attr:`nfev` counts simulations: a row is one run of an
        orthogonal array (a parameter set), simulated on every identification
        experiment and replicate, and the stages simulate more than their arrays (the
        start points, a confirmation run per iteration, the refinement, the checks).
        ``attrs["note"]`` says so and ``attrs["simulations"]`` holds the account,
        stage by stage (:meth:`simulations_frame`).
        """
        import pandas as pd

        frames = [rec.runs_frame() for rec in self.iterations]
        df = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
        df.attrs["note"] = RUNS_NOTE
        df.attrs["simulations"] = self.simulations_frame().to_dict(orient="index")
        return df

    def simulations_frame(self) -> pd.DataFrame:
        """Return where the :attr:`nfev` simulations went, one row per stage.

        Columns: ``kind``; ``array runs`` (the stage's rows of :meth:`to_pandas`);
        ``confirmation runs`` (one parameter set per iteration, at the predicted
        optimum); ``array simulations`` (what the array runs and confirmation runs
        simulated, every experiment and replicate); ``other simulations`` (start points
        and re-runs of a Taguchi stage, or the whole of a refinement, contribution
        analysis or check); ``simulations`` (their sum, the stage's ``nfev``). The
        column ``simulations`` adds up to :attr:`nfev`.
        """
        return result_views.simulations_frame(self)

    def stages_frame(self) -> pd.DataFrame:
        """Return one row per stage: kind, cost, simulations, what it contributed."""
        return result_views.stages_frame(self)

    def parameters_frame(self) -> pd.DataFrame:
        """Return the identified parameters with units, intervals, ranges and flags.

        With sampled intervals (:attr:`sampled`), their ends follow the standard error
        (columns ``bootstrap low``/``high`` or ``monte carlo low``/``high``).
        """
        return result_views.parameters_frame(self)
