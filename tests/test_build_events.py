"""Events in Model Exchange and input interpolation in Co-Simulation, on small models.

The models are written here, not taken from ``models/``: the behaviour must come from
the generated code for any model's if-expressions, not from the bundled plants. Needs
pymoca, casadi and a C compiler (like ``test_build.py``).
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

pytest.importorskip("pymoca")
pytest.importorskip("casadi")
if shutil.which("cc") is None and shutil.which("gcc") is None:  # pragma: no cover
    pytest.skip("no C compiler", allow_module_level=True)

from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from tsid_fmu.build import build_fmu

# Acceleration -g1 above x = 0, +g2 below: the right-hand side jumps where x crosses 0
# (transversally, with v != 0), so a variable-step solver must stop there.
SWITCH = """
model Switch "Mass between two constant forces that switch at x = 0"
  parameter Real g1 = 10 "Acceleration towards 0 from above";
  parameter Real g2 = 40 "Acceleration towards 0 from below";
  output Real y "Position";
  Real x(start = 1, fixed = true) "Position";
  Real v(start = 0, fixed = true) "Velocity";
equation
  der(x) = v;
  der(v) = ACC;
  y = x;
end Switch;
"""
EVENT_ACC = "if x > 0 then -g1 else g2"
NO_EVENT_ACC = "noEvent(if x > 0 then -g1 else g2)"

INTEGRATOR = """
model Integrator "Integral of an input, and the input passed through"
  input Real u(start = 0) "Input";
  output Real y "Integral of u";
  output Real yu "The input";
  Real x(start = 0, fixed = true) "State";
equation
  der(x) = u;
  y = x;
  yu = u;
  annotation(__tsid_fmu(fixedStepSize = 0.025));
end Integrator;
"""

# A relation whose operands come from an algebraic loop solved by Newton at run time.
LOOP_SWITCH = """
model LoopSwitch "Nonlinear algebraic loop with a switching right-hand side"
  input Real u(start = 2) "Drive";
  output Real y "Solution of y + y^3/2 = w";
  Real x(start = 1, fixed = true) "State";
  Real w "Right-hand side of the loop";
equation
  der(x) = u - x;
  y + 0.5 * y^3 = w;
  w = if y > 1 then x else 2 * x - 1.5;
end LoopSwitch;
"""


# A rate that is on only while x = t is inside a band [0.54, 0.56], which lies inside
# one internal step [0.5, 0.6]: the relation flips and flips back within that step, and
# neither end of it sees the band. Exact: y = clip(t - 0.54, 0, 2 w).
BAND = """
model Band "Time spent inside a narrow band, crossed within one internal step"
  parameter Real w = 0.01 "Half width of the band";
  output Real y "Time spent inside the band";
  Real x(start = 0, fixed = true) "Position, equal to time";
  Real q(start = 0, fixed = true) "Time spent inside the band";
equation
  der(x) = 1;
  der(q) = if INSIDE then 1 else 0;
  y = q;
  annotation(__tsid_fmu(fixedStepSize = 0.1));
