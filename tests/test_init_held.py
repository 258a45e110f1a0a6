"""``tsid init`` holds what the data should not decide (issue 62, item 3).

Measured on vendor FMUs, ``init`` freed Hopsan's ``timestep``, Dymola's
``resistor.T_ref``, ``resistor.alpha`` and ``resistor.T`` (16 runs failed on
"Temperature outside scope of model!") and, in a pump-and-valve model, the medium's
properties, the ambient temperature and pressure, ``pipe.g`` and the ramps' start times
and durations (34 runs failed). Each is now written commented out, with its reason; a
plant's parameters stay free.
"""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tsid_fmu import Study
from tsid_fmu.fmu.variables import VariableInfo
from tsid_fmu.scaffold import init_study
from tsid_fmu.scaffold_rules import held_reason, numerical_setting

NUMERICAL = "numerical, not physical"
WORLD = "a constant of the medium or the environment"
SOURCE = "a setting of a signal source (its time), not a parameter of the plant"


def _var(name: str, description: str | None = None, unit: str | None = None) -> VariableInfo:
    return VariableInfo(name, 0, "Real", "parameter", "fixed", "exact", "1", unit, description)


HELD = [
    (_var("timestep", "Hopsan time step", "s"), NUMERICAL),
    (_var("timestep", None, "s"), NUMERICAL),
    (_var("Ts_sim", "Time step of the simulation"), NUMERICAL),
    (_var("system.p_ambient", "Default ambient pressure", "Pa"), WORLD),
    (_var("system.T_ambient", "Default ambient temperature", "K"), WORLD),
    (_var("system.g", "Constant gravity acceleration", "m/s2"), WORLD),
    (_var("world.g", None, "m/s2"), WORLD),
    (_var("pipe.g", "Constant gravity acceleration", "m/s2"), WORLD),
    (_var("pump.g", None, "m/s2"), WORLD),
    (_var("g", "Gravitational acceleration"), WORLD),
    (_var("T_amb", None, "K"), WORLD),
    (_var("p_amb"), WORLD),
    (_var("p_ambient", None, "Pa"), WORLD),
    (_var("ambient.T", "Temperature", "K"), WORLD),
    (_var("environment.p", None, "Pa"), WORLD),
    (_var("medium.rho", None, "kg/m3"), WORLD),
    (_var("Medium1.cp", None, "J/(kg.K)"), WORLD),
    (_var("rho", "Density of the medium", "kg/m3"), WORLD),
    (_var("cp", "Specific heat capacity of the medium", "J/(kg.K)"), WORLD),
    (_var("resistor.T_ref", "Reference temperature", "K"), WORLD),
    (_var("resistor.alpha", "Temperature coefficient of resistance (R_actual = "
          "R*(1 + alpha*(T_heatPort - T_ref))", "1/K"), WORLD),
    (_var("resistor.T", "Fixed device temperature if useHeatPort = false", "K"), WORLD),
    (_var("T_env", "Environment temperature", "K"), WORLD),
    (_var("ramp.startTime", "Output y = offset for time < startTime", "s"), SOURCE),
    (_var("ramp.duration", "Duration of ramp (= 0.0 gives a Step)", "s"), SOURCE),
    (_var("step.startTime", None, "s"), SOURCE),
    (_var("pulse.period", "Time for one period", "s"), SOURCE),
    (_var("valveOpening.offset", None, "s"), SOURCE),
    (_var("start_time", None, "s"), SOURCE),
    (_var("t_on", "Start time of the pulse train"), SOURCE),
    (_var("t_d", "Delay of the step", "s"), SOURCE),
]  # fmt: skip
"""Parameters ``init`` must hold, with the reason it writes."""

FREE = [
    _var("damper.d", "Damping constant", "N.s/m"), _var("mass.m", "Mass of the sliding mass", "kg"),
    _var("spring.c", "Spring constant", "N/m"),
    _var("resistor.R", "Resistance at temperature T_ref", "Ohm"),
    _var("inductor.L", "Inductance", "H"), _var("capacitor.C", "Capacitance", "F"),
    _var("K_s", "Stiffness of the series spring", "N/m"),
    _var("M_m", "Moving mass of motor, ball screw and nut block reflected to the nut", "kg"),
    _var("F_cm", "Coulomb friction force of the motor side", "N"), _var("B_s"), _var("k4"),
    _var("T", "Time constant of the lag", "s"), _var("tau", None, "s"),
    _var("delay.delayTime", "Delay time of output with respect to input signal", "s"),
    _var("G", "Thermal conductance to ambient", "W/K"),
    _var("alpha_c", "Heat transfer coefficient between wall and medium", "W/(m2.K)"),
    _var("V", "Volume of medium in the tank", "m3"),
    _var("r_CM", "Position of the centre of gravity", "m"),
    _var("g", "Conductance of the shunt", "S"), _var("gear.ratio"),
    _var("pipe.length", "Length of pipe", "m"), _var("pipe.diameter", "Diameter of pipe", "m"),
    _var("pipe.roughness", "Absolute roughness of pipe", "m"),
    _var("valve.Kv", "Kv (metric) flow coefficient", "m3/h"),
    _var("fixed.s0", "Fixed offset position of housing", "m"),
    _var("c", "Offset of the level sensor", "V"), _var("ramp.height", "Height of ramps"),
    _var("T_start", "Start value of temperature", "K"), _var("systemGain"),
    _var("plant.period", "Period of the pendulum's swing"),
    _var("mgl", "Gravity torque at 90 degrees (m g l)", "N.m"),
]  # fmt: skip
"""A plant's parameters, which ``init`` must leave free."""


