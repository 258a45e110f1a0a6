"""Output timing with direct feed-through, and the hold of each input between samples.

The FMU of ``feed_factory`` passes its inputs ``a``, ``b`` straight to ``ya``, ``yb``
and integrates them exactly into ``za``, ``zb``, so it shows both what the FMU sees at
the communication points and what it sees between them.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from feed_factory import build_feed_fmu
from fmu_factory import build_c_fmu, lag_response

from tsid_fmu.errors import FMUError
from tsid_fmu.fmu import FMUSession
from tsid_fmu.fmu import compiled as fastloop
from tsid_fmu.fmu import grid as grid_module
from tsid_fmu.fmu.exchange import input_signal
from tsid_fmu.fmu.grid import refine

OUT = ["ya", "yb", "za", "zb", "nder"]
BACKENDS = ["numba", "python"]


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    d = tmp_path_factory.mktemp("hold")
    return {
        "fmi2": build_feed_fmu(d, "Feed2"),
        "fmi2_interp": build_feed_fmu(d, "Feed2I", can_interpolate=True),
        "fmi3": build_feed_fmu(d, "Feed3", fmi_version="3.0"),
        "lag": build_c_fmu(d, "HoldLag", interfaces=("cs",)),
    }


@pytest.fixture
def samples():
    t = np.arange(201) * 0.01
    return t, np.column_stack([np.sin(7 * t) + (t > 0.8), np.cos(3 * t)])


@pytest.fixture(params=BACKENDS)
def backend(request, monkeypatch):
    if request.param == "numba" and not fastloop.numba_available():
        pytest.skip("Numba not installed")
    if request.param == "python":
        monkeypatch.setenv(fastloop.LOOP_ENV, "python")
    yield request.param
    assert fastloop.backend() == request.param  # the compiled loop never fell back


def fine_grid(t: np.ndarray, m: int) -> np.ndarray:
    """Each sample interval split into m equal steps (what ``substeps=m`` runs on)."""
    parts = [np.linspace(a, b, m, endpoint=False) for a, b in itertools.pairwise(t)]
    return np.concatenate([*parts, t[-1:]])


@pytest.mark.parametrize("kind", ["fmi2", "fmi2_interp", "fmi3"])
def test_feedthrough_output_has_no_lag(fmus, samples, kind, backend):
    """The output at t[k] sees the input of t[k], at k = 0 too (no one-step lag)."""
    t, u = samples
    with FMUSession(fmus[kind], ["a", "b"], OUT) as s:
        y = s.simulate(t, u, {})
    np.testing.assert_array_equal(y[:, :2], u)
    # zero-order hold: the integral is the left Riemann sum
    left = np.concatenate([[0.0], np.cumsum(np.diff(t) * u[:-1, 0])])
    np.testing.assert_allclose(y[:, 2], left, rtol=1e-13, atol=1e-15)
    assert y[-1, 4] == 0  # no input derivatives for held inputs


def held_linear(t: np.ndarray, u: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The fine grid and what a linear input holds over each step with ``substeps=m``.

    From a sample the sample itself; from a communication point inside an interval the
    line's value at the middle of the step that starts there. (The last entry, the last
    sample, starts no step.)
    """
    tf = fine_grid(t, m)
    values = np.interp(tf, t, u)
    inner = np.ones(tf.size - 1, dtype=bool)
    inner[::m] = False
    mid = tf[:-1][inner] + 0.5 * np.diff(tf)[inner]
    values[:-1][inner] = np.interp(mid, t, u)
    return tf, values


