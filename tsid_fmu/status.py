"""The verdict of a study in one sentence, and the account of how it got there.

A person reads the verdict first: :func:`study_status` gives the exit status, a one-line
:attr:`~tsid_fmu.result.IdentificationResult.message` of at most :data:`MAX_MESSAGE`
characters made from a code and the table :data:`MESSAGES` (never parsed back), and the
stage-by-stage :attr:`~tsid_fmu.result.IdentificationResult.account`, in which each
clause is said once. The report and ``tsid identify --verbose`` print the account; the
console, the headline of the reports and ``result.json``'s ``message`` the one line.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

from tsid_fmu.search.local.adaptive import answer_stage
from tsid_fmu.search.outcome import Stationarity
from tsid_fmu.search.stage import StageKind, StageResult

__all__ = ["MAX_MESSAGE", "MESSAGES", "Verdict", "account", "study_status"]

MAX_MESSAGE = 200
"""Most characters of the one-line verdict (issue 64)."""

PAUSED = 3  # tsid_fmu.result.PAUSED (the result imports this module's neighbours)


class Verdict(enum.Enum):
    """Why a study ended, one code per sentence of :data:`MESSAGES`."""

    STATIONARY = "stationary"
    """Exit 0: the answer's stationarity test holds."""
    LEVELS = "levels"
    """Exit 0: every stage converged; no stationarity test was made (``refine = "none"``
    with a cost the probe test does not cover)."""
    NOT_SHOWN = "not shown"
    """Exit 1: the answer's stationarity test does not hold."""
    LIMIT = "limit"
    """Exit 1: a stage stopped at a limit and no test was made."""
    PAUSED = "paused"
    """Exit 3: paused for review (``--pause-after``)."""
    FMU = "fmu"
    """Exit 1: the FMU does not reproduce its runs (:mod:`tsid_fmu.conformance`): its
    costs are not reproducible, so no answer can be shown to be the optimum."""


MESSAGES = {
    Verdict.STATIONARY: "converged: the answer is stationary ({nfev} simulations)",
    Verdict.LEVELS: "converged: the levels converged ({nfev} simulations)",
    Verdict.NOT_SHOWN: (
        "stopped: the answer is not shown to be an optimum ({nfev} simulations); see the warnings"
    ),
    Verdict.LIMIT: "stopped at a limit ({why}): the answer may not be the optimum "
    "({nfev} simulations)",
    Verdict.PAUSED: "paused for review after {nit} ({nfev} simulations): "
    "edit the levels, then --resume",
    Verdict.FMU: "stopped: the FMU does not reproduce its runs ({why}); the answer cannot be "
    "trusted ({nfev} simulations)",
}
"""The one-line verdict of each :class:`Verdict`, formatted with the study's counts."""

_WHY = 80  # characters of a stage's own reason quoted in the LIMIT sentence


def _clauses(message: str) -> list[str]:
    return [c.strip() for c in message.split("; ") if c.strip()]


_SAME = 24  # characters a repeated clause must have to be said as "the same"


def _once(message: str, said: list[str]) -> list[str]:
    """Return the clauses of ``message`` not yet ``said`` (and add them to it).

    A clause already said, or part of one, is left out; one that quotes an earlier
    clause after its own words (``again with ...: <the first pass's reason>``) says
    "the same" in its place.
    """
    fresh = []
    for clause in _clauses(message):
        if any(clause in earlier for earlier in said):
            continue
        for earlier in sorted(said, key=len, reverse=True):
            if len(earlier) >= _SAME and earlier in clause:
                clause = clause.replace(earlier, "the same")
        fresh.append(clause)
        said.append(clause)
    return fresh


def account(stages: Sequence[StageResult]) -> list[str]:
    """Return one line per stage, ``"<stage>: <why it stopped>"``, each clause said once.

    A clause a stage repeats from an earlier one (a second pass that stopped for the
    same reason, the stationarity test quoting the refinement) is left out or said as
    "the same"; the last line is the stationarity test's verdict, where one was made.
    """
    said: list[str] = []
    lines = []
    for s in stages:
        if s.kind == StageKind.CONTRIBUTION:
            continue
        fresh = _once(s.message, said)
        if fresh:
            lines.append(f"{s.name}: {'; '.join(fresh)}")
    test = _test(stages)
    if test is not None:
        head = "stationary at the answer" if test.holds else "not shown to be an optimum"
        fresh = _once(test.detail, said)
        tail = f": {'; '.join(fresh)}" if fresh else ""
        lines.append(f"verdict: {head} ({test.test}){tail}")
    return lines


def _test(stages: Sequence[StageResult]) -> Stationarity | None:
    return answer_stage(stages).stationarity if stages else None


def study_status(
    stages: Sequence[StageResult], fmu: str | None = None
) -> tuple[int, Verdict, str, list[str]]:
    """Return the study's exit status, its verdict, the one-line message and the account.

    The verdict is the answer's stationarity test where one was made; a stage paused
    for review (its status 2) pauses the study (exit status 3). ``fmu``: why the FMU
    does not reproduce its runs (:func:`tsid_fmu.evaluate.conformance.problem`), which
    decides the verdict of a study that was not paused.
    """
    nfev = sum(s.nfev for s in stages)
    nit = sum(len(s.records) for s in stages)
    told = account(stages)
    paused = [s for s in stages if s.status == 2]
    test = _test(stages)
    if paused:
        code, status = Verdict.PAUSED, PAUSED
        told = [*told, f"{paused[0].name}: {paused[0].message}"]
    elif fmu:
        code, status = Verdict.FMU, 1
        told = [*told, f"FMU: {fmu}"]
    elif test is not None:
        code = Verdict.STATIONARY if test.holds else Verdict.NOT_SHOWN
        status = 0 if code is Verdict.STATIONARY else 1
    else:
        ran = [s for s in stages if s.kind != StageKind.CONTRIBUTION]
        stopped = [s for s in ran if s.status != 0]
        code = Verdict.LIMIT if stopped else Verdict.LEVELS
        status = 1 if stopped else 0
    why = ""
    if code is Verdict.LIMIT:
        first = stopped[0]
        reason = _clauses(first.message)[0] if _clauses(first.message) else "a limit"
        reason = reason if len(reason) <= _WHY else reason[: _WHY - 3].rstrip() + "..."
        why = f"{first.name}: {reason}"
    elif code is Verdict.FMU:
        why = str(fmu)[:_WHY]
    iterations = f"{nit} Taguchi iteration" + ("" if nit == 1 else "s")
    message = MESSAGES[code].format(nfev=nfev, nit=iterations, why=why)
    return status, code, message[:MAX_MESSAGE], told
