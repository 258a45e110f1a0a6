"""Tests of the Modelica -> FMU build (needs pymoca, casadi and a C compiler)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pymoca")
pytest.importorskip("casadi")
if shutil.which("cc") is None and shutil.which("gcc") is None:  # pragma: no cover
    pytest.skip("no C compiler", allow_module_level=True)

from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu
from grid_sim import DT, grid, input_signal, simulate_grid

from tsid_fmu.build import build_all, build_fmu, find_models, main
from tsid_fmu.errors import BuildError

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "models"
FMUS = ROOT / "fmus"

OSC = """
model Osc "Damped oscillator, written only in a test"
  parameter Real k(unit = "N/m") = 400 "Stiffness";
  parameter Real m(unit = "kg") = 1 "Mass";
  parameter Real d(unit = "N.s/m") = 2 "Damping";
  input Real F(unit = "N", start = 0) "Force";
  output Real y(unit = "m") "Position";
  Real x(unit = "m", start = 0.1, fixed = true) "Position state";
  Real v(unit = "m/s", start = 0, fixed = true) "Velocity";
equation
  der(x) = v;
  m * der(v) = F - k * x - d * v;
  y = x;
end Osc;
"""

LOOP = """
model Loop "Nonlinear algebraic loop (solved by Newton at run time)"
  parameter Real a = 0.5 "Cubic coefficient";
  input Real u(start = 2) "Drive";
  output Real y "Solution of y + a*y^3 = x";
  Real x(start = 1, fixed = true) "State";
equation
  der(x) = u - x;
  y + a * y^3 = x;
