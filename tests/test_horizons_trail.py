"""Growing horizons on a real FMU: kept in the trail, read back by load() and on resume.

The lag FMU against data with an unmodelled ringing (``0.2 sin(7 t)``, twenty times the
noise): every answer is a poor fit, so the search follows the data from their first
part (:mod:`tsid_fmu.search.local.flow`), reaches the same answer again, and skips the
restarts; the warning says so.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from fmu_factory import lag_study

from tsid_fmu import Method, identify, load


def _ringing_study(tmp_path):
    study = lag_study(tmp_path, method=Method(cost="sse", weighting="noise", replicates=1))
    data = pd.read_csv(study.experiments[0].data)
    data["y_meas"] += 0.2 * np.sin(7.0 * data["time"])
    data.to_csv(study.experiments[0].data, index=False)
    return study


def test_horizons_are_kept_in_the_trail_and_read_back(tmp_path):
    study = _ringing_study(tmp_path)
    out = tmp_path / "out"
    res = identify(study, out, workers=1, timeout=0, plots=False)
    kinds = [s.kind for s in res.stages]
    assert kinds.count("horizon") == 3, kinds
    last = res.stages[-1]
    assert last.name == "refinement after the horizons" and last.agrees
    assert not any(s.name.startswith("restart") for s in res.stages)  # agreement: none
    assert any("from their first part reached the same answer" in w for w in res.warnings)
    for folder in ("horizon_01", "horizon_02", "horizon_03", "horizon_full"):
        assert (out / folder / "stage.json").is_file(), folder
    back = load(out)
    assert [(s.name, s.kind, s.nfev) for s in back.stages] == [
        (s.name, s.kind, s.nfev) for s in res.stages
    ]
    assert back.fun == res.fun
    again = identify(study, out, resume=True, workers=1, timeout=0, plots=False)
    assert again.fun == res.fun and list(again.x) == list(res.x)
    assert [s.nfev for s in again.stages] == [s.nfev for s in res.stages]
