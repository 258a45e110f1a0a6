"""``tsid init`` writes studies that work (issue 24, item 6).

Numerical settings (steps, tolerances, thresholds) are written commented out, the
levels respect the bounds the FMU declares, and an FMU input or output that the data
hold only in parts gets a ``--derived`` proposal. Every study written here is read back
with :meth:`tsid_fmu.Study.from_toml`.
"""

from __future__ import annotations

import re
import shlex
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tsid_fmu import Study
from tsid_fmu.cli import main
from tsid_fmu.errors import StudyError
from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.variables import VariableInfo, variable_info
from tsid_fmu.scaffold import init_study
from tsid_fmu.scaffold_rules import bounded_levels, decade_levels, derived_hints, numerical_setting
from tsid_fmu.study import load_study

REPO = Path(__file__).resolve().parents[1]
SISO = REPO / "examples" / "lsea_siso"
MISO = REPO / "examples" / "lsea_miso"

_BALL = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Ball" guid="{1}">
  <CoSimulation modelIdentifier="Ball"/>
  <TypeDefinitions><SimpleType name="Share"><Real min="0" max="1"/></SimpleType></TypeDefinitions>
  <ModelVariables>
    <ScalarVariable name="h" valueReference="0" causality="output" variability="continuous">
      <Real unit="m"/></ScalarVariable>
    <ScalarVariable name="e" valueReference="1" causality="parameter" variability="fixed"
      initial="exact" description="Coefficient of restitution"><Real start="0.7" min="0.5"
      max="1"/></ScalarVariable>
    <ScalarVariable name="loss" valueReference="2" causality="parameter" variability="fixed"
      initial="exact"><Real declaredType="Share" start="0.3"/></ScalarVariable>
    <ScalarVariable name="g" valueReference="3" causality="parameter" variability="fixed"
      initial="exact"><Real unit="m/s2" start="-9.81" max="-9"/></ScalarVariable>
    <ScalarVariable name="v_min" valueReference="4" causality="parameter" variability="fixed"
      initial="exact" description="Velocity below which the ball is considered at rest">
      <Real unit="m/s" start="0.01" min="0"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1"/></Outputs></ModelStructure>
</fmiModelDescription>
"""


def _ball(tmp_path: Path) -> tuple[Path, Path]:
    """A bouncing ball's model description (no binaries: init reads the description only)."""
    fmu = tmp_path / "Ball.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", _BALL)
    t = np.arange(0.0, 2.0, 0.01)
    data = tmp_path / "ball.csv"
    pd.DataFrame({"time": t, "h": np.abs(np.sin(3 * t))}).to_csv(data, index=False)
    return fmu, data


def _parameters(text: str) -> list[str]:
    return re.findall(r"^(\w+) = \{ levels", text, re.MULTILINE)


def _commented(text: str) -> list[str]:
    return re.findall(r"^# (\w+) = \{ levels", text, re.MULTILINE)


def test_variable_info_carries_the_declared_bounds(tmp_path):
    fmu, _ = _ball(tmp_path)
    infos = {v.name: variable_info(v) for v in read_fmu_description(fmu).modelVariables}
    assert (infos["e"].min, infos["e"].max) == (0.5, 1.0)
    assert (infos["loss"].min, infos["loss"].max) == (0.0, 1.0)  # from its declared type
    assert (infos["g"].min, infos["g"].max) == (None, -9.0)
    assert (infos["h"].min, infos["h"].max) == (None, None)


@pytest.mark.parametrize(
    ("fmu", "numerical"),
    [("LSEA_SISO.fmu", {"V_z", "fixedStepSize"}), ("LSEA_MISO.fmu", {"fixedStepSize"}),
     ("fmi3/LSEA_SISO.fmu", {"V_z", "fixedStepSize"}), ("fmi3/LSEA_MISO.fmu", {"fixedStepSize"})],
)  # fmt: skip
def test_the_bundled_fmus_numerical_settings(fmu, numerical):
    infos = [variable_info(v) for v in read_fmu_description(REPO / "fmus" / fmu).modelVariables]
    params = {v.name for v in infos if v.causality == "parameter"}
    assert {v.name for v in infos if v.causality == "parameter" and numerical_setting(v)} == (
        numerical
    )
    assert len(params - numerical) >= 5  # masses, stiffness, friction, damping stay free