@pytest.mark.parametrize(("v", "why"), HELD, ids=[f"{v.name}-{i}" for i, (v, _) in enumerate(HELD)])
def test_what_init_holds(v, why):
    reason = held_reason(v)
    assert reason is not None and reason.startswith(why), reason


@pytest.mark.parametrize("v", FREE, ids=lambda v: f"{v.name}-{v.unit}")
def test_a_plants_parameters_stay_free(v):
    assert held_reason(v) is None


def test_hopsans_time_step_is_a_numerical_setting():
    assert numerical_setting(_var("timestep", "Hopsan time step", "s")) is not None
    assert numerical_setting(_var("timestep", None, "s")) is not None


def _param(i: int, name: str, start: str, unit: str = "", description: str = "") -> str:
    unit = f' unit="{unit}"' if unit else ""
    text = f' description="{description}"' if description else ""
    return (
        f'<ScalarVariable name="{name}" valueReference="{i}" causality="parameter" '
        f'variability="fixed" initial="exact"{text}><Real start="{start}"{unit}/></ScalarVariable>'
    )


_PARAMETERS = [
    ("timestep", "0.001", "s", "Hopsan time step"),
    ("resistor.R", "10", "Ohm", "Resistance at temperature T_ref"),
    ("resistor.T_ref", "300.15", "K", "Reference temperature"),
    ("resistor.alpha", "0.004", "1/K", "Temperature coefficient of resistance"),
    ("resistor.T", "293.15", "K", "Fixed device temperature if useHeatPort = false"),
    ("inductor.L", "0.1", "H", "Inductance"),
    ("system.p_ambient", "101325", "Pa", "Default ambient pressure"),
    ("pipe.g", "9.81", "m/s2", "Constant gravity acceleration"),
    ("ramp.startTime", "0.5", "s", "Output y = offset for time &lt; startTime"),
    ("ramp.duration", "1", "s", "Duration of ramp (= 0.0 gives a Step)"),
]


def _circuit(tmp_path: Path) -> tuple[Path, Path]:
    """An FMU's model description with a vendor's parameters (no binaries), and data."""
    params = "".join(_param(i + 1, *p) for i, p in enumerate(_PARAMETERS))
    xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Circuit" guid="{{1}}">
  <CoSimulation modelIdentifier="Circuit"/>
  <ModelVariables>
    <ScalarVariable name="i" valueReference="0" causality="output" variability="continuous">
      <Real unit="A"/></ScalarVariable>
    {params}
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1"/></Outputs></ModelStructure>
</fmiModelDescription>
"""
    fmu = tmp_path / "Circuit.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", xml)
    t = np.arange(0.0, 2.0, 0.01)
    data = tmp_path / "circuit.csv"
    pd.DataFrame({"time": t, "i": 1 - np.exp(-t)}).to_csv(data, index=False)
    return fmu, data


def test_init_writes_what_it_holds_commented_with_its_reason(tmp_path):
    fmu, data = _circuit(tmp_path)
    out = tmp_path / "study.toml"
    text = init_study(fmu, data, out)
    assert {p.name for p in Study.from_toml(out).parameters} == {"resistor.R", "inductor.L"}
    commented = {
        m.group(1).strip('"'): m.group(2)
        for m in re.finditer(r"^# (\S+) = \{ levels = .*?\}  # (.*)$", text, re.MULTILINE)
    }
    expected = {
        "timestep": NUMERICAL, "resistor.T_ref": WORLD, "resistor.alpha": WORLD,
        "resistor.T": WORLD, "system.p_ambient": WORLD, "pipe.g": WORLD,
        "ramp.startTime": SOURCE, "ramp.duration": SOURCE,
    }  # fmt: skip
    assert set(commented) == set(expected)
    for name, why in expected.items():
        assert commented[name].startswith(why), (name, commented[name])
        assert commented[name].endswith("is kept; uncomment to identify it")
