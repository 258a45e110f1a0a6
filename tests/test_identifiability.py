"""Standard errors (Cramer-Rao bound) of identified parameters."""

import numpy as np
import pytest


def test_standard_errors_match_least_squares_theory_for_the_lag(tmp_path):
    """For a first-order lag with white output noise the Cramer-Rao standard error of
    tau from the sensitivities equals the spread of least-squares estimates."""
    import pandas as pd
    from fmu_factory import build_c_fmu, lag_response

    from tsid_fmu.study import Experiment, Parameter, Study
    from tsid_fmu.study import serial_evaluator as Evaluator
    from tsid_fmu.uncertainty import standard_errors

    t = np.arange(0, 5.0 + 1e-9, 0.01)
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5)
    y = lag_response(t, u, 0.4) + np.random.default_rng(1).normal(0, 0.02, t.shape)
    pd.DataFrame({"time": t, "u": u, "y": y}).to_csv(tmp_path / "d.csv", index=False)
    study = Study(
        fmu=build_c_fmu(tmp_path),
        parameters=[Parameter("tau", [0.2, 0.4, 0.8])],
        experiments=[Experiment(data=tmp_path / "d.csv", inputs={"u": "u"}, outputs={"y": "y"})],
        replicates=1,
    )
    with Evaluator(study) as ev:
        res = standard_errors(ev, {"tau": 0.4})
    # analytic: d y / d tau by central differences of the exact response
    h = 1e-6
    dy = (lag_response(t, u, 0.4 + h) - lag_response(t, u, 0.4 - h)) / (2 * h)
    sigma = res.sigma["d"][0]
    expected = sigma / np.sqrt(np.sum(dy**2))
    assert res.std_error["tau"] == pytest.approx(expected, rel=1e-3)
    assert sigma == pytest.approx(0.02, rel=0.1)
    assert res.relative["tau"] == pytest.approx(100 * expected / 0.4, rel=1e-3)