def _var(name: str, description: str | None = None, unit: str | None = None) -> VariableInfo:
    return VariableInfo(name, 0, "Real", "parameter", "fixed", "exact", "1", unit, description)


@pytest.mark.parametrize(
    "v",
    [_var("eps"), _var("v_eps", "Regularisation velocity of the friction law", "m/s"),
     _var("relTol"), _var("solverTolerance"), _var("step_size"), _var("dt", None, "s"),
     _var("h", "Integration step", "s"), _var("Ts", "Controller period", "s"),
     _var("v_small", "Velocity below which the body is treated as stopped", "m/s"),
     _var("w", "Smoothing width of the tanh friction", "m/s"),
     _var("V_z", "Velocity below which the motor side is considered at rest", "m/s"),
     _var("F_thr", "Switching threshold of the contact model", "N"),
     _var("n_iter", "Newton iterations of the numerical solver"),
     # as tools export them (issue 43): JModelica.org's internals, OpenModelica's nominals
     _var("_cs_rel_tol"), _var("_nle_jacobian_finite_difference_delta"),
     _var("_nle_solver_max_residual_scaling_factor"), _var("_events_default_tol"),
     _var("sub._private"),
     _var("damper.s_nominal", "Nominal value of s_rel (used for scaling)", "m")],
    ids=lambda v: v.name,
)  # fmt: skip
def test_numerical_settings_are_recognised(v):
    assert numerical_setting(v) is not None


@pytest.mark.parametrize(
    "v",
    [_var("m", "Mass of the cart", "kg"), _var("k", "Stiffness of the spring", "N/m"),
     _var("d", "Damping coefficient", "N.s/m"), _var("F_c", "Coulomb friction force", "N"),
     _var("F_brk", "Breakaway friction threshold", "N"), _var("h", "Drop height", "m"),
     _var("T", "Time constant of the lag", "s"), _var("tau", None, "s"), _var("e"),
     _var("J", "Rotor inertia", "kg.m2"), _var("stepHeight", "Height of a stair step", "m"),
     _var("R", "Winding resistance", "Ohm"), _var("K_s"), _var("B_s"),
     # OpenModelica's and JModelica.org's physical parameters stay free
     _var("mass.m", "Mass of the sliding mass", "kg"), _var("spring.c", "Spring constant"),
     _var("damper.d", "Damping constant", "N.s/m"), _var("ampl[0]"), _var("a_b_"),
     _var("C", "Heat capacity of element (= cp*m)", "J/K"),
     _var("R1", "Constant thermal resistance of material", "K/W"),
     _var("V_nominal", "Nominal voltage of the motor", "V")],
    ids=lambda v: v.name,
)  # fmt: skip
def test_physical_parameters_stay_free(v):
    assert numerical_setting(v) is None


def test_bounded_levels_stay_inside_the_declared_bounds():
    assert bounded_levels(0.7, 0.5, 1.0) == [0.5, 0.5916, 0.7, 0.8367, 1.0]
    assert bounded_levels(8600.0) == decade_levels(8600.0)  # no bounds: the decade
    assert bounded_levels(8600.0, 0.0, None) == decade_levels(8600.0)  # bounds that don't bite
    assert bounded_levels(0.5, 0.5, 1.0) == [0.5, 0.5946, 0.7071, 0.8409, 1.0]  # at a bound
    assert bounded_levels(-9.81, None, -9.0) == [-31.02, -17.44, -9.81, -9.396, -9.0]
    assert bounded_levels(0.0, 0.0, None) == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert bounded_levels(2.0, 1.0, 3.0) == [1.0, 1.414, 2.0, 2.449, 3.0]
    assert bounded_levels(5.0, 1.0, 3.0) == [1.0, 1.316, 1.732, 2.280, 3.0]  # start outside
    tight = bounded_levels(1.0, 1.0, 1.000001)
    assert len(set(tight)) == 5 and all(1.0 <= x <= 1.000001 for x in tight)


