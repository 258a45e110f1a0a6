"""Initial states that are expressions of parameters (issue 63, item 1).

Two Modelica idioms make an initial state identifiable: a ``start`` that names a
parameter (``Real x(start = x0, fixed = true)``) and an ``initial equation``
``x = <expression of parameters>``. The FMU computes the state from the parameter values
at initialisation (also after ``fmi2Reset``), and ``modelDescription.xml`` gives the
value at the parameters' defaults as the state's ``start``. Constructs that remain
unsupported are refused with their line in the ``.mo`` file.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

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
from tsid_fmu.errors import BuildError

#: x1 starts at the parameter x1_0 (start = parameter), x2 at 2*x1_0 + x2_off (initial
#: equation); both decay: x(t) = x(0) exp(-t/tau).
TANKS = """
model Tanks "Two decaying states whose initial values are parameters"
  parameter Real tau = 2 "Time constant";
  Real x1(start = x1_0, fixed = true) "Set by its start";
  Real x2 "Set by an initial equation";
  parameter Real x1_0 = 1.5 "Initial x1";
  parameter Real x2_off = 0.25 "Offset of the initial x2";
  output Real y "x1 + x2";
initial equation
  x2 = 2 * x1_0 + x2_off;
equation
  tau * der(x1) = -x1;
  tau * der(x2) = -x2;
  y = x1 + x2;
end Tanks;
"""

TAU, X1_0, X2_OFF = 2.0, 1.5, 0.25


@pytest.fixture(scope="module")
def tanks(tmp_path_factory) -> dict[int, Path]:
    """The model built as FMI 2.0 and FMI 3.0 FMUs."""
    d = tmp_path_factory.mktemp("tanks")
    mo = d / "Tanks.mo"
    mo.write_text(TANKS)
    return {v: build_fmu(mo, "Tanks", d / f"Tanks{v}.fmu", fmi_version=v) for v in (2, 3)}


def _variables(fmu: Path) -> dict[str, dict[str, str]]:
    """Attributes of each variable (with those of its type element) by name."""
    with zipfile.ZipFile(fmu) as zf:
        root = ET.fromstring(zf.read("modelDescription.xml"))
    out = {}
    for mv in root.iter("ModelVariables"):
        for sv in mv:
            attrs = dict(sv.attrib)
            for child in sv:
                attrs.update(child.attrib)
            out[attrs["name"]] = attrs
    return out


@pytest.mark.parametrize("version", [2, 3])
def test_fmu_is_valid_and_declares_the_computed_states(tanks, version):
    fmu = tanks[version]
    assert validate_fmu(str(fmu)) == []
    v = _variables(fmu)
    assert float(v["x1"]["start"]) == X1_0
    assert float(v["x2"]["start"]) == 2 * X1_0 + X2_OFF
    assert v["x1"]["initial"] == v["x2"]["initial"] == "approx"
    for p in ("x1_0", "x2_off"):
        assert v[p]["causality"] == "parameter" and v[p]["variability"] == "fixed"
    md = read_model_description(str(fmu))
    unknowns = {u.variable.name for u in md.initialUnknowns}
    assert {"x1", "x2"} <= unknowns


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("fmi_type", ["CoSimulation", "ModelExchange"])
def test_initial_states_follow_the_parameters(tanks, version, fmi_type):
    fmu = str(tanks[version])
    kw = {"stop_time": 1.0, "output_interval": 0.1, "fmi_type": fmi_type}
    kw["output"] = ["x1", "x2", "y"]
    for x1_0, x2_off in ((X1_0, X2_OFF), (3.0, -1.0)):
        start = {} if x1_0 == X1_0 else {"x1_0": x1_0, "x2_off": x2_off}
        r = simulate_fmu(fmu, start_values=start, **kw)
        x1, x2 = x1_0, 2 * x1_0 + x2_off
        assert r["x1"][0] == pytest.approx(x1, abs=1e-12)
        assert r["x2"][0] == pytest.approx(x2, abs=1e-12)
        assert r["y"][0] == pytest.approx(x1 + x2, abs=1e-12)
        decay = np.exp(-r["time"] / TAU)
        np.testing.assert_allclose(r["x1"], x1 * decay, rtol=1e-5, atol=1e-9)
        np.testing.assert_allclose(r["x2"], x2 * decay, rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("version", [2, 3])
def test_reset_reapplies_the_initial_states(tanks, version, tmp_path):
    fmu = tanks[version]
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(str(fmu), str(tmp_path / "x"))
    cls = FMU2Slave if version == 2 else FMU3Slave
    slave = cls(
        guid=md.guid if version == 2 else md.instantiationToken,
        unzipDirectory=unzipped,
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="tanks",
    )
    slave.instantiate()
    get = slave.getReal if version == 2 else slave.getFloat64
    put = slave.setReal if version == 2 else slave.setFloat64

    def initial(x1_0: float | None) -> list[float]:
        if version == 2:
            slave.setupExperiment(startTime=0.0)
        if x1_0 is not None:
            put([vr["x1_0"]], [x1_0])
        if version == 2:
            slave.enterInitializationMode()
        else:
            slave.enterInitializationMode(startTime=0.0)
        slave.exitInitializationMode()
        values = get([vr["x1"], vr["x2"]])
        slave.doStep(0.0, 0.5)
        return values

    try:
        assert initial(4.0) == pytest.approx([4.0, 8.0 + X2_OFF])
        slave.reset()
        assert initial(-2.0) == pytest.approx([-2.0, -4.0 + X2_OFF])
        slave.reset()
        assert initial(None) == pytest.approx([X1_0, 2 * X1_0 + X2_OFF])
        slave.terminate()
    finally:
        slave.freeInstance()


def test_rebuild_with_start_values_moves_the_declared_start(tmp_path):
    mo = tmp_path / "Tanks.mo"
    mo.write_text(TANKS)
    fmu = build_fmu(mo, "Tanks", tmp_path / "Tanks.fmu", start_values={"x1_0": 0.5})
    v = _variables(fmu)
    assert float(v["x1"]["start"]) == 0.5 and float(v["x2"]["start"]) == 1.0 + X2_OFF
    r = simulate_fmu(str(fmu), stop_time=0.1, output=["x1", "x2"])
    assert (r["x1"][0], r["x2"][0]) == pytest.approx((0.5, 1.0 + X2_OFF))
    # a value for the state itself replaces its initial equation: x2 starts there
    fmu = build_fmu(mo, "Tanks", tmp_path / "Tanks_x2.fmu", start_values={"x2": 7.0})
    v = _variables(fmu)
    assert v["x2"]["initial"] == "exact" and float(v["x2"]["start"]) == 7.0
    assert v["x1"]["initial"] == "approx"
    r = simulate_fmu(str(fmu), stop_time=0.1, output=["x1", "x2"], start_values={"x1_0": 2.0})
    assert (r["x1"][0], r["x2"][0]) == pytest.approx((2.0, 7.0))


_BAD_HEAD = """model Bad
  parameter Real p = 1;
  input Real u;
  Real x(start = 1, fixed = true);
  Real z;
