"""The one restart loop: refinements from starts not yet tried, counted and limited.

A restart is a refinement from another start than the answer's. Three parts of the
search restart, and all go through :class:`Restarts`, so that one rule holds for each:

- the local search, while its answer is unsettled, from the start points and then the
  arrays' next-best runs (:func:`tsid_fmu.search.local.flow.local_search`), at most
  ``max_reruns`` times;
- structure identification, a candidate whose answer a nesting shows is not its
  optimum, from the point the nesting gives
  (:meth:`tsid_fmu.search.structure.pool.Pool.restart`);
- a refinement that stopped at its tolerances short of its own stationarity test, once
  from its own answer (:func:`tsid_fmu.search.structure.optima.settle`).

The rule: a start refined from already is not refined from again; a restart is
numbered by the attempts made (``restart_01`` ...), kept or not; at most ``limit`` are
made; and the caller keeps a restart's answer only where it is lower (a refinement
returns the best point it saw, so one from an answer never ends above it).

The arrays' re-run from the next-best run (the MISO paper's rule,
:mod:`tsid_fmu.search.taguchi.stage`) is not a restart in this sense: it re-conducts an
orthogonal array, within the Taguchi procedure, and stays there.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from tsid_fmu.search.stage import StageResult

__all__ = ["Pick", "Refine", "Restarts"]

#: Refines from a start; called with the start, the restart's number (1, 2, ...) and
#: why it is made (whatever the caller's ``pick`` gave: a reason, or where it came from).
Refine = Callable[[dict[str, float], int, Any], StageResult]

#: The next start and why it is wanted, or ``None`` when none is (settled, none left).
Pick = Callable[[], tuple[dict[str, float], Any] | None]


@dataclass
class Restarts:
    """The restarts of one answer: where they started, how many, how many may run.

    Attributes
    ----------
    limit : float
        Most restarts made (``inf``: as many as the caller asks for).
    tried : list of dict
        The starts refined from so far (a candidate's shares its own list).
    count : int
        Restarts made so far; the next one is number ``count + 1``.
    """

    limit: float = math.inf
    tried: list[dict[str, float]] = field(default_factory=list)
    count: int = 0

    @property
    def left(self) -> bool:
        """Whether another restart may be made."""
        return self.count < self.limit

    def run(self, start: Mapping[str, float], refine: Refine, why: Any = "") -> StageResult | None:
        """Refine from ``start``; ``None`` where it was tried already or none is left."""
        start = {k: float(v) for k, v in start.items()}
        if not self.left or start in self.tried:
            return None
        self.count += 1
        self.tried.append(dict(start))
        return refine(start, self.count, why)

    def loop(self, pick: Pick, refine: Refine) -> list[StageResult]:
        """Restart while ``pick`` gives a start and restarts are left; return the stages.

        ``pick`` is asked again after each restart, so it judges the answer as the
        restart left it (``refine`` puts the stage where ``pick`` sees it).
        """
        out: list[StageResult] = []
        while self.left:
            found = pick()
            if found is None:
                break
            stage = self.run(found[0], refine, found[1])
            if stage is None:
                break
            out.append(stage)
        return out