def test_init_writes_the_declared_bounds_and_comments_out_the_rest_threshold(tmp_path):
    fmu, data = _ball(tmp_path)
    text = init_study(fmu, data, tmp_path / "study.toml")
    assert "e = { levels = [0.5, 0.5916, 0.7, 0.8367, 1.0], min = 0.5, max = 1 }" in text
    assert "loss = { levels = [0.09487, 0.1687, 0.3, 0.5335, 0.9487], min = 0, max = 1 }" in text
    # gravity is held (issue 62), its entry written with the bounds the FMU declares
    assert '# g = { levels = [-31.02, -17.44, -9.81, -9.396, -9.0], max = -9, unit = "m/s2" }' in (
        text
    )
    assert _parameters(text) == ["e", "loss"] and _commented(text) == ["g", "v_min"]
    study = Study.from_toml(tmp_path / "study.toml")
    assert {p.name: p.bounds for p in study.parameters} == {"e": (0.5, 1.0), "loss": (0.0, 1.0)}


def test_init_siso_comments_out_V_z_and_proposes_F_o(tmp_path, capsys):
    out = tmp_path / "s" / "study.toml"
    text = init_study(REPO / "fmus" / "LSEA_SISO.fmu", SISO / "measured.csv", out)
    assert _parameters(text) == ["F_cm", "F_vm", "M_m", "K_s", "B_s"]
    assert _commented(text) == ["V_z", "fixedStepSize"]
    assert "considered at rest" in text.split("# V_z = ")[1].splitlines()[0]
    assert '# F_o has no column; if it is F_of - F_or: --derived "F_o=F_of - F_or"' in text
    assert {p.name for p in Study.from_toml(out).parameters} == set(_parameters(text))
    # the proposed command writes a study that compares F_o too
    command = re.search(r"^# to add them, run: tsid init (.*)$", text, re.MULTILINE).group(1)
    args = shlex.split(command)
    derived = dict(a.split("=", 1) for a in args[args.index("--derived") + 1 :: 2])
    assert derived == {"F_o": "F_of - F_or"} and args[2:5] == ["-o", str(out), "--force"]
    # as a user runs it: the study file it rewrites exists, so it needs its --force
    assert main(["init", *args]) == 0, capsys.readouterr().err
    again = out.read_text(encoding="utf-8")
    assert 'outputs = { F_o = "F_o", x_m = "x_m" }' in again and "has no column" not in again
    assert main(["init", *(a for a in args if a != "--force")]) == 2
    assert "the file exists; give --force" in capsys.readouterr().err
    assert [e.outputs for e in Study.from_toml(out).experiments] == [{"F_o": "F_o", "x_m": "x_m"}]


def test_init_miso_names_the_derived_channels_it_needs(tmp_path):
    fmu, data = REPO / "fmus" / "LSEA_MISO.fmu", MISO / "force_only.csv"
    with pytest.raises(StudyError, match="no column matches an output") as err:
        init_study(fmu, data, tmp_path / "study.toml")
    message = str(err.value)
    for option in ('"F_o=F_of - F_or"', '"v_o=der(x_o)"', '"a_o=der(x_o, 2)"'):
        assert f"--derived {option}" in message
    text = init_study(fmu, data, tmp_path / "study.toml", derived={"F_o": "F_of - F_or"})
    assert '# v_o has no column; if it is der(x_o): --derived "v_o=der(x_o)"' in text
    assert '--derived "F_o=F_of - F_or" --derived "v_o=der(x_o)" --derived "a_o=der(x_o, 2)"' in (
        text
    )


