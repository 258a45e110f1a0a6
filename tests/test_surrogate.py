import numpy as np
import pytest

from tsid_fmu.arrays import get_array
from tsid_fmu.surrogate import quadratic_optimum


def test_quadratic_surface_follows_a_valley_that_main_effects_miss():
    # S/N of a valley: best along u - v = 0.3, weakly pulled to u = 0.2
    arr = get_array("L25")
    z = (arr.table[:, :2] - 2) / 2.0  # five levels -1 .. 1
    u, v = z[:, 0], z[:, 1]
    sn = -10 * (u - v - 0.3) ** 2 - (u - 0.2) ** 2
    best = quadratic_optimum(z, sn)
    assert best == pytest.approx([0.2, -0.1], abs=1e-6)


def test_failed_runs_are_left_out_and_small_designs_are_refused():
    arr = get_array("L9")
    z = arr.table[:, :2] - 1.0
    sn = -((z[:, 0] - 0.5) ** 2) - (z[:, 1] + 0.25) ** 2
    sn[3] = -np.inf
    assert quadratic_optimum(z, sn) == pytest.approx([0.5, -0.25], abs=1e-6)
    assert quadratic_optimum(z[:4], sn[:4]) is None
