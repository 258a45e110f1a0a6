"""The time limit per simulation of the worker-process evaluators.

``timeout`` means the same everywhere it is accepted
(:class:`~tsid_fmu.evaluate.pool.PoolEvaluator`,
:class:`~tsid_fmu.evaluate.dask.DaskEvaluator`,
:func:`~tsid_fmu.evaluate.factory.make_evaluator`):

* ``None`` (the default): **automatic**. Until a simulation has succeeded the limit is
  :data:`AUTO_FIRST_S` (300 s); then it is ``max(AUTO_MIN_S, AUTO_FACTOR * median)``
  of the durations of the successful simulations seen so far -- at least 5 s, 20 times
  the median -- and it is fixed at the end of the first batch that had a successful
  simulation. So a hanging FMU never stops a study, while an FMU that is merely slow
  keeps 20 times its usual time.
* ``0``: no limit.
* a positive number: that many seconds per simulation.

A simulation over the limit is stopped by killing its worker process (which is
replaced); its parameter set fails with the reason. The checks that simulate outside the
evaluators (the solver-fidelity check) run in a child process under the same limit
(:mod:`tsid_fmu.evaluate.isolated`). Only the serial in-process evaluator, which
:func:`~tsid_fmu.evaluate.factory.make_evaluator` chooses for one worker with
``timeout=0``, cannot stop a simulation.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable

from tsid_fmu.errors import StudyError

__all__ = ["AUTO_FACTOR", "AUTO_FIRST_S", "AUTO_MIN_S", "EXCEEDED", "TimeLimit", "timed_out"]

AUTO_FACTOR = 20.0
"""Automatic limit: this many times the median duration of the first simulations."""
AUTO_MIN_S = 5.0
"""Automatic limit: never below this many seconds."""
AUTO_FIRST_S = 300.0
"""Automatic limit before any simulation has succeeded."""
EXCEEDED = "per simulation exceeded"
"""The words every reason of a simulation stopped at the time limit holds."""


def timed_out(reason: str | None) -> bool:
    """Return True if ``reason`` (a parameter set's error) is the time limit's."""
    return reason is not None and EXCEEDED in reason


class TimeLimit:
    """A per-simulation time limit: automatic, off, or fixed (see the module docstring).

    Parameters
    ----------
    timeout : float or None
        ``None``: automatic; ``0``: none; ``> 0``: seconds.

    Raises
    ------
    StudyError
        ``timeout`` is negative or not a number.
    """

    def __init__(self, timeout: float | None) -> None:
        if timeout is not None:
            try:
                timeout = float(timeout)
            except (TypeError, ValueError):
                timeout = math.nan
            if not (math.isfinite(timeout) and timeout >= 0):
                raise StudyError(
                    f"timeout must be None (automatic), 0 (none) or a positive number of "
                    f"seconds, got {timeout}"
                )
        self.timeout = timeout
        self.auto = timeout is None
        self._durations: list[float] = []
        self._median = math.nan
        self._fixed = False

    def observe(self, durations: Iterable[float]) -> None:
        """Record the durations of successful simulations (automatic limit only)."""
        if self.auto and not self._fixed:
            before = len(self._durations)
            self._durations.extend(durations)
            if len(self._durations) > before:  # the pool asks for the limit at every wake
                self._median = statistics.median(self._durations)

    def end_batch(self) -> None:
        """End a batch: the automatic limit is fixed once it has seen a simulation."""
        if self._durations:
            self._fixed = True

    def seconds(self) -> float | None:
        """Return the current limit in seconds, or None for no limit."""
        if not self.auto:
            return self.timeout or None
        if not self._durations:
            return AUTO_FIRST_S
        return max(AUTO_MIN_S, AUTO_FACTOR * self._median)

    def exceeded(self) -> str:
        """Return the reason given to a parameter set stopped by the limit."""
        text = f"time limit of {self.seconds():g} s {EXCEEDED}"
        if self.auto:
            text += (
                f" (automatic: {AUTO_FACTOR:g}x the median of the first simulations, at "
                f"least {AUTO_MIN_S:g} s; give timeout to change it)"
            )
        return text

    def __repr__(self) -> str:
        mode = "automatic" if self.auto else "fixed" if self.timeout else "none"
        return f"TimeLimit({mode}, {self.seconds()})"