@pytest.mark.parametrize("kind", ["fmi2", "fmi3"])
def test_linear_input_is_interpolated_between_samples_held_input_is_a_step(
    fmus, samples, kind, backend, monkeypatch
):
    """Linear ``a`` with 4 substeps: at every communication point, samples or between
    them, the FMU sees exactly the linearly interpolated signal (its feed-through ``ya``),
    and ``b`` the step signal (``yb``); over each step it holds the line's value at the
    step's middle (its integral ``za`` is that of a session given that staircase).
    """
    t, u = samples
    m = 4
    session = {"hold": {"a": "linear"}, "substeps": m}
    with FMUSession(fmus[kind], ["a", "b"], OUT, **session) as s:
        assert s.hold == {"a": "linear", "b": "previous"}
        coarse = s.simulate(t, u, {})
    refine_real = grid_module.refine  # the same run, keeping every communication point
    monkeypatch.setattr(
        grid_module, "refine", lambda *a, **k: refine_real(*a, **k)._replace(keep=None)
    )
    with FMUSession(fmus[kind], ["a", "b"], OUT, **session) as s:
        every = s.simulate(t, u, {})
    tf = fine_grid(t, m)
    step = np.concatenate([np.repeat(u[:-1, 1], m), u[-1:, 1]])
    np.testing.assert_array_equal(every[:, 0], np.interp(tf, t, u[:, 0]))  # the line itself
    np.testing.assert_array_equal(every[:, 1], step)  # held between samples
    k = 10  # at a point between samples the linear input is neither neighbour
    assert every[k * m + 1, 0] == pytest.approx(u[k, 0] + 0.25 * (u[k + 1, 0] - u[k, 0]))
    assert every[k * m + 1, 0] not in (u[k, 0], u[k + 1, 0])
    np.testing.assert_array_equal(every[::m], coarse)
    np.testing.assert_array_equal(coarse[:, :2], u)  # still no lag at the samples
    _, held = held_linear(t, u[:, 0], m)
    with FMUSession(fmus[kind], ["a", "b"], OUT) as s:
        explicit = s.simulate(tf, np.column_stack([held, step]), {})
    np.testing.assert_array_equal(explicit[::m, 2:4], coarse[:, 2:4])  # za, zb


@pytest.mark.parametrize("m", [4, 10])
def test_substeps_of_a_linear_input_do_not_lag(fmus, m, backend):
    """The integral ``za`` of a ramp held on substeps: the staircase of midpoint values
    misses the exact (trapezoid) integral only in each interval's first step, by 1/m of
    what a staircase of the steps' start values would miss (half a substep's lag)."""
    t = np.arange(51) * 0.02
    u = np.column_stack([3.0 * t + np.sin(2 * t), np.zeros_like(t)])
    with FMUSession(fmus["fmi2"], ["a", "b"], OUT, hold={"a": "linear"}, substeps=m) as s:
        za = s.simulate(t, u, {})[:, 2]
    h = np.diff(t)
    slope = np.diff(u[:, 0]) / h
    trapezoid = np.concatenate([[0.0], np.cumsum(h * 0.5 * (u[:-1, 0] + u[1:, 0]))])
    start_lag = np.concatenate([[0.0], np.cumsum(m * 0.5 * (h / m) ** 2 * slope)])
    first_step = np.concatenate([[0.0], np.cumsum(0.5 * (h / m) ** 2 * slope)])
    np.testing.assert_allclose(trapezoid - za, first_step, rtol=1e-9, atol=1e-13)
    assert np.abs(trapezoid - za)[-1] <= 1.0001 * np.abs(start_lag)[-1] / m


def test_fmu_that_interpolates_gets_input_derivatives(fmus, samples, backend):
    """canInterpolateInputs: fmi2SetRealInputDerivatives with the slope, no substeps."""
    t, u = samples
    with FMUSession(fmus["fmi2_interp"], ["a", "b"], OUT, hold={"a": "linear"}) as s:
        y = s.simulate(t, u, {})
        again = s.simulate(t, u, {})
    np.testing.assert_array_equal(y, again)
    np.testing.assert_array_equal(y[:, :2], u)
    assert y[-1, 4] == t.size - 1  # one derivative call per step
    h = np.diff(t)
    trapezoid = np.concatenate([[0.0], np.cumsum(h * (u[:-1, 0] + u[1:, 0]) / 2)])
    np.testing.assert_allclose(y[:, 2], trapezoid, rtol=1e-12, atol=1e-15)
    left = np.concatenate([[0.0], np.cumsum(h * u[:-1, 1])])
    np.testing.assert_allclose(y[:, 3], left, rtol=1e-12, atol=1e-15)  # b held


def test_models_without_feedthrough_unchanged(fmus, samples):
    """The lag has no feed-through: the same exact zero-order-hold response as before."""
    t, u = samples
    with FMUSession(fmus["lag"], ["u"], ["y"], parameters=["tau"]) as s:
        y = s.simulate(t, u[:, 0], {"tau": 0.05})
    np.testing.assert_allclose(y[:, 0], lag_response(t, u[:, 0], 0.05), atol=1e-12)