end Loop;
"""


@pytest.fixture(scope="module")
def rebuilt(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus")
    assert main(["--models-dir", str(MODELS), "--out", str(out)]) == 0
    return out


def test_find_models():
    assert list(find_models(MODELS)) == [
        "CascadedTanks",
        "LSEA_MISO",
        "LSEA_MISO_OneMass",
        "LSEA_SISO",
        "LSEA_SISO_Friction",
    ]


@pytest.mark.slow
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize(
    "name", ["LSEA_SISO", "LSEA_MISO", "LSEA_SISO_Friction", "LSEA_MISO_OneMass"]
)
def test_rebuilt_fmus_simulate_identically_to_committed(rebuilt, name, version):
    sub = "" if version == 2 else "fmi3/"
    new, old = rebuilt / f"{sub}{name}.fmu", FMUS / f"{sub}{name}.fmu"
    assert validate_fmu(str(new)) == []
    md = read_model_description(str(new))
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    t = grid(5.0)
    F = np.where((t % 1.0) < 0.5, 1.0, -1.0) * (150 + 50 * np.floor(t))
    vals = {n: F if n == "F_m" else 1e-3 * np.sin(2 * np.pi * t) for n in inputs}
    kw = {"input": input_signal(t, **vals)}
    a = simulate_grid(new, 5.0, **kw)
    b = simulate_grid(old, 5.0, **kw)
    np.testing.assert_allclose(a["F_o"], b["F_o"], rtol=1e-12, atol=1e-9)
    me = {"fmi_type": "ModelExchange", "record_events": False}
    a = simulate_grid(new, 5.0, **kw, **me)
    b = simulate_grid(old, 5.0, **kw, **me)
    np.testing.assert_allclose(a["F_o"], b["F_o"], rtol=1e-12, atol=1e-9)


def _square(t: np.ndarray) -> dict:
    F = np.where((t % 1.0) < 0.5, 1.0, -1.0) * (150 + 50 * np.floor(t))
    return {"input": input_signal(t, F_m=F)}


@pytest.mark.slow
@pytest.mark.parametrize("version", [2, 3])
def test_friction_switch_is_an_integer_parameter_and_law_2_is_lsea_siso(rebuilt, version):
    """``parameter Integer friction``: an FMI Integer (Int32) parameter that switches the law.

    Law 2 (the default) reproduces LSEA_SISO to solver precision (same equations), law 1
    is law 2 with F_vm = 0, law 3 with F_sm = F_cm is law 2; law 3 differs otherwise.
    """
    sub = "" if version == 2 else "fmi3/"
    new = rebuilt / f"{sub}LSEA_SISO_Friction.fmu"
    v = {x.name: x for x in read_model_description(str(new)).modelVariables}
    assert v["friction"].type == ("Integer" if version == 2 else "Int32")
    assert v["friction"].causality == "parameter" and int(v["friction"].start) == 2
    t = grid(5.0)
    kw = _square(t)
    ref = simulate_grid(FMUS / f"{sub}LSEA_SISO.fmu", 5.0, **kw)["F_o"]
    for interface in ({}, {"fmi_type": "ModelExchange", "record_events": False}):
        law2 = simulate_grid(new, 5.0, **kw, **interface)["F_o"]
        old = simulate_grid(FMUS / f"{sub}LSEA_SISO.fmu", 5.0, **kw, **interface)["F_o"]
        np.testing.assert_allclose(law2, old, rtol=1e-12, atol=1e-9)

    def run(**start):
        return simulate_grid(new, 5.0, start_values=start, **kw)["F_o"]

    np.testing.assert_allclose(run(friction=1), run(friction=2, F_vm=0.0), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(run(friction=3, F_sm=88.5), ref, rtol=1e-12, atol=1e-9)
    for law in (1, 3):
        assert np.max(np.abs(run(friction=law) - ref)) > 5.0
    # parameter Integer damping: 1 (default) is LSEA_SISO, 0 is the spring without B_s
    assert v["damping"].type == ("Integer" if version == 2 else "Int32")
    assert v["damping"].causality == "parameter" and int(v["damping"].start) == 1
    for law in (1, 2, 3):
        off = run(friction=law, damping=0)
        np.testing.assert_allclose(off, run(friction=law, B_s=0.0), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(
            off, run(friction=law, damping=0, B_s=7.0), rtol=1e-12, atol=1e-9
        )
        assert np.max(np.abs(off - run(friction=law))) > 1.0  # B_s = 2.5 acts when on


@pytest.mark.slow
def test_build_is_byte_reproducible_and_selects_versions(rebuilt, tmp_path):
    args = ["--models-dir", str(MODELS), "--out", str(tmp_path), "--fmi-version", "3"]
    assert main([*args, "LSEA_SISO"]) == 0
    assert not (tmp_path / "LSEA_SISO.fmu").exists()
    again = tmp_path / "fmi3" / "LSEA_SISO.fmu"
    assert again.read_bytes() == (rebuilt / "fmi3" / "LSEA_SISO.fmu").read_bytes()


@pytest.mark.slow
def test_model_description_from_declarations(rebuilt):
    md = read_model_description(str(rebuilt / "LSEA_SISO.fmu"))
    v = {x.name: x for x in md.modelVariables}
    assert v["K_s"].causality == "parameter" and v["K_s"].variability == "fixed"
    assert v["K_s"].unit == "N/m" and float(v["K_s"].start) == 8600.0
    assert v["F_cm"].description.startswith("Coulomb")
    assert v["F_m"].causality == "input" and v["F_o"].causality == "output"
    assert float(v["V_z"].start) == 0.001
    assert v["fixedStepSize"].causality == "parameter"
    assert md.coSimulation is not None and md.modelExchange is not None
    srcs = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert "fmi2Functions.c" in srcs and "model_casadi.c" in srcs
    out = md.outputs[0]
    assert out.variable.name == "F_o"
    assert sorted(d.name for d in out.dependencies) == ["v_m", "x_m"]
    miso = read_model_description(str(rebuilt / "LSEA_MISO.fmu"))
    deps = sorted(d.name for d in miso.outputs[0].dependencies)
    assert deps == ["a_o", "v", "v_o", "x", "x_o"]


@pytest.mark.slow
def test_fmi3_model_description(rebuilt):
    import zipfile

    path = rebuilt / "fmi3" / "LSEA_SISO.fmu"
    md = read_model_description(str(path))
    assert md.fmiVersion == "3.0"
    v = {x.name: x for x in md.modelVariables}
    assert v["time"].causality == "independent"
    assert v["K_s"].causality == "parameter" and float(v["K_s"].start) == 8600.0
    assert v["F_m"].causality == "input"
    indicators = [x for x in md.modelVariables if x.name.startswith("_eventIndicator_")]
    assert len(indicators) == md.numberOfEventIndicators == 2
    assert "abs(v_m) <= V_z" in indicators[0].description
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    # FMI 3.0 platform tuple, e.g. binaries/x86_64-linux/
    assert any(n.startswith("binaries/") and "-" in n.split("/")[1] for n in names)
    assert "sources/buildDescription.xml" in names and "sources/fmi3Functions.c" in names
    assert md.outputs[0].variable.name == "F_o"
    # FMI 3.0 counts parameters among the knowns of an output
    assert sorted(d.name for d in md.outputs[0].dependencies) == ["B_s", "K_s", "v_m", "x_m"]


def test_extra_model_built_from_test_source(tmp_path):
    mo = tmp_path / "Osc.mo"
    mo.write_text(OSC)
    fmu = build_fmu(mo, "Osc", tmp_path / "Osc.fmu")
    assert validate_fmu(str(fmu)) == []
    k, m, d = 400.0, 1.0, 2.0
    t = grid(2.0)
    wd = np.sqrt(k / m - (d / (2 * m)) ** 2)
    sigma = d / (2 * m)
    exact = 0.1 * np.exp(-sigma * t) * (np.cos(wd * t) + sigma / wd * np.sin(wd * t))
    for fmi_type in ("CoSimulation", "ModelExchange"):
        r = simulate_grid(fmu, 2.0, fmi_type=fmi_type, output=["y"], relative_tolerance=1e-9)
        np.testing.assert_allclose(r["y"], exact, atol=1e-3 * 0.1 * 2)
    # parameter change through start_values follows the equations: 4k -> 2x frequency
    r4 = simulate_grid(fmu, 2.0, output=["y"], start_values={"k": 4 * k})
    wd4 = np.sqrt(4 * k / m - sigma**2)
    exact4 = 0.1 * np.exp(-sigma * t) * (np.cos(wd4 * t) + sigma / wd4 * np.sin(wd4 * t))
    np.testing.assert_allclose(r4["y"], exact4, atol=1e-3 * 0.1 * 2)


def test_algebraic_loop_solved_by_newton(tmp_path):
    mo = tmp_path / "Loop.mo"
    mo.write_text(LOOP)
    fmu = build_fmu(mo, "Loop", tmp_path)
    assert fmu == tmp_path / "Loop.fmu"
    r = simulate_fmu(str(fmu), stop_time=1.0, step_size=DT, output=["y", "x"])
    np.testing.assert_allclose(r["y"] + 0.5 * r["y"] ** 3, r["x"], atol=1e-10)
    assert r["x"][-1] == pytest.approx(2 - np.exp(-1.0), rel=1e-6)


@pytest.mark.parametrize(
    ("source", "fragment"),
    [
        (
            "model Bad\n  Real x(start=0, fixed=true);\nequation\n  der(x) = ;\nend Bad;\n",
            "parse error",
        ),
        (
            "model Bad\n  Real x(start=0, fixed=true);\n  Real y;\nequation\n"
            "  der(x) = -x;\nend Bad;\n",
            "not balanced",
        ),
        (
            "model Bad\n  Real x(start=0, fixed=true);\nequation\n  der(x) = foo(x);\nend Bad;\n",
            "foo",
        ),
        (
            "model Bad\n  Integer n = 1;\n  Real x(start=0, fixed=true);\nequation\n"
            "  der(x) = -x;\nend Bad;\n",
            "only Real",
        ),
        (
            "model Bad\n  parameter Integer n = 1.5;\n  Real x(start=0, fixed=true);\n"
            "equation\n  der(x) = -n*x;\nend Bad;\n",
            "Integer parameter 'n'",
        ),
    ],
    ids=["syntax", "unbalanced", "unknown-function", "integer", "integer-value"],
)
def test_build_errors_name_the_fault(tmp_path, source, fragment):
    mo = tmp_path / "Bad.mo"
    mo.write_text(source)
    with pytest.raises(BuildError) as info:
        build_fmu(mo, "Bad", tmp_path)
    msg = str(info.value)
    assert fragment in msg and "Bad.mo" in msg


def test_missing_model_and_cli_exit_code(tmp_path, capsys):
    with pytest.raises(BuildError, match="not found"):
        build_all(MODELS, tmp_path, ["NoSuchModel"])
    assert main(["--models-dir", str(MODELS), "--out", str(tmp_path), "NoSuchModel"]) == 1
    assert "NoSuchModel" in capsys.readouterr().err


def test_compiler_error_names_command(tmp_path, monkeypatch):
    mo = tmp_path / "Osc.mo"
    mo.write_text(OSC)
    monkeypatch.setenv("CC", "cc -DNX=oops")
    with pytest.raises(BuildError, match="compiler command failed"):
        build_fmu(mo, "Osc", tmp_path)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cmake") is None, reason="fmpy compile needs cmake")
@pytest.mark.parametrize("sub", ["", "fmi3"], ids=["fmi2", "fmi3"])
def test_fmu_sources_recompile_with_fmpy(tmp_path, sub):
    import subprocess
    import sys

    committed = FMUS / sub / "LSEA_SISO.fmu"
    fmu = tmp_path / "LSEA_SISO.fmu"
    shutil.copy2(committed, fmu)
    proc = subprocess.run(
        [sys.executable, "-m", "fmpy", "compile", str(fmu)], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    t = grid(2.0)
    sig = input_signal(t, F_m=np.where(t < 1.0, 300.0, -300.0))
    a = simulate_grid(fmu, 2.0, input=sig)
    b = simulate_grid(committed, 2.0, input=sig)
    np.testing.assert_allclose(a["F_o"], b["F_o"], rtol=1e-9, atol=1e-6)
