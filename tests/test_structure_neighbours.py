"""The comparison's local search over structures: the neighbours of its choice."""

from __future__ import annotations

from types import SimpleNamespace

from tsid_fmu.search.structure.arrays import DiscreteFactor
from tsid_fmu.search.structure.pool import Pool, label

FACTORS = [
    DiscreteFactor("outflow", [0.0, 1.0], ["0", "1"]),
    DiscreteFactor("pump", [0.0, 1.0, 2.0], ["linear", "dead zone", "saturation"]),
]


def _pool(*values: dict[str, float]) -> Pool:
    pool = Pool(ctx=None, make=None, factors=FACTORS)  # type: ignore[arg-type]
    pool.cands = [SimpleNamespace(values=v, label=label(FACTORS, v)) for v in values]  # type: ignore[misc]
    return pool


def test_the_neighbours_are_the_structures_one_level_away_not_yet_refined():
    pool = _pool({"outflow": 0.0, "pump": 0.0}, {"outflow": 0.0, "pump": 2.0})
    steps = pool.neighbours(0)
    assert [v for v, _ in steps] == [{"outflow": 1.0, "pump": 0.0}, {"outflow": 0.0, "pump": 1.0}]
    assert steps[1][1] == "a neighbour of outflow=0, pump=linear: pump=dead zone"


def test_a_choice_whose_neighbours_are_all_refined_has_none():
    every = [{"outflow": o, "pump": p} for o in (0.0, 1.0) for p in (0.0, 1.0, 2.0)]
    assert _pool(*every).neighbours(3) == []
    # two levels away is no neighbour: the comparison walks one factor at a time
    assert {"outflow": 1.0, "pump": 2.0} not in [v for v, _ in _pool(*every[:1]).neighbours(0)]
