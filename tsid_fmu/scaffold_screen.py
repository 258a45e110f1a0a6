"""``tsid init``'s screening: which candidate parameters the data can decide, by simulation.

The metadata rules (:func:`~tsid_fmu.scaffold_rules.held_reason`) hold what a name,
unit or description shows to be a numerical setting or a constant of the medium. What
is left is screened at the start values, ``2 p + 1`` simulations of the identification
experiments on the measured inputs:

- the start (each parameter at its middle first level), then each parameter alone at
  its lowest and at its highest first level;
- a parameter's **effect** is the larger of the two ends' changes of the residuals, in
  units of the data's noise: ``max(|r(low) - r(start)|², |r(high) - r(start)|²)``.
  Below ``chi2_1(0.95)`` (3.84) no test on these data could tell the end from the start,
  so the parameter has no effect the data can see: it is held;
- of the rest, taken in order of effect, a parameter whose change across its first
  range (the secant ``r(high) - r(low)``) is reproduced by those already free to within
  the same 3.84 noise² acts only together with them: the data fix the group in
  combination, so one member is free and this one is held, naming the members.

The rule has one number, the 95 % point of chi-square with one degree of freedom, the
threshold the profile intervals use too. A run that fails at an end is an effect (the
parameter decides whether the FMU runs): the parameter stays free.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from tsid_fmu.errors import TsidError, one_line
from tsid_fmu.study.definition import Study
from tsid_fmu.uncertainty.profile import CHI2_95

__all__ = ["SIGNIFICANT", "Screened", "console_progress", "screen_start"]

SIGNIFICANT = CHI2_95
"""``chi2_1(0.95)``: the change of the noise-weighted SSE one parameter must make to be
seen by the data (the profile intervals' threshold)."""
MEMBERS_NAMED = 3
"""Members of a combination a held parameter's reason names, largest share first."""


@dataclass
class Screened:
    """What the screening found.

    Attributes
    ----------
    effect : dict of str to float
        Per screened parameter, its effect in noise² (``inf`` where a run at an end
        failed).
    held : dict of str to str
        The parameters to hold, each with its reason.
    nfev : int
        Simulations run.
    failed : str
        Why the screening could not run ("" where it ran).
    """

    effect: dict[str, float] = field(default_factory=dict)
    held: dict[str, str] = field(default_factory=dict)
    nfev: int = 0
    failed: str = ""

    def summary(self) -> str:
        """One line for the study file."""
        if self.failed:
            return f"not screened: {self.failed}; every candidate is free"
        free = len(self.effect) - len(self.held)
        return (
            f"screened: {self.nfev} simulations at the start values; {free} of "
            f"{len(self.effect)} candidates act on the outputs on their own"
        )


def console_progress(stream: TextIO | None = None) -> Callable[[int, int], None]:
    """Return a progress callback for the screening, printing to ``stream`` (stderr).

    On a terminal the line is redrawn; elsewhere a line at the first simulation and one
    at the end.
    """
    out = stream or sys.stderr
    live = hasattr(out, "isatty") and out.isatty()

    def show(done: int, total: int) -> None:
        if live:
            end = "\n" if done == total else ""
            print(f"\rscreening the parameters: {done}/{total} simulations", end=end, file=out)
        elif done in (0, total) or done == 1:
            what = "done" if done == total else "running"
            print(f"screening the parameters: {done}/{total} simulations ({what})", file=out)
        out.flush()

    return show


def screen_start(
    study_file: str | Path,
    *,
    workers: int | None = None,
    timeout: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Screened:
    """Screen the free parameters of the study in ``study_file`` at their start values.

    Parameters
    ----------
    study_file : path
        A study as ``tsid init`` writes it, every candidate free.
    workers, timeout
        As for :func:`tsid_fmu.identify`.
    progress : callable, optional
        Gets ``(done, total)`` simulations.

    Returns
    -------
    Screened
        The effects, the parameters to hold with their reasons, the simulations; where
        the study cannot be simulated at its start, ``failed`` says why.
    """
    from tsid_fmu.screening.run import study_evaluator

    try:
        study = Study.from_toml(study_file)
        params = study.identified_parameters()
        ev = study_evaluator(study, {"workers": workers, "timeout": timeout, "scheduler": None})
    except (TsidError, OSError, ValueError) as exc:
        return Screened(failed=one_line(str(exc)))
    try:
        names = [p.name for p in params]
        start = {p.name: float(p.levels[len(p.levels) // 2]) for p in params}
        sets = [start]
        for p in params:
            sets += [{**start, p.name: float(p.levels[0])}, {**start, p.name: float(p.levels[-1])}]
        evaluation = ev.evaluate(sets, progress)
        nfev = int(evaluation.nfev)
    except TsidError as exc:
        return Screened(failed=one_line(str(exc)))
    finally:
        ev.close()
    residuals = evaluation.residuals or [None] * len(sets)
    if residuals[0] is None:
        reason = evaluation.errors[0] or "the start values' run failed"
        return Screened(nfev=nfev, failed=f"the FMU fails at the start values ({one_line(reason)})")
    effect, held = _judge(names, np.asarray(residuals[0]), residuals[1:])
    return Screened(effect=effect, held=held, nfev=nfev)


def _judge(
    names: Sequence[str], r0: np.ndarray, ends: Sequence[np.ndarray | None]
) -> tuple[dict[str, float], dict[str, str]]:
    """Return each parameter's effect and the parameters held, with their reasons."""
    effect: dict[str, float] = {}
    secant: dict[str, np.ndarray] = {}
    for j, name in enumerate(names):
        low, high = ends[2 * j], ends[2 * j + 1]
        if low is None or high is None:
            effect[name] = np.inf
            continue
        low, high = np.asarray(low), np.asarray(high)
        effect[name] = float(max(np.sum((low - r0) ** 2), np.sum((high - r0) ** 2)))
        secant[name] = high - low
    held: dict[str, str] = {}
    for name in names:
        if effect[name] < SIGNIFICANT:
            held[name] = (
                f"no effect the data can see: its first levels move the outputs by "
                f"{effect[name]:.2g} noise² at most (screened; {SIGNIFICANT:.2f} would be)"
            )
    free: list[str] = []
    for name in sorted((n for n in names if n not in held), key=lambda n: -effect[n]):
        if name not in secant or not free:
            free.append(name)
            continue
        basis = [n for n in free if n in secant]
        if not basis:
            free.append(name)
            continue
        a = np.column_stack([secant[n] for n in basis])
        coef, *_ = np.linalg.lstsq(a, secant[name], rcond=None)
        rest = float(np.sum((secant[name] - a @ coef) ** 2))
        if rest >= SIGNIFICANT:
            free.append(name)
            continue
        share = np.abs(coef) * np.linalg.norm(a, axis=0)
        members = [basis[i] for i in np.argsort(-share)[:MEMBERS_NAMED] if share[i] > 0]
        held[name] = (
            f"acts only together with {', '.join(members)}: what it does across its first "
            f"levels, they do too (to {rest:.2g} noise²; screened), so the data fix them "
            f"in combination; {members[0] if members else 'the others'} is free"
        )
    return effect, held
