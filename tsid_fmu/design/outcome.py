"""What :func:`tsid_fmu.design` found: the proposal, the predicted intervals, the reasons."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.design.signals import Signal
from tsid_fmu.report.style import fmt_levels
from tsid_fmu.story import interval_text
from tsid_fmu.uncertainty.intervals import json_safe

__all__ = ["CRITERIA_TEXT", "Design", "Structural"]

CRITERIA_TEXT = {
    "D": "D-optimal: the largest determinant of the Fisher matrix of every parameter (in "
    "search coordinates, so units do not matter): the smallest joint confidence region, "
    "which gains most where the study is weakest",
    "A": "A-optimal on the weak combinations: the smallest sum of their variances",
}
"""How each criterion ranks the candidates, as the report says it."""


@dataclass
class Structural:
    """A direction that no candidate input separates: the model's own symmetry.

    Attributes
    ----------
    members : list of str
        The parameters in it.
    terms : list of dict
        Its directions, each by search coordinate (``lg C``: weight).
    fixed : list of dict
        The combinations across it that the data fix (``{"name": "C R1", "value",
        "interval"}``), predicted with the proposed experiment where there is one.
    tried : str or None
        The best candidate, where its own prediction left the members open (the design
        then proposes nothing); ``None`` for a subspace that no candidate moved.
    """

    members: list[str]
    terms: list[dict[str, float]]
    fixed: list[dict[str, Any]] = field(default_factory=list)
    tried: str | None = None

    def advice(self) -> str:
        """Say what would fix the rest: known values or another measurement."""
        names = ", ".join(self.members)
        if self.tried is not None:
            names += f" (the best, {self.tried}, is predicted to leave them open)"
        k = len(self.terms)
        which = (
            "one of them at a known value"
            if k == 1
            else "them at known values"
            if k >= len(self.members)
            else f"{k} of them at known values"
        )
        return (
            f"no input of this kind separates {names}: fix {which} (a datasheet, a "
            "separate test), or measure another output that depends on them otherwise"
        )


def _fmt(v: float | None) -> str:
    return "open" if v is None else f"{v:.5g}"


def _span(iv: list | None) -> str:
    """Return the interval as every view shows it (:func:`tsid_fmu.story.interval_text`)."""
    if iv is None:
        return "-"
    return interval_text(iv, math.nan, lambda values: [_fmt(v) for v in values])


def _levels(levels: list | None) -> str:
    return "-" if not levels else ", ".join(fmt_levels(levels))


def _plain(x: float) -> float:
    """Return ``x`` without the float noise of a difference of sample times (4.999999999)."""
    return float(f"{float(x):.12g}")


def width(iv: list | None) -> float:
    """Return an interval's width; ``inf`` for an open one."""
    if not iv or iv[0] is None or iv[1] is None:
        return math.inf
    return float(iv[1]) - float(iv[0])


