"""``to_pandas()`` has fewer rows than ``nfev`` counts simulations, and says why."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd

from tsid_fmu import IdentificationResult
from tsid_fmu.search.stage import StageResult


def _record(index: int, runs: int, nfev: int) -> SimpleNamespace:
    frame = pd.DataFrame({"stage": "taguchi", "iteration": index, "run": range(1, runs + 1)})
    return SimpleNamespace(sets=np.zeros((runs, 2)), nfev=nfev, runs_frame=lambda: frame)


def test_the_runs_frame_accounts_for_every_simulation_nfev_counts():
    # two experiments: each run of an L9 is 2 simulations, its confirmation run 2 more
    records = [_record(1, 9, 20), _record(2, 9, 20)]
    taguchi = StageResult("taguchi", "taguchi", {}, 1.0, 44, "done", records=records)  # type: ignore[arg-type]
    refine = StageResult("refinement", "refinement", {}, 0.5, 30, "done")
    check = StageResult("check", "check", {}, 0.5, 6, "stationary")
    res = IdentificationResult(
        params={},
        fun=0.5,
        nfev=80,
        success=True,
        status=0,
        message="m",
        stages=[taguchi, refine, check],
    )
    runs = res.to_pandas()
    assert len(runs) == 18 < res.nfev
    assert "start points" in runs.attrs["note"] and "confirmation run" in runs.attrs["note"]
    spent = res.simulations_frame()
    assert spent["simulations"].sum() == res.nfev
    assert spent.loc["taguchi", "array runs"] == len(runs)
    assert spent.loc["taguchi", "confirmation runs"] == 2
    assert spent.loc["taguchi", "array simulations"] == 40
    assert spent.loc["taguchi", "other simulations"] == 4  # the start points
    assert spent.loc["refinement", "other simulations"] == 30
    assert runs.attrs["simulations"]["check"]["simulations"] == 6
