"""A standard error below what the profile likelihood resolves is reported as a bound."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from tsid_fmu import IdentificationResult
from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.report.notebook import parameter_rows
from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.assess import _widen_by_profile
from tsid_fmu.uncertainty.intervals import Uncertainty

X0 = {"sharp": 3.0, "soft": 5.0}


class _Quadratic:
    """Residuals ``[1] * 100 + gain_j (x_j - x0_j) / x0_j``: cost 100 at ``X0``."""

    def __init__(self, gains: dict[str, float]) -> None:
        self.gains = gains

    def evaluate(self, sets):
        rs = [
            np.concatenate(
                [np.ones(100), [g * (x[n] - X0[n]) / X0[n] for n, g in self.gains.items()]]
            )
            for x in sets
        ]
        return SimpleNamespace(costs=np.array([[float(r @ r)] for r in rs]), residuals=rs)


def _assessed() -> Uncertainty:
    space = Space(
        {n: [0.5 * v, 2 * v] for n, v in X0.items()},
        {n: (0.01, 1000.0) for n in X0},
        LevelingOptions(scale="log"),
    )
    scales = [space.local_scale(j, X0[n]) for j, n in enumerate(space.names)]
    # "soft": the cost rises by the 95 % threshold (3.84) about 0.01 coordinates out;
    # "sharp": already within the profile's resolution
    gains = {"sharp": 1e9, "soft": 196.0 * X0["soft"] / scales[1]}
    jac = np.zeros((102, 1, 2))
    for j, n in enumerate(space.names):
        jac[100 + j, 0, j] = gains[n] * scales[j] / X0[n]
    u = Uncertainty(
        values=dict(X0),
        std_error={n: 1e-12 for n in X0},
        relative={n: 1e-10 for n in X0},
        intervals={n: [v, v] for n, v in X0.items()},
    )
    spec = SimpleNamespace(experiments=[SimpleNamespace(scale=np.ones(1))])
    sens = SimpleNamespace(jacobian=[jac])
    _widen_by_profile(_Quadratic(gains), spec, space, sens, u, x=dict(X0), cost=100.0)
    return u


def test_a_standard_error_at_the_profile_floor_is_a_bound_not_an_estimate():
    u = _assessed()
    assert set(u.resolution) == {"sharp"}
    assert u.resolution["sharp"] == u.relative["sharp"] > 0
    assert math.isfinite(u.relative["soft"]) and u.relative["soft"] > u.resolution["sharp"]
    res = IdentificationResult(
        params=dict(X0), fun=100.0, nfev=1, success=True, status=0, message="m", uncertainty=u
    )
    rows = {r[0]: r for r in parameter_rows(res)}
    assert isinstance(rows["sharp"][4], str)
    assert rows["sharp"][4].startswith("below the profile's resolution (< ")
    assert rows["soft"][4] == u.relative["soft"]  # a real estimate stays a number
    assert u.to_dict()["resolution"] == {"sharp": u.relative["sharp"]}


def test_report_md_writes_the_bound_too():
    from pathlib import Path

    from tsid_fmu.report.markdown import markdown_report
    from tsid_fmu.study import Study

    study = Study.from_toml(Path(__file__).resolve().parents[1] / "examples/lsea_siso/study.toml")
    x = {n: 2.0 for n in study.parameter_names}
    u = Uncertainty(values=x, relative={n: 3.0 for n in x}, resolution={"K_s": 0.014685})
    res = IdentificationResult(
        params=x, fun=1.0, nfev=1, success=True, status=0, message="m", study=study, uncertainty=u
    )
    rows = [r for r in markdown_report(res).splitlines() if r.startswith("| K_s |")]
    # a "<" that opens no tag stays as written (issue 62: report.md reads as text too)
    assert len(rows) == 1 and "below the profile's resolution (< 0.015)" in rows[0]
    assert "0.014685" not in rows[0]