"""
_BAD_TAIL = """equation
  der(x) = -x + u;
  der(z) = x - z;
end Bad;
"""


@pytest.mark.parametrize(
    ("source", "line", "fragment"),
    [
        (_BAD_HEAD + "initial equation\n  der(z) = 0;\n" + _BAD_TAIL, 7, "'der(z) = 0'"),
        (_BAD_HEAD + "initial equation\n  z = 1;\n  x * z = 1;\n" + _BAD_TAIL, 8, "x * z"),
        (_BAD_HEAD + "initial equation\n\n  z = x;\n" + _BAD_TAIL, 8, "depends on 'x'"),
        (_BAD_HEAD + "initial equation\n  z = u;\n" + _BAD_TAIL, 7, "depends on 'u'"),
        (_BAD_HEAD + "initial equation\n  z = p;\n  z = 2*p;\n" + _BAD_TAIL, 8, "second time"),
        (_BAD_HEAD + "initial equation\n  x = p;\n" + _BAD_TAIL, 7, "fixed = true"),
        (_BAD_HEAD + "initial equation\n  p = 2;\n" + _BAD_TAIL, 7, "not a state"),
        (
            _BAD_HEAD.replace("Real z;", "Real z(start = x);") + _BAD_TAIL,
            5,
            "start value of 'z' depends on 'x'",
        ),
        (
            _BAD_HEAD.replace("input Real u;", "input Real u(start = p);") + _BAD_TAIL,
            3,
            "input 'u'",
        ),
        (_BAD_HEAD + "algorithm\n  z := 1;\n" + _BAD_TAIL, 6, "algorithm sections"),
        (_BAD_HEAD + _BAD_TAIL.replace("x - z", "foo(x)"), 8, "foo"),
        (_BAD_HEAD.replace("Real z;", "Integer z;") + _BAD_TAIL, 5, "only Real"),
        (
            _BAD_HEAD + "equation\n  der(x) = -x;\n  if u > 0 then\n    der(z) = 1;\n  else\n"
            "    der(z) = 0;\n  end if;\n  z = foo(x);\n"
            "  annotation(experiment(StopTime = 1));\nend Bad;\n",
            8,
            "IfEquation",
        ),
        (
            _BAD_HEAD + "equation\n  der(x) = -x + der(z);\n  x = u;\nend Bad;\n",
            8,
            "structurally singular",
        ),
    ],
    ids=[
        "der-init",
        "product",
        "state-rhs",
        "input-rhs",
        "twice",
        "fixed-twice",
        "parameter",
        "start-state",
        "input-start",
        "algorithm",
        "function",
        "integer",
        "if-equation",
        "singular",
    ],
)
def test_refusals_name_the_construct_and_line(tmp_path, source, line, fragment):
    mo = tmp_path / "Bad.mo"
    mo.write_text(source)
    with pytest.raises(BuildError) as info:
        build_fmu(mo, "Bad", tmp_path)
    msg = str(info.value)
    assert "Bad.mo" in msg and fragment in msg, msg
    assert f"line {line}:" in msg or f"(line {line})" in msg, msg