def test_derived_hints_from_names():
    columns = ["time", "F_of", "F_or", "x_o", "v_j", "phi_k", "pos_z", "y meas", "q_dot"]
    missing = ["F_o", "v_o", "a_o", "a_j", "w_k", "vel_z", "acc_z", "y", "q_ddot", "u", "F"]
    assert derived_hints(missing, columns) == {
        "F_o": "F_of - F_or", "v_o": "der(x_o)", "a_o": "der(x_o, 2)", "a_j": "der(v_j)",
        "w_k": "der(phi_k)", "vel_z": "der(pos_z)", "acc_z": "der(pos_z, 2)",
        "q_ddot": "der(q_dot)",
    }  # fmt: skip
    assert derived_hints(["F_o"], columns, unused=["F_of"]) == {"F_o": "F_of"}


def _many(tmp_path: Path, n: int) -> tuple[Path, Path]:
    """A model description with ``n`` positive real parameters ``k[1]`` ... (no binaries)."""
    params = "".join(
        f'<ScalarVariable name="k[{i}]" valueReference="{i}" causality="parameter" '
        f'variability="fixed" initial="exact"><Real start="{i}.5"/></ScalarVariable>'
        for i in range(1, n + 1)
    )
    xml = _BALL.replace(_BALL[_BALL.index("    <ScalarVariable name=\"e\"") : _BALL.index(
        "  </ModelVariables>")], params)  # fmt: skip
    fmu = tmp_path / f"Many{n}.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", xml)
    data = tmp_path / "ball.csv"
    t = np.arange(0.0, 2.0, 0.01)
    pd.DataFrame({"time": t, "h": np.abs(np.sin(3 * t))}).to_csv(data, index=False)
    return fmu, data


@pytest.mark.parametrize(
    ("n", "array", "levels"), [(11, "L50", 5), (13, "L27", 3), (18, "L81", 3), (45, "L81", 3)]
)
def test_init_writes_a_study_that_runs_for_any_number_of_parameters(tmp_path, n, array, levels):
    """18 parameters gave exit 2 and no file: no five-level array hosts them (issue 43)."""
    fmu, data = _many(tmp_path, n)
    text = init_study(fmu, data, tmp_path / "study.toml")
    study = load_study(tmp_path / "study.toml")
    assert study.method.array == array
    assert len(study.parameters) == min(n, 40)
    assert {len(p.levels) for p in study.parameters} == {levels}
    beyond = re.findall(r'^# "k\[\d+\]" = .*beyond the 40 parameters', text, re.MULTILINE)
    assert len(beyond) == max(n - 40, 0)


def test_a_bound_tsid_chose_itself_is_said_in_the_file(tmp_path):
    """min = 0 from a positive start value is tsid's guess, not the FMU's (issue 43)."""
    fmu, data = _many(tmp_path, 1)
    text = init_study(fmu, data, tmp_path / "study.toml")
    line = next(x for x in text.splitlines() if x.startswith('"k[1]"'))
    assert "min = 0 }" in line and "min = 0 is tsid's (the FMU declares none)" in line
    fmu, data = _ball(tmp_path)
    text = init_study(fmu, data, tmp_path / "ball.toml")
    line = next(x for x in text.splitlines() if x.startswith("e = "))
    assert "tsid's" not in line  # the FMU declared e's bounds


def test_init_writes_paths_as_a_person_would(tmp_path):
    """An FMU far outside the study's folder was written as ../../../... (issue 43)."""
    fmu, data = _ball(tmp_path)
    deep = tmp_path / "a" / "b" / "c"
    deep.mkdir(parents=True)
    text = init_study(fmu, data, deep / "study.toml")
    assert f'fmu = "{fmu.resolve().as_posix()}"' in text  # three folders up: absolute
    near = tmp_path / "studies"
    near.mkdir()
    text = init_study(fmu, data, near / "study.toml")
    assert 'fmu = "../Ball.fmu"' in text and 'file = "../ball.csv"' in text
    assert load_study(deep / "study.toml").fmu == fmu.resolve()