end Band;
"""


def _build(tmp_path, source: str, name: str, version: int = 2):
    mo = tmp_path / f"{name}.mo"
    mo.write_text(source)
    return build_fmu(mo, name, tmp_path / f"{name}{version}.fmu", fmi_version=version)


def switch_exact(t: np.ndarray, x0: float = 1.0, g1: float = 10.0, g2: float = 40.0):
    """Position of the Switch model: parabolic arcs, period 2*sqrt(2*x0/g1) + 2*v/g2."""
    t_fall = np.sqrt(2 * x0 / g1)  # x0 -> 0 under -g1
    vmax = np.sqrt(2 * g1 * x0)
    t_below = 2 * vmax / g2  # excursion below 0 under +g2
    period = 2 * t_fall + t_below
    tau = np.mod(t, period)
    x = np.empty_like(tau)
    a = tau < t_fall
    x[a] = x0 - 0.5 * g1 * tau[a] ** 2
    b = (tau >= t_fall) & (tau < t_fall + t_below)
    s = tau[b] - t_fall
    x[b] = -vmax * s + 0.5 * g2 * s**2
    c = tau >= t_fall + t_below
    s = tau[c] - t_fall - t_below
    x[c] = vmax * s - 0.5 * g1 * s**2
    return x


@pytest.mark.parametrize("version", [2, 3])
def test_if_expression_becomes_event_indicator_and_me_locates_switches(tmp_path, version):
    fmu = _build(tmp_path, SWITCH.replace("ACC", EVENT_ACC), "Switch", version)
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert md.numberOfEventIndicators == 1
    t = np.linspace(0.0, 3.0, 3001)
    exact = switch_exact(t)
    kw = {"stop_time": 3.0, "output_interval": 1e-3, "output": ["y"]}
    me = simulate_fmu(
        str(fmu), fmi_type="ModelExchange", relative_tolerance=1e-10, record_events=False, **kw
    )
    cs = simulate_fmu(str(fmu), fmi_type="CoSimulation", step_size=1e-3, **kw)
    # the switches are located: both modes follow the arcs to far below the step error
    # an unlocated jump of the acceleration (g1 + g2)*h^2 ~ 5e-5 would cause per switch
    assert np.max(np.abs(me["y"] - exact)) < 1e-6
    assert np.max(np.abs(cs["y"] - exact)) < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("inside", ["abs(x - 0.55) <= w", "(x - 0.55)^2 <= w^2"])
def test_cs_locates_a_switch_that_flips_back_within_one_internal_step(tmp_path, version, inside):
    fmu = _build(tmp_path, BAND.replace("INSIDE", inside), "Band", version)
    kw = {"step_size": 0.1, "output_interval": 0.1, "stop_time": 1.0, "output": ["y"]}
    res = simulate_fmu(str(fmu), fmi_type="CoSimulation", **kw)
    assert len(res) == 11  # one communication step per internal step
    exact = np.clip(res["time"] - 0.54, 0.0, 0.02)
    # without both switches located, RK4 sees the band at its midpoint stages only, and
    # y ends near 0.067 instead of 0.02
    np.testing.assert_allclose(res["y"], exact, rtol=0, atol=1e-9)


def test_relations_inside_no_event_are_not_event_indicators(tmp_path):
    fmu = _build(tmp_path, SWITCH.replace("ACC", NO_EVENT_ACC), "Switch")
    assert validate_fmu(str(fmu)) == []
    assert read_model_description(str(fmu)).numberOfEventIndicators == 0


def test_relation_in_algebraic_loop_is_an_event_indicator(tmp_path):
    fmu = _build(tmp_path, LOOP_SWITCH, "LoopSwitch")
    assert validate_fmu(str(fmu)) == []
    assert read_model_description(str(fmu)).numberOfEventIndicators == 1
    kw = {"stop_time": 2.0, "output_interval": 1e-3, "output": ["x", "y", "w"]}
    me = simulate_fmu(
        str(fmu), fmi_type="ModelExchange", relative_tolerance=1e-10, record_events=False, **kw
    )
    x, y, w = me["x"], me["y"], me["w"]
    np.testing.assert_allclose(x, 2 - np.exp(-me["time"]), atol=1e-8)
    np.testing.assert_allclose(y + 0.5 * y**3, w, atol=1e-10)
    # the branch follows the relation y > 1 on both sides of the switch
    np.testing.assert_allclose(w, np.where(y > 1, x, 2 * x - 1.5), atol=1e-8)
    assert (y < 1).any() and (y > 1).any()


def _slave2(fmu):
    md = read_model_description(str(fmu))
    f = FMU2Slave(
        guid=md.guid,
        unzipDirectory=extract(str(fmu)),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="interp",
    )
    return f, {v.name: v.valueReference for v in md.modelVariables}


def _ramp(f, set_u, a, b, h, steps=20):
    """Drive the slave ``f``, in initialization mode, with the input ramp ``u = a + b*t``.

    ``set_u(value)`` sets the input. Sets ``u = a``, leaves initialization mode, then for
    each of ``steps`` steps of ``h`` sets ``u`` to its value at the step's start ``t`` and
    yields ``t`` (the caller does the step); after the last step terminates and frees ``f``.
    """
    set_u(a)
    f.exitInitializationMode()
    for k in range(steps):
        t = k * h
        set_u(a + b * t)
        yield t
    f.terminate()
    f.freeInstance()


@pytest.mark.parametrize("interpolate", [True, False])
def test_fmi2_input_derivatives_give_exact_interpolation(tmp_path, interpolate):
    fmu = _build(tmp_path, INTEGRATOR, "Integrator")
    assert read_model_description(str(fmu)).coSimulation.canInterpolateInputs
    f, vr = _slave2(fmu)
    a, b, h = 1.0, 2.0, 0.1  # u(t) = a + b*t, integral a*t + b*t^2/2
    f.instantiate()
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    rows = []
    for t in _ramp(f, lambda u: f.setReal([vr["u"]], [u]), a, b, h):
        if interpolate:
            f.setRealInputDerivatives([vr["u"]], [1], [b])
        f.doStep(t, h)
        rows.append(f.getReal([vr["y"], vr["yu"]]))
    y, yu = np.array(rows).T
    t = np.arange(1, 21) * h
    if interpolate:
        # RK4 integrates the interpolated ramp exactly; at the end of a step the input
        # holds its interpolated value, so the feed-through output is current too
        np.testing.assert_allclose(y, a * t + 0.5 * b * t**2, rtol=0, atol=1e-12)
        np.testing.assert_allclose(yu, a + b * t, rtol=0, atol=1e-12)
    else:
        # held inputs: the integral of the staircase, half a step behind
        np.testing.assert_allclose(y, a * t + 0.5 * b * t * (t - h), rtol=0, atol=1e-12)
        np.testing.assert_allclose(yu, a + b * (t - h), rtol=0, atol=1e-12)


def test_fmi3_intermediate_update_gives_exact_interpolation(tmp_path):
    fmu = _build(tmp_path, INTEGRATOR, "Integrator", version=3)
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert md.coSimulation.providesIntermediateUpdate
    vr = {v.name: v.valueReference for v in md.modelVariables}
    a, b, h = 1.0, 2.0, 0.1
    calls: list[float] = []
    f = FMU3Slave(
        guid=md.guid,
        unzipDirectory=extract(str(fmu)),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="interp",
    )

    def intermediate_update(env, t, set_requested, get_allowed, finished, can_return, *_):
        assert set_requested and not get_allowed and not can_return
        calls.append(t)
        f.setFloat64([vr["u"]], [a + b * t])  # the importer's interpolation

    f.instantiate(intermediateUpdate=intermediate_update, requiredIntermediateVariables=[vr["u"]])
    f.enterInitializationMode(startTime=0.0)
    rows = []
    for t in _ramp(f, lambda u: f.setFloat64([vr["u"]], [u]), a, b, h):
        n0 = len(calls)
        f.doStep(t, h)
        inside = np.array(calls[n0:])
        assert inside.min() >= t - 1e-15 and inside.max() <= t + h + 1e-15
        assert np.isclose(inside, t + 0.0125).any()  # RK4 midpoint of the first substep
        rows.append(f.getFloat64([vr["y"], vr["yu"]]))
    y, yu = np.array(rows).T
    t = np.arange(1, 21) * h
    np.testing.assert_allclose(y, a * t + 0.5 * b * t**2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(yu, a + b * t, rtol=0, atol=1e-12)
