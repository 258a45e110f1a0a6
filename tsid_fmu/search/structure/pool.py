"""The candidate structures identified so far, and how one more joins them.

:func:`~tsid_fmu.search.structure.compare.run_structure` adds the candidates the mixed
arrays ranked (simplest first), then, while the comparison goes on, the structures one
factor's level away from its choice (:meth:`Pool.neighbours`); a candidate not at its
optimum by a nesting is restarted (:meth:`Pool.restart`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from tsid_fmu.search.context import Context
from tsid_fmu.search.local.restarts import Restarts
from tsid_fmu.search.phases.stage import Evaluators
from tsid_fmu.search.stage import StageResult
from tsid_fmu.search.structure.arrays import DiscreteFactor
from tsid_fmu.search.structure.candidates import (
    embedded_answers,
    identify_candidate,
    measure_in,
    own_study,
    short,
    warm_starts,
)
from tsid_fmu.search.structure.nesting import known
from tsid_fmu.search.structure.optima import settle, update
from tsid_fmu.search.structure.selection import Candidate
from tsid_fmu.study.definition import Study

__all__ = ["Pool", "label"]


def label(factors: list[DiscreteFactor], values: Mapping[str, float]) -> str:
    """Return a structure's name, ``factor=level`` for each discrete factor."""
    return ", ".join(f"{f.name}={f.labels[f.values.index(values[f.name])]}" for f in factors)


@dataclass
class Pool:
    """The candidates, each with its stages, study, evaluators and own study."""

    ctx: Context
    make: Callable[[Study], Evaluators]
    factors: list[DiscreteFactor]
    cands: list[Candidate] = field(default_factory=list)
    stages: list[list[StageResult]] = field(default_factory=list)
    studies: list[Study] = field(default_factory=list)
    evs: list[Evaluators] = field(default_factory=list)
    owns: list[tuple[Study, Callable]] = field(default_factory=list)
    started: set[tuple[int, int]] = field(default_factory=set)  # (simpler, richer) embedded
    cache: dict = field(default_factory=dict)  # nesting checks, embeddings found before

    def add(self, values: dict[str, float], origin: str, probed: tuple) -> bool:
        """Identify one more candidate structure; return whether the study paused.

        ``probed`` is :func:`~tsid_fmu.search.structure.candidates.probe`'s answer. The
        first candidate gets a study of its own; every later one a refinement from the
        best of its warm starts (the earlier answers it nests, embedded, first).
        """
        ctx, cands, i = self.ctx, self.cands, len(self.cands)
        sub, ev, best, active, n_probe = probed
        name = label(self.factors, values)
        if ctx.progress:
            ctx.progress("stage", {"name": f"structure {i + 1}", "message": f"structure {name}"})
        own = (own_study(ctx.study, values, active, best), self.make)
        self.owns.append(own)
        if i == 0:
            origin += f"; the simplest ({len(active)} free parameters): a study of its own"
        embedded, n_embed = [], 0
        if cands:
            embedded, n_embed = embedded_answers(ctx.study, cands, active, best, ev)
            for s, point, _ in embedded:
                self.started.add((s, i))
                known(self.cache, s, i, cands[s], point)
        warm = warm_starts(ctx.study, cands, best, embedded) if cands else None
        cand, stages = identify_candidate(
            ctx, i, values, origin, own if i == 0 else None, sub, ev, warm
        )
        cand.nfev += n_probe + n_embed
        cand.label = name
        cand.free = list(active)  # free at the arrays' best point, off any bound
        cands.append(cand)
        self.stages.append(stages)
        self.studies.append(sub)
        self.evs.append(ev)
        return stages[-1].status == 2

    def neighbours(self, chosen: int) -> list[tuple[dict[str, float], str]]:
        """Return the structures one factor's level away from the choice, not yet candidates.

        The candidates are those the mixed arrays ranked best, but the arrays score far
        from any fit, where a factor that matters at the optimum can look like noise. So
        the comparison is a local search over the structures too: each structure that
        differs from the choice in one factor's level is refined (from the choice's
        answer, embedded where it nests it), and the comparison is made again, until no
        neighbour of the choice is left unrefined. Where every combination is a
        candidate (at most :data:`~tsid_fmu.numerics.tuning.MAX_ALL`), there is none.
        Measured on the Cascaded Tanks (``examples/cascaded_tanks/structure.toml``, 24
        structures): the arrays' eight best did not include the one BIC chooses among
        all, whose Est RMSE is 0.162 V against the 0.255 V of their choice.
        """
        pick = self.cands[chosen]
        seen = [c.values for c in self.cands]
        out: list[tuple[dict[str, float], str]] = []
        for f in self.factors:
            for v in f.values:
                values = {**pick.values, f.name: v}
                if values not in seen and values not in [w for w, _ in out]:
                    level = f.labels[f.values.index(v)]
                    out.append((values, f"a neighbour of {pick.label}: {f.name}={level}"))
        return out

    def restart(self, i: int, start: dict[str, float], why: str) -> bool:
        """Refine candidate ``i`` again from ``start``; return whether its answer is lower.

        The candidate's :class:`~tsid_fmu.search.local.restarts.Restarts` shares its
        ``tried`` starts: one refined from already is not refined from again (the nesting
        unchanged since). The restart's number counts the kept ones, as the trail names
        their folders.
        """
        ctx, cand = self.ctx, self.cands[i]
        names = self.studies[i].parameter_names
        ev = self.evs[i].get(names, self.studies[i].identify_names(), {})
        kept = sum(1 for s in self.stages[i] if s.name.startswith("restart"))
        study = short(self.studies[i])

        def refine(point: dict[str, float], k: int, reason: str) -> StageResult:
            return settle(f"restart {k}: {reason}", study, point, ev, ctx.progress)

        stage = Restarts(tried=cand.tried, count=kept).run(start, refine, why)
        if stage is None:
            return False
        cand.nfev += stage.nfev
        if not stage.cost < cand.cost:
            return False
        ctx.store.write_stage(f"{cand.folder}/restart_{kept + 1:02d}", stage)
        self.stages[i].append(stage)
        update(cand, measure_in(ctx.study, self.evs[i], stage.x))
        cand.origin += f"; restarted {why}"
        return True

    def found(self) -> tuple[list, list, list, list]:
        """Return the candidates, their stages, studies and evaluators."""
        return self.cands, self.stages, self.studies, self.evs