@dataclass
class Design:
    """An experiment design and its evidence (:func:`tsid_fmu.design`).

    Attributes
    ----------
    names : list of str
        The parameters.
    values : dict
        The answer the design is made at.
    criterion : str
        ``D`` or ``A`` (:data:`CRITERIA_TEXT`).
    inputs : list of str
        The FMU inputs designed, in the column order of ``proposal.values``.
    limits : list of (float, float)
        Each input's ``[min, max]``.
    band : (float, float)
        The frequencies allowed (Hz).
    time : numpy.ndarray
        Sample times of the proposed record (s).
    candidates : list of dict
        Every candidate's name, kind and criterion value.
    proposal : Signal or None
        The proposed input; ``None`` where no input of the family helps (structural).
    predicted_outputs : numpy.ndarray or None
        The template's outputs simulated at the answer with the proposal.
    output_names : list of str
        Those outputs.
    template : str
        The experiment whose outputs and sensors the proposal has.
    study_intervals : dict
        The study's own 95 % intervals.
    after : list or None
        Predicted 95 % intervals per parameter (in ``names`` order) of the study plus
        the proposal (``None`` without one).
    weak : list of dict
        The directions the study leaves weak.
    structural : list of Structural
        The directions no candidate separates.
    nfev : int
        Simulations used (each candidate's record counts one).
    separating : Signal or None
        Where the study's structures ended indistinguishable: the input that separates
        them best (:mod:`tsid_fmu.design.discriminate`).
    discrimination : dict or None
        Its evidence: ``structures``, ``chi2`` per pair with it, ``now`` on the study's
        inputs, ``scores`` per candidate.
    levels : dict
        First levels of the study ``after`` is predicted for: the study with the
        proposal added, started around the answer (half to twice each value, inside its
        bounds; the study's interval around an answer nearer zero than that interval is
        wide; :func:`~tsid_fmu.design.plan.follow_up_levels`). Empty without a proposal.
    warnings : list of str
        What the design was made despite: the study or its files changed since the
        result (:func:`tsid_fmu.load.study_changes`).
    """

    names: list[str]
    values: dict[str, float]
    criterion: str
    inputs: list[str]
    limits: list[tuple[float, float]]
    band: tuple[float, float]
    time: np.ndarray
    candidates: list[dict[str, Any]]
    proposal: Signal | None
    predicted_outputs: np.ndarray | None
    output_names: list[str]
    template: str
    study_intervals: dict[str, list]
    after: list | None
    weak: list[dict[str, float]]
    structural: list[Structural]
    nfev: int
    separating: Signal | None = None
    discrimination: dict[str, Any] | None = None
    levels: dict[str, list[float]] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        """One line: what the design proposes, or why nothing."""
        if self.proposal is None:
            advice = "; ".join(s.advice() for s in self.structural)
            if self.separating is not None:  # the headline says what the section proposes
                line = f"run {self.separating.name}: it tells the structures apart best"
                return line + (f"; for the parameters, {advice}" if advice else "")
            return "no experiment of this kind helps" + (f": {advice}" if advice else "")
        what = "what the study left weak" if self.weak else "every parameter"
        line = f"run {self.proposal.name}: it determines {what} best ({self.criterion}-optimal)"
        if self.separating is not None:
            line += f"; to tell the structures apart, run {self.separating.name}"
        return line

    def table(self) -> list[dict[str, Any]]:
        """Per parameter: value, the study's interval, and predicted with the proposal."""
        return [
            {
                "parameter": n,
                "value": self.values[n],
                "study": self.study_intervals.get(n),
                "predicted_after": None if self.after is None else self.after[j],
                "first_levels": self.levels.get(n),
            }
            for j, n in enumerate(self.names)
        ]

    def to_pandas(self) -> Any:
        """:meth:`table` as a DataFrame indexed by parameter."""
        import pandas as pd

        return pd.DataFrame(self.table()).set_index("parameter")

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable copy (the proposal's samples are in the CSV, not here)."""
        return json_safe(
            {
                "verdict": self.verdict,
                "criterion": self.criterion,
                "criterion_text": CRITERIA_TEXT[self.criterion],
                "template": self.template,
                "inputs": {n: list(lim) for n, lim in zip(self.inputs, self.limits, strict=True)},
                "band_hz": list(self.band),
                "duration": _plain(self.time[-1] - self.time[0]),
                "sample_time": _plain(self.time[1] - self.time[0]),
                "proposal": None if self.proposal is None else self.proposal.name,
                "parameters": self.table(),
                "weak": self.weak,
                "structural": [{**vars(s), "advice": s.advice()} for s in self.structural],
                "candidates": self.candidates,
                "nfev": self.nfev,
                "separating": None if self.separating is None else self.separating.name,
                "discrimination": self.discrimination,
                "warnings": list(self.warnings),
            }
        )

    def _repr_markdown_(self) -> str:
        """Show the report section in a notebook."""
        return self.markdown()

    def section(self) -> dict[str, Any]:
        """Return the report section's content, for :meth:`markdown` and the HTML page.

        ``facts`` (sentences), ``intervals`` (columns and rows), ``separate`` (a
        sentence, columns and rows; ``None`` where no structures tied) and ``structural``
        (sentences).
        """
        limits = ", ".join(
            f"{n} in [{a:g}, {b:g}]" for n, (a, b) in zip(self.inputs, self.limits, strict=True)
        )
        facts = [
            f"Inputs: {limits}; band {self.band[0]:.3g}-{self.band[1]:.3g} Hz; "
            f"{self.time[-1] - self.time[0]:g} s at {self.time[1] - self.time[0]:g} s, with the "
            f"outputs and sensors of experiment {self.template!r}.",
            f"Criterion: {CRITERIA_TEXT[self.criterion]}.",
            f"{len(self.candidates)} candidates, {self.nfev} simulations.",
            *(f"Warning: {w}{'' if w.endswith('.') else '.'}" for w in self.warnings),
        ]
        if self.levels:
            facts.append(
                "Predicted for the study with the proposal added as a second experiment, "
                "started from the first levels below (half to twice each value, or the "
                "study's interval around a value near zero): start "
                "it so, since the intervals' resolution and finite-difference steps are "
                "fractions of a first range."
            )
        rows = [[r["parameter"], f"{r['value']:.5g}", _span(r["study"]),
                 _span(r["predicted_after"]), _levels(r["first_levels"])]
                for r in self.table()]  # fmt: skip
        separate = None
        if self.discrimination is not None and self.separating is not None:
            d = self.discrimination
            said = (f"Structures the study cannot tell apart: {', '.join(d['structures'])}. "
                    f"Run {self.separating.name} to separate them (expected chi-square "
                    "between their predictions, in the sensors' noise):")  # fmt: skip
            pairs = [[p, f"{d['now'][p]:.4g}", f"{v:.4g}"] for p, v in d["chi2"].items()]
            separate = (said, ["pair", "on the study's inputs", "with the proposal"], pairs)
        structural = []
        for s in self.structural:
            structural.append(f"Structural: {s.advice()}.")
            fixed = "; ".join(
                f"{f['name']} = {f['value']:.5g} ({_span(f['interval'])})" for f in s.fixed
            )
            if fixed:
                structural.append(f"The data fix: {fixed}.")
        columns = ["parameter", "value", "study's 95 % interval", "predicted, with the proposal",
                   "first levels"]  # fmt: skip
        return {"facts": facts, "intervals": (columns, rows), "separate": separate,
                "structural": structural}  # fmt: skip

    def _body(self, grid: Any) -> list[str]:
        """Return the lines :meth:`text` and :meth:`markdown` share, tables by ``grid``.

        The facts, the intervals, what separates the parameters, the structural directions.
        """
        part = self.section()
        lines = [f"- {fact}" for fact in part["facts"]] + [""]
        lines += grid(*part["intervals"])
        if part["separate"] is not None:
            said, columns, rows = part["separate"]
            lines += ["", said, "", *grid(columns, rows)]
        for sentence in part["structural"]:
            lines += ["", sentence] if sentence.startswith("Structural") else [sentence]
        return lines

    def text(self) -> str:
        """Return the design as ``tsid design`` prints it: plain text, aligned columns.

        The same section as :meth:`markdown` (verdict, facts, intervals, what separates
        the parameters, the structural directions), without markdown's markup.
        """

        def grid(columns: list[str], rows: list[list[str]]) -> list[str]:
            widths = [max(len(str(x)) for x in col) for col in zip(columns, *rows, strict=True)]
            return [
                "  ".join(str(x).ljust(w) for x, w in zip(r, widths, strict=True)).rstrip()
                for r in [columns, *rows]
            ]

        return "\n".join([self.verdict, "", *self._body(grid)])

    def markdown(self) -> str:
        """Return the report section, in markdown."""

        def grid(columns: list[str], rows: list[list[str]]) -> list[str]:
            return ["| " + " | ".join(columns) + " |", "|" + " --- |" * len(columns),
                    *("| " + " | ".join(r) + " |" for r in rows)]  # fmt: skip

        head = ["## Experiment design", "", f"**{self.verdict}**", ""]
        return "\n".join([*head, *self._body(grid)]) + "\n"
