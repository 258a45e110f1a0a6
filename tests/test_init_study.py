"""The study `tsid init` writes for the bundled SISO example, run unedited, as a user would.

It must end with exit status 0 at the least-squares optimum of its own cost, checked
against SciPy's ``least_squares`` over :func:`tsid_fmu.simulate` with the noise weights
the result reports (an independent path to the same cost: no evaluator, no memo).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import least_squares

import tsid_fmu
from tsid_fmu.scaffold import init_study
from tsid_fmu.search.taguchi.start import fmu_start_values

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_init_study_of_the_siso_example_converges_at_the_least_squares_optimum(tmp_path):
    path = tmp_path / "study.toml"
    init_study(ROOT / "fmus" / "LSEA_SISO.fmu", ROOT / "examples/lsea_siso/measured.csv", path)
    res = tsid_fmu.identify(path, workers=1, plots=False)
    assert res.status == 0 and res.success, res.message
    assert res.message.startswith("converged: the answer is stationary")
    assert res.account[-1].startswith("verdict: stationary at the answer")

    study = tsid_fmu.Study.from_toml(path)
    (exp,) = study.experiments
    data = pd.read_csv(ROOT / "examples/lsea_siso/measured.csv")
    names = study.parameter_names
    sigma = res.noise[exp.name]
    outputs = list(exp.outputs)
    measured = np.column_stack([data[exp.outputs[o]].to_numpy() for o in outputs])
    scale = np.array([sigma[o] for o in outputs])

    def residuals(v: np.ndarray) -> np.ndarray:
        sim = tsid_fmu.simulate(
            study.fmu,
            data,
            inputs=dict(exp.inputs),
            outputs=outputs,
            parameters=dict(zip(names, 10.0**v, strict=True)),
            start_values=dict(study.start_values),
        )
        return ((sim[outputs].to_numpy() - measured) / scale).ravel()

    at_answer = residuals(np.log10([res.params[n] for n in names]))
    assert float(at_answer @ at_answer) == pytest.approx(res.fun, rel=1e-3)
    start = np.log10([fmu_start_values(study.fmu, names)[n] for n in names])
    fit = least_squares(residuals, start, method="trf", x_scale="jac")
    optimum = min(2.0 * fit.cost, float(at_answer @ at_answer))
    assert res.fun <= 1.001 * optimum, (res.fun, 2.0 * fit.cost)