def test_step_size_keeps_last_input_and_linear_hold_on_step_size(fmus, samples):
    t, u = samples
    with FMUSession(fmus["fmi2"], ["a", "b"], OUT, step_size=0.0025) as s:
        y = s.simulate(t, u, {})
    np.testing.assert_array_equal(y[:, :2], u)  # also the last sample
    with FMUSession(
        fmus["fmi2"], ["a", "b"], OUT, step_size=0.0025, hold={"a": "linear"}, substeps=2
    ) as s:
        lin = s.simulate(t, u, {})
    with FMUSession(fmus["fmi2"], ["a", "b"], OUT, hold={"a": "linear"}, substeps=4) as s:
        np.testing.assert_array_equal(lin, s.simulate(t, u, {}))  # max(4, 2) steps


def test_bad_holds_are_refused(fmus):
    with pytest.raises(FMUError, match=r"hold of input 'a' must be 'previous' or 'linear'"):
        FMUSession(fmus["fmi2"], ["a"], ["ya"], hold={"a": "cubic"})
    with pytest.raises(FMUError, match=r"hold given for 'aa'.*Did you mean 'a'"):
        FMUSession(fmus["fmi2"], ["a"], ["ya"], hold={"aa": "linear"})
    with pytest.raises(FMUError, match=r"substeps must be 1 to"):
        FMUSession(fmus["fmi2"], ["a"], ["ya"], substeps=0)
    with pytest.raises(FMUError, match=r"step_size must be a positive time"):
        FMUSession(fmus["fmi2"], ["a"], ["ya"], step_size=-1.0)


def test_refine_grid():
    t = np.array([0.0, 0.1, 0.3, 0.35])
    u = np.array([[1.0, 5.0], [2.0, 6.0], [0.0, 7.0], [4.0, 8.0]])
    g = refine("x", t, u, np.array([True, False]), native=False, substeps=3)
    np.testing.assert_array_equal(g.time, fine_grid(t, 3))
    np.testing.assert_array_equal(g.keep, [0, 3, 6, 9])
    # set at every point: the line there (at the samples the samples)
    np.testing.assert_array_equal(g.inputs[:, 0], np.interp(g.time, t, u[:, 0]))
    np.testing.assert_array_equal(g.inputs[g.keep, 0], u[:, 0])
    np.testing.assert_array_equal(g.inputs[:, 1], [5, 5, 5, 6, 6, 6, 7, 7, 7, 8])
    # held over each step: from a sample the sample, else the line at the step's middle
    _, expected = held_linear(t, u[:, 0], 3)
    np.testing.assert_array_equal(g.held[:, 0], expected[:-1])
    assert g.held[1, 0] == pytest.approx(1.5, rel=1e-12)  # step [1/3, 2/3] of 1 -> 2
    np.testing.assert_array_equal(g.held[:, 1], [5, 5, 5, 6, 6, 6, 7, 7, 7])
    assert g.slopes.shape == (9, 0)
    native = refine("x", t, u, np.array([True, False]), native=True, substeps=3)
    assert native.keep is None and native.held.shape == (0, 2)
    # an FMU that interpolates itself gets the line at the points and the slopes
    split = refine("x", t, u, np.array([True, False]), native=True, step_size=0.05)
    np.testing.assert_array_equal(split.inputs[:, 0], np.interp(split.time, t, u[:, 0]))
    assert split.held.shape == (0, 2) and split.slopes.shape == (split.time.size - 1, 1)
    held_only = refine("x", t, u, np.array([False, False]), native=False, step_size=0.05)
    assert held_only.held.shape == (0, 2)
    np.testing.assert_allclose(native.slopes[:, 0], np.diff(u[:, 0]) / np.diff(t))
    held = refine("x", t, u, np.array([False, False]), native=False, substeps=3)
    assert held.keep is None and held.slopes.shape == (3, 0)


def test_model_exchange_signal_holds_and_interpolates():
    t = np.array([0.0, 1.0, 2.0])
    u = np.array([[1.0, 10.0], [2.0, 20.0], [3.0, 30.0]])
    sig = input_signal(t, u, ["a", "b"], np.array([True, False]))
    np.testing.assert_array_equal(sig["time"], [0, 1, 1, 2, 2])
    np.testing.assert_array_equal(sig["a"], [1, 2, 2, 3, 3])  # continuous: linear
    np.testing.assert_array_equal(sig["b"], [10, 10, 20, 20, 30])  # event: held
