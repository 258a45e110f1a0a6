"""Only the ratios of weights matter: a common scale changes no answer (issue 45).

Multiplying every weight by one constant must not change the answer, its intervals or
its verdict. It did: on the SISO example's first 2 s, window weights of 1e-6 ended 0.39 %
above the optimum, and 1e-300 gave exit 0 at the first array's point, because a few
thresholds compare the cost with absolute figures. Every weight is now divided by the
study's largest (:func:`tsid_fmu.study.prepare.weight_norms`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from fmu_factory import lag_data
from hypothesis import given, settings
from hypothesis import strategies as st

from tsid_fmu import Experiment, Method, Parameter, Study, identify
from tsid_fmu.study.prepare import prepare, weight_norms


@pytest.fixture(scope="module")
def lag(tmp_path_factory):
    d = tmp_path_factory.mktemp("wscale")
    fmu, data = lag_data(d, 0.37, 0.8)
    frame = pd.read_csv(data)
    frame["y2"] = 2.0 * frame["y_meas"] + np.random.default_rng(3).normal(0, 0.02, len(frame))
    both = d / "two.csv"
    frame.to_csv(both, index=False)
    return fmu, both


def _study(lag, k: float, max_iterations: int = 3) -> Study:
    """Every output weight and every window weight times ``k`` (the cost times k**2)."""
    fmu, data = lag
    return Study(
        fmu=fmu,
        parameters=[
            Parameter("tau", [0.05, 0.5, 2.0], min=0.0),
            Parameter("x0", [-1.0, 0.0, 2.0]),
        ],
        experiments=[
            Experiment(
                data,
                inputs={"u": "u"},
                outputs={"y": "y_meas"},
                name="a",
                weights={"y": 1.0 * k},
                windows=[[0.0, 2.0], [2.5, 5.0]],
                window_weights=[0.5 * k, 1.0 * k],
            ),
            Experiment(
                data,
                inputs={"u": "u"},
                outputs={"y": "y2"},
                name="b",
                weights={"y": 0.25 * k},
                windows=[[0.0, 5.0]],
                window_weights=[0.75 * k],
            ),
        ],
        method=Method(cost="sse", weighting="noise", replicates=1, max_iterations=max_iterations),
    )


@settings(max_examples=40, deadline=None)
@given(st.floats(min_value=-12.0, max_value=12.0))
def test_the_weights_the_evaluators_get_do_not_depend_on_a_common_scale(lag, exponent):
    k = 10.0**exponent
    ref, scaled = prepare(_study(lag, 1.0)), prepare(_study(lag, k))
    for e1, ek in zip(ref.experiments, scaled.experiments, strict=True):
        np.testing.assert_allclose(ek.weights, e1.weights, rtol=1e-14)
        np.testing.assert_allclose(ek.scale, e1.scale, rtol=1e-14)
        np.testing.assert_allclose(ek.window_weights, e1.window_weights, rtol=1e-14)
    assert max(ref.experiments[0].window_weights) == 1.0  # the largest counts 1
    assert ref.experiments[1].window_weights == (0.75,)


def test_the_norms_are_the_largest_output_and_window_weights(lag):
    assert weight_norms(_study(lag, 1.0)) == (1.0, 1.0)
    assert weight_norms(_study(lag, 1e-6)) == (1e-6, 1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("k", [1e-6, 1e6])
def test_a_study_gives_the_same_answer_and_exit_with_every_weight_scaled(lag, k):
    one = identify(_study(lag, 1.0), progress=False, plots=False)
    scaled = identify(_study(lag, k), progress=False, plots=False)
    assert scaled.status == one.status and scaled.nfev == one.nfev
    np.testing.assert_allclose(scaled.x, one.x, rtol=1e-9)
    np.testing.assert_allclose(scaled.fun, one.fun, rtol=1e-9)  # in the normalised units
    for name in one.params:
        np.testing.assert_allclose(scaled.intervals[name], one.intervals[name], rtol=1e-9)
