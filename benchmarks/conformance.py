"""Conformance of FMUs exported by real modelling tools, run the way a user receives them.

For each FMU in ``CASES`` this script fetches the FMU from a published wheel on PyPI (or
builds it with pythonfmu), makes measured data that the FMU did not make at the values
being identified (an independent solution of the model's equations, or the FMU's Model
Exchange at a tolerance of 1e-10 where the equations are not at hand), adds 1 % noise,
and runs what a user runs: ``tsid info``, ``tsid init`` then ``tsid identify`` on the
study init wrote, unedited, and a hand-written study. A parameter whose 95 % interval is
finite on both sides is "determined"; it passes when it lies within 1 % of the truth and
the truth lies inside its interval. It is a measurement, not a test: it exits 0 whatever
the rows say. ``docs/benchmarks/conformance.md`` holds the table of the last run. A
study's FMU conformance probe (a broken reset, a non-deterministic FMU; issue 62) is in
its notes where it found something or could not run. The last rows are synthetic quirk
FMUs (``QUIRKS``): the test suite's first-order lag (``tests/fmu_factory.py``) built with
the C compiler and one quirk each, run the same way.

Run (downloads into ``benchmarks/.cache``, git-ignored; a few minutes on two cores)::

    python benchmarks/conformance.py --workers 2 [--only Mass_Damper]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
import tomllib
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp
from scipy.linalg import expm

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "benchmarks" / ".cache"
WHEELS, WORK = CACHE / "wheels", CACHE / "conformance"
GEMSEO, MODESTPY = "gemseo-fmu==3.1.1", "modestpy==0.1.1"
OM, MP = "gemseo_fmu/problems/fmu_files/linux/", "modestpy/test/resources/"
# numpy's old manylinux1 wheel bundles a libgfortran.so.3 (JModelica's FMUs need one)
GFORTRAN_WHEEL = ("numpy==1.16.6", "--only-binary=:all:", "--python-version", "3.7",
                  "--platform", "manylinux1_x86_64")  # fmt: skip
SUBPROCESS_LIMIT = 1800  # seconds for one tsid command, so that a hang cannot stop the run
Made = tuple[pd.DataFrame, str]  # the noiseless data, and how they were made


@dataclass
class Case:
    """One FMU: where it comes from, its truth, how its data are made, its hand study."""

    name: str
    source: str  # a wheel (pip requirement), "pythonfmu" or "quirk:NAME:FMI" built here
    member: str  # the FMU's path in the wheel
    truth: dict[str, float]  # what the data were made at (others: the FMU's start values)
    data: Callable[[Path, dict[str, float]], Made]
    inputs: list[str] = field(default_factory=list)  # data columns fed to FMU inputs
    outputs: list[str] = field(default_factory=list)
    hand: str = ""  # the hand study's [parameters] lines; "" for none
    hand_study: str = ""  # extra lines for the hand study's [study] and [data] tables
    hand_data: str = ""
    combos: dict[str, tuple[str, str, int]] = field(default_factory=dict)  # a * b**power
    gfortran: bool = False  # needs libgfortran.so.3


def sines(t: np.ndarray, *terms: tuple[float, float, float]) -> np.ndarray:
    """Sum of ``amplitude * sin(2 pi f t + phase)`` over (amplitude, f, phase)."""
    return sum(a * np.sin(2 * np.pi * f * t + p) for a, f, p in terms)


def ode(rhs: Callable, t: np.ndarray, x0: list[float]) -> np.ndarray:
    """Solve ``x' = rhs(t, x)`` at ``t`` with DOP853 at a tolerance of 1e-11."""
    sol = solve_ivp(rhs, (t[0], t[-1]), x0, "DOP853", t_eval=t, rtol=1e-11, atol=1e-12)
    return sol.y


def me_data(fmu: Path, truth: dict[str, float]) -> Made:
    """Mass_Damper's data: its Model Exchange at 1e-10 (no independent solution at hand)."""
    from tsid_fmu.fmu import FMUSession

    t = np.arange(0, 1.0 + 1e-9, 0.002)
    f = sines(t, (1000, 3, 0), (600, 17, 0))  # the forced motion outweighs the free one
    truth = {k: truth[k] for k in ("mass.m", "damper.d", "spring.c")}
    with FMUSession(
        fmu, ["f"], ["y"], parameters=list(truth), interface="me", tolerance=1e-10
    ) as s:
        y = s.simulate(t, f[:, None], truth)[:, 0]
    return pd.DataFrame({"time": t, "f": f, "y": y}), "the FMU's Model Exchange at 1e-10"


def me_free_data(fmu: Path, truth: dict[str, float]) -> Made:
    """Mass_Damper released from its start (no force measured): its Model Exchange at 1e-10."""
    from tsid_fmu.fmu import FMUSession

    t = np.arange(0, 2.0 + 1e-9, 0.002)
    truth = {k: truth[k] for k in ("mass.m", "damper.d", "spring.c")}
    with FMUSession(
        fmu, ["f"], ["y"], parameters=list(truth), interface="me", tolerance=1e-10
    ) as s:
        y = s.simulate(t, np.zeros((t.size, 1)), truth)[:, 0]
    return pd.DataFrame({"time": t, "y": y}), "the FMU's Model Exchange at 1e-10, f = 0"


def add_data(fmu: Path, p: dict[str, float]) -> Made:
    t = np.arange(0, 1.0 + 1e-9, 0.01)
    u1, u2 = sines(t, (1, 1, 0), (0.5, 3.3, 0)), sines(t, (1, 0.7, 1), (0.3, 5.1, 0))
    y = p["add.k1"] * u1 + p["add.k2"] * u2
    return pd.DataFrame({"time": t, "u1": u1, "u2": u2, "y": y}), "y = k1 u1 + k2 u2"


def ramp_data(fmu: Path, p: dict[str, float]) -> Made:
    t = np.arange(0, 1.5 + 1e-9, 0.005)
    frac = np.clip((t - p["ramp.startTime"]) / p["ramp.duration"], 0, 1)
    out = p["ramp.offset"] + p["ramp.height"] * frac
    return pd.DataFrame({"time": t, "out": out}), "Modelica.Blocks.Sources.Ramp's formula"


def spring_data(fmu: Path, p: dict[str, float]) -> Made:
    """MassSpringSystem: m1 x1'' = k2 x2 - (k1+k2) x1, m2 x2'' = k2 x1 - (k2+k3) x2."""
    t = np.arange(0, 20 + 1e-9, 0.02)
    k1, k2, k3, m1, m2 = (p[n] for n in ("k1", "k2", "k3", "m1", "m2"))
    a = np.array([[0, 1, 0, 0], [-(k1 + k2) / m1, 0, k2 / m1, 0],
                  [0, 0, 0, 1], [k2 / m2, 0, -(k2 + k3) / m2, 0]])  # fmt: skip
    x = np.array([expm(a * ti) @ [0.0, 1.0, 1.0, 0.0] for ti in t])  # x1, v1, x2, v2
    return pd.DataFrame({"time": t, "x1": x[:, 0], "x2": x[:, 2]}), "matrix exponential"


def sub_data(which: int) -> Callable[[Path, dict[str, float]], Made]:
    """One mass of MassSpringSystem, the other's position an input (``x2`` or ``x1``)."""
    me, other = (f"x{which}", f"x{3 - which}")
    k, m = ("k1", "m1") if which == 1 else ("k3", "m2")

    def make(fmu: Path, p: dict[str, float]) -> Made:
        t = np.arange(0, 20 + 1e-9, 0.01)
        terms = ((0.5, 0.3, 0), (0.3, 0.7, 1.0))
        rhs = lambda s, x: [x[1], (p["k2"] * sines(s, *terms) - (p[k] + p["k2"]) * x[0]) / p[m]]  # noqa: E731
        x = ode(rhs, t, [0.0, 1.0] if which == 1 else [1.0, 0.0])
        cols = {"time": t, other: sines(t, *terms), me: x[0]}
        return pd.DataFrame(cols), "DOP853 at 1e-11 on the equation, the input as its sines"

    return make


def rc_data(fmu: Path, p: dict[str, float]) -> Made:
    """Simple2R1C: C T' = (Ti1 - T)/R1 + (Ti2 - T)/R2, modestpy's inputs, linear between."""
    u = pd.read_csv(fmu.parent / "inputs.csv")
    t = u.time.to_numpy(float)

    def rhs(s: float, x: np.ndarray) -> list[float]:
        ti1, ti2 = np.interp(s, t, u.Ti1), np.interp(s, t, u.Ti2)
        return [((ti1 - x[0]) / p["R1"] + (ti2 - x[0]) / p["R2"]) / p["C"]]

    temp = ode(rhs, t, [p.get("Tstart", 293.15)])[0]
    gap = np.abs(pd.read_csv(fmu.parent / "result.csv")["T"].to_numpy() - temp).max()
    how = f"DOP853 at 1e-11 (modestpy's result.csv differs by at most {gap:.2g} K)"
    return u.assign(T=temp), how


def rc_own_data(fmu: Path, p: dict[str, float]) -> Made:
    """Simple2R1C: modestpy's own ``result.csv`` (the FMU at ``parameters.csv``, inputs held)."""
    u = pd.read_csv(fmu.parent / "inputs.csv")
    temp = pd.read_csv(fmu.parent / "result.csv")["T"].to_numpy(float)
    return u.assign(T=temp), "modestpy's result.csv (its FMU at R1 0.1, R2 0.25, C 2000)"


def fmi3_data(fmu: Path, p: dict[str, float]) -> Made:
    """FMU3Model: output = 3 + increment * input(0) after init, + increment per step."""
    t = np.arange(0, 2 + 1e-9, 0.1)
    u = 1 + sines(t, (0.5, 0.5, 0.3))
    out = 3 + p["increment"] * u[0] + p["increment"] * np.arange(t.size)
    return pd.DataFrame({"time": t, "input": u, "output": out}), "its documented rule"


def lag_data(fmu: Path, p: dict[str, float]) -> Made:
    """PyLag: der(y) = (u - y)/tau solved exactly (the FMU steps it by explicit Euler)."""
    t = np.arange(0, 10 + 1e-9, 0.01)
    terms = ((1, 0.1, 0), (0.5, 0.37, 0.5))
    y = ode(lambda s, x: [(sines(s, *terms) - x[0]) / p["tau"]], t, [0.0])[0]
    return pd.DataFrame({"time": t, "u": sines(t, *terms), "y": y}), "DOP853 at 1e-11"


def quirk_data(fmu: Path, p: dict[str, float]) -> Made:
    """A quirk FMU's lag: x' = (u - x)/tau from x0, exact for the input held per sample."""
    sys.path.insert(0, str(ROOT / "tests"))
    from fmu_factory import lag_response

    t = np.arange(0, 5.0 + 1e-9, 0.01)
    u = np.where((t % 2.0) < 1.0, 1.0, -0.5) + 0.3 * np.sin(3 * t)
    y = lag_response(t, u, p["tau"], p["x0"])
    return pd.DataFrame({"time": t, "u": u, "y": y}), "the lag's exact step response"


QUIRK_HAND = (
    'tau = { levels = [0.05, 0.5, 2.0], min = 0.0, unit = "s" }\n'
    "x0 = { levels = [-1.0, 0.0, 2.0] }\n"
)
QUIRKS = [
    Case(f"quirk {name} (FMI {fmi})", f"quirk:{name}:{fmi}", "", {"tau": 0.37, "x0": 0.8},
         quirk_data, ["u"], ["y"], QUIRK_HAND + hand)
    for name, fmi, hand in (
        ("none", "2.0", ""), ("STALE_CLOCK", "2.0", ""), ("STALE_CLOCK", "3.0", ""),
        ("NONDETERMINISTIC", "2.0", ""), ("LOOSE_TOLERANCE", "2.0", ""),
        ("LOOSE_TOLERANCE", "3.0", ""), ("ASSERT_RANGE", "2.0", ""),
        # a user who frees everything the FMU offers; a time step no one would free by hand
        ("NO_EFFECT", "2.0", "spare = { levels = [0.5, 1.0, 2.0] }\n"),
        ("NUMERICAL_SETTING", "2.0", ""),
    )
]  # fmt: skip
"""One synthetic FMU per quirk of issue 62 (see ``build_c_fmu``'s ``quirks``): FMI 2.0
ones Co-Simulation only, as 20-sim's and most vendors' are."""

SPRING = {"k1": 2.0, "k2": 0.6, "k3": 1.5, "m1": 0.6, "m2": 2.0}
RC = {"R1": 0.1, "R2": 0.25, "C": 2000.0}  # modestpy's parameters.csv
RC_HAND = """R1 = { levels = [0.02, 0.05, 0.12, 0.3, 0.6], min = 0.001 }
R2 = { levels = [0.02, 0.05, 0.12, 0.3, 0.6], min = 0.001 }
"""
RC_STUDY = "start_values = { C = 2000.0 }  # the scale: the data fix only R1 C and R2 C"
RC_COMBOS = {"R1 C": ("R1", "C", 1), "R2 C": ("R2", "C", 1)}
KM = {f"k{i}/m{j}": (f"k{i}", f"m{j}", -1) for i, j in ((1, 1), (2, 1), (2, 2), (3, 2))}
CASES = [
    Case("Mass_Damper", GEMSEO, OM + "Mass_Damper.fmu",
         {"mass.m": 2.0, "damper.d": 6.0, "spring.c": 6000.0}, me_data, ["f"], ["y"],
         '"mass.m" = { levels = [0.5, 1, 3, 6, 10], min = 0.01 }\n'
         '"damper.d" = { levels = [1, 3, 10, 20, 40], min = 0.01 }\n'
         '"spring.c" = { levels = [1000, 3000, 10000, 20000, 40000], min = 1 }\n',
         'interface = "me"  # its Co-Simulation is a fixed explicit Euler step'),
    Case("Mass_Damper free response", GEMSEO, OM + "Mass_Damper.fmu",
         {"mass.m": 2.0, "damper.d": 6.0, "spring.c": 6000.0}, me_free_data, [], ["y"],
         '"damper.d" = { levels = [1, 3, 10, 20, 40], min = 0.01 }\n'
         '"spring.c" = { levels = [1000, 3000, 10000, 20000, 40000], min = 1 }\n',
         'interface = "me"\nstart_values = { "mass.m" = 2.0 }  # the scale: a free '
         "response fixes only c/m and d/m",
         combos={"damper.d/mass.m": ("damper.d", "mass.m", -1),
                 "spring.c/mass.m": ("spring.c", "mass.m", -1)}),
    Case("add", GEMSEO, OM + "add.fmu", {"add.k1": 2.0, "add.k2": 0.6}, add_data,
         ["u1", "u2"], ["y"],
         '"add.k1" = { levels = [0.3, 1, 3] }\n"add.k2" = { levels = [0.3, 1, 3] }\n'),
    Case("ramp", GEMSEO, OM + "ramp.fmu",
         {"ramp.height": 2.0, "ramp.duration": 0.6, "ramp.offset": 0.5,
          "ramp.startTime": 0.2}, ramp_data, [], ["out"],
         '"ramp.height" = { levels = [0.5, 1, 3, 5] }\n'
         '"ramp.duration" = { levels = [0.3, 0.5, 0.8, 1.1], min = 0.01 }\n'
         '"ramp.offset" = { levels = [-1, 0, 1, 2] }\n'
         '"ramp.startTime" = { levels = [0, 0.1, 0.3, 0.4], min = 0 }\n'),
    Case("MassSpringSystem", GEMSEO, OM + "MassSpringSystem.fmu", SPRING, spring_data,
         [], ["x1", "x2"],
         "k1 = { levels = [0.5, 1, 3, 5], min = 0.01 }\nk2 = { levels = [0.2, 0.4, 1, 2], "
         "min = 0.01 }\nk3 = { levels = [0.5, 1, 3, 5], min = 0.01 }\n"
         "m1 = { levels = [0.2, 0.4, 1, 2], min = 0.01 }\n",
         "start_values = { m2 = 2.0 }  # the scale: free oscillation fixes only k/m",
         combos=KM),
    Case("MassSpringSubSystem1", GEMSEO, OM + "MassSpringSubSystem1.fmu",
         {k: SPRING[k] for k in ("k1", "k2", "m1")}, sub_data(1), ["x2"], ["x1"],
         "k1 = { levels = [0.5, 1, 3, 5], min = 0.01 }\n"
         "k2 = { levels = [0.2, 0.4, 1, 2], min = 0.01 }\n",
         "start_values = { m1 = 0.6 }  # the scale", 'hold = { x2 = "linear" }',
         combos={k: v for k, v in KM.items() if k.endswith("m1")}),
    Case("MassSpringSubSystem2", GEMSEO, OM + "MassSpringSubSystem2.fmu",
         {k: SPRING[k] for k in ("k2", "k3", "m2")}, sub_data(2), ["x1"], ["x2"],
         "k2 = { levels = [0.2, 0.4, 1, 2], min = 0.01 }\n"
         "k3 = { levels = [0.5, 1, 3, 5], min = 0.01 }\n",
         "start_values = { m2 = 2.0 }  # the scale", 'hold = { x1 = "linear" }',
         combos={k: v for k, v in KM.items() if k.endswith("m2")}),
    Case("FMU3Model", GEMSEO, OM + "FMU3Model.fmu", {"increment": 2.0}, fmi3_data,
         ["input"], ["output"], "increment = { levels = [0.5, 1, 3, 5] }\n"),
    Case("Simple2R1C", MODESTPY, MP + "simple2R1C/Simple2R1C_linux64.fmu", RC, rc_data,
         ["Ti1", "Ti2"], ["T"], RC_HAND, RC_STUDY, 'hold = { Ti1 = "linear", Ti2 = "linear" }',
         RC_COMBOS, gfortran=True),
    Case("Simple2R1C on result.csv", MODESTPY, MP + "simple2R1C/Simple2R1C_linux64.fmu",
         RC, rc_own_data, ["Ti1", "Ti2"], ["T"], RC_HAND, RC_STUDY, "", RC_COMBOS,
         gfortran=True),
    Case("Simple2R1C_ic", MODESTPY, MP + "simple2R1C_ic/Simple2R1C_ic_linux64.fmu",
         {**RC, "Tstart": 293.15}, rc_data, ["Ti1", "Ti2"], ["T"],
         RC_HAND + "Tstart = { levels = [270, 280, 290, 300, 310] }\n", RC_STUDY,
         'hold = { Ti1 = "linear", Ti2 = "linear" }', RC_COMBOS, gfortran=True),
    Case("PyLag (pythonfmu)", "pythonfmu", "", {"tau": 2.0}, lag_data, ["u"], ["y"],
         "tau = { levels = [0.3, 1, 3, 6], min = 0.01 }\n"),
    *QUIRKS,
]  # fmt: skip


def fetch(requirement: str, *extra: str) -> Path:
    """The wheel of ``requirement`` (``name==version``) in the cache, downloaded once."""
    name, version = requirement.split("==")
    pattern = f"{name.replace('-', '_')}-{version}-*.whl"
    if not any(WHEELS.glob(pattern)):
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d", str(WHEELS)]
        subprocess.run([*cmd, requirement, *extra], check=True, capture_output=True)
    return next(WHEELS.glob(pattern))


def loads(so: Path, libdir: Path) -> str:
    """'' when the shared library loads with ``libdir`` on LD_LIBRARY_PATH, else why not."""
    env = {**os.environ, "LD_LIBRARY_PATH": str(libdir)}
    code = "import ctypes, sys; ctypes.CDLL(sys.argv[1])"
    proc = subprocess.run([sys.executable, "-c", code, so], env=env, capture_output=True, text=True)
    return proc.stderr.strip().splitlines()[-1] if proc.returncode else ""


# the symbols JModelica's FMUs import from libgfortran.so.3 (a Fortran WRITE statement)
STUB = {"GFORTRAN_1.0": ("concat_string", "st_write", "st_write_done"),
        "GFORTRAN_1.4": ("transfer_character_write", "transfer_integer_write")}  # fmt: skip


def gfortran(so: Path) -> tuple[Path, str]:
    """A folder with ``libgfortran.so.3`` for ``so``, and a note on where it came from."""
    lib = CACHE / "gfortran"
    lib.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(fetch(*GFORTRAN_WHEEL)) as whl:
        for member in whl.namelist():
            base = Path(member).name
            for soname in ("libgfortran.so.3", "libquadmath.so.0"):
                if ".libs/" in member and base.startswith(soname.split(".")[0] + "-"):
                    (lib / base).write_bytes(whl.read(member))
                    (lib / soname).unlink(missing_ok=True)
                    (lib / soname).symlink_to(base)
    why = loads(so, lib)
    if not why:
        return lib, f"libgfortran.so.3 from the {GFORTRAN_WHEEL[0]} wheel"
    # the wheels' libgfortran stops at GFORTRAN_1.2 (1.4 is needed): a no-op stub of STUB
    stub = CACHE / "gfortran-stub"
    stub.mkdir(exist_ok=True)
    (stub / "stub.c").write_text(
        "".join(f"void _gfortran_{f}(void) {{}}\n" for f in sum(STUB.values(), ()))
    )
    (stub / "stub.map").write_text(
        "".join(
            f"{v} {{ global: _gfortran_{'; _gfortran_'.join(fs)}; }};\n" for v, fs in STUB.items()
        )
    )
    gcc = subprocess.run(["gcc", "-shared", "-fPIC", "-o", str(stub / "libgfortran.so.3"),
                          "-Wl,-soname,libgfortran.so.3", "-Wl,--version-script=stub.map",
                          "stub.c"], cwd=stub, capture_output=True, text=True)  # fmt: skip
    why, still = re.sub(r"/\S*/", "", why), gcc.stderr.strip() or loads(so, stub)
    said = f"{GFORTRAN_WHEEL[0]}'s libgfortran: `{why}`"
    return (
        (lib, f"{said}; the stub failed too: {still}")
        if still
        else (stub, f"{said}; ran with a no-op stub")
    )


def obtain(case: Case, folder: Path) -> Path:
    """Put the case's FMU (and modestpy's CSV files beside it) into ``folder``."""
    if case.source == "pythonfmu":
        sys.path.insert(0, str(ROOT / "tests"))
        from fmu_factory import build_pythonfmu

        return build_pythonfmu(folder)
    if case.source.startswith("quirk:"):
        sys.path.insert(0, str(ROOT / "tests"))
        from fmu_factory import build_c_fmu

        _, quirk, fmi = case.source.split(":")
        kind = {"fmi_version": fmi} if fmi == "3.0" else {"interfaces": ("cs",)}
        quirks = [quirk] if quirk != "none" else []
        return build_c_fmu(folder, "Quirk" + fmi[0], quirks=quirks, **kind)
    with zipfile.ZipFile(fetch(case.source)) as whl:
        wanted = [case.member]
        if case.gfortran:
            wanted += [str(Path(case.member).parent / n) for n in ("inputs.csv", "result.csv")]
        for member in wanted:
            (folder / Path(member).name).write_bytes(whl.read(member))
    return folder / Path(case.member).name


def describe(fmu: Path) -> tuple[str, str, dict[str, float], list[str]]:
    """Generation tool, FMI version, start values and shared libraries of ``fmu``."""
    with zipfile.ZipFile(fmu) as z:
        root = ElementTree.fromstring(z.read("modelDescription.xml"))
        libs = [n for n in z.namelist() if n.startswith("binaries/linux64/") and n.endswith(".so")]
    starts = {}
    for var in root.iter():
        start = next((c.get("start") for c in var if c.get("start") is not None), var.get("start"))
        if var.get("name") and start is not None:
            try:
                starts[var.get("name")] = float(start)
            except ValueError:
                pass
    return root.get("generationTool", "?"), root.get("fmiVersion", "?"), starts, libs


def tsid(folder: Path, env: dict[str, str], *args: str) -> subprocess.CompletedProcess:
    """Run ``tsid ARGS`` in ``folder`` as a user would (this Python's tsid_fmu)."""
    cmd = [sys.executable, "-m", "tsid_fmu", *args]
    try:
        return subprocess.run(cmd, cwd=folder, env=env, capture_output=True, text=True,
                              timeout=SUBPROCESS_LIMIT)  # fmt: skip
    except subprocess.TimeoutExpired:
        return subprocess.CompletedProcess(cmd, -1, "", f"no answer in {SUBPROCESS_LIMIT} s")


def judge(summary: dict, truth: dict[str, float], combos: dict) -> str:
    """'k/n' determined parameters within 1 % with the truth inside, then what missed."""
    good, missed, loose = 0, [], []
    params = summary["parameters"]
    for name, p in params.items():
        lo, hi = p["interval"]
        if lo is None or hi is None or not math.isfinite(lo + hi):
            loose.append(name)
            continue
        true = truth.get(name, math.nan)
        err = p["value"] / true - 1 if true else math.nan
        if abs(err) <= 0.01 and lo <= true <= hi:
            good += 1
        else:
            inside = "inside" if lo <= true <= hi else "outside"
            missed.append(f"{name} {err:+.1%} (truth {inside} [{lo:.4g}, {hi:.4g}])")
    text = f"{good}/{good + len(missed)}" + "".join(f"; ✗ {m}" for m in missed)
    if loose:
        text += "; not determined: " + ", ".join(loose)
    value = {n: p["value"] for n, p in params.items()}
    if combos and any(a in value for a, _, _ in combos.values()):
        errs = [(value.get(a, truth[a]) * value.get(b, truth[b]) ** k) / (truth[a] * truth[b] ** k)
                - 1 for a, b, k in combos.values()]  # fmt: skip
        shown = ", ".join(f"{c} {e:+.2%}" for c, e in zip(combos, errs, strict=True))
        text += (
            f"; combinations within 1 %: {sum(abs(e) <= 0.01 for e in errs)}/{len(errs)} ({shown})"
        )
    return text


def identify(folder: Path, env: dict[str, str], study: str, out: str, workers: int) -> tuple:
    """``tsid identify --json``: (cell, summary or None, note, the interface it ran)."""
    t0 = time.monotonic()
    proc = tsid(folder, env, "identify", study, "--out", out, "--json", "-q",
                "--workers", str(workers), "--timeout", "60")  # fmt: skip
    secs = time.monotonic() - t0
    try:
        summary = json.loads(proc.stdout)
    except json.JSONDecodeError:
        last = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        return f"exit {proc.returncode}, no JSON", None, f"{last} ({secs:.0f} s)", "?"
    probe = summary.get("conformance") or {}  # reset and determinism (issue 62)
    odd = probe.get("fresh") or probe.get("deterministic") is False or not probe.get("probed")
    probed = f"; conformance: {probe.get('message')}" if probe and odd else ""
    try:  # what "auto" became: the fidelity check's record in result.json
        record = json.loads((folder / out / "result.json").read_text(encoding="utf-8"))
        fidelity = record["extra"]["fidelity"]
        ran = (fidelity.get("answer") or fidelity["start"])["interface"]
    except (OSError, KeyError, TypeError, ValueError):
        ran = "?"
    warns = summary["warnings"]
    short = [w if len(w) < 90 else w[:80] + "…" for w in warns[:2]]
    more = f" (+{len(warns) - 2} more warnings)" if len(warns) > 2 else ""
    note = f"{secs:.0f} s, status {summary['status']}" + "".join(f"; ⚠ {w}" for w in short) + more
    note += probed
    return f"exit {proc.returncode}, nfev {summary['nfev']}", summary, note, ran


def hand_toml(case: Case, fmu: Path) -> str:
    """The hand-written study: the case's parameters, the data's columns, SSE by noise."""
    cols = lambda names: "{ " + ", ".join(f'{n} = "{n}"' for n in names) + " }"  # noqa: E731
    inputs = f"inputs = {cols(case.inputs)}\n" if case.inputs else ""
    return (f'[study]\nname = "{case.name} by hand"\nfmu = "{fmu.name}"\n{case.hand_study}\n'
            f'[data]\nfile = "data.csv"\n{inputs}outputs = {cols(case.outputs)}\n'
            f'{case.hand_data}\n[method]\ncost = "sse"\nweighting = "noise"\nreplicates = 1\n'
            f"\n[parameters]\n{case.hand}")  # fmt: skip


def run_case(case: Case, workers: int) -> dict[str, str]:
    """Every step for one FMU; a row of the table (errors go into its cells)."""
    row = dict.fromkeys(("tool", "fmi", "interface", "info", "init", "hand", "judged"), "–")
    notes: list[str] = []
    folder = WORK / re.sub(r"\W+", "_", case.name).strip("_")
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    env = dict(os.environ)
    try:
        fmu = obtain(case, folder)
        row["tool"], row["fmi"], starts, libs = describe(fmu)
        if case.gfortran and libs:
            with zipfile.ZipFile(fmu) as z:
                so = Path(z.extract(libs[0], folder / "unzipped"))
            libdir, note = gfortran(so)
            env["LD_LIBRARY_PATH"] = str(libdir)
            notes.append(note)
        info = tsid(folder, env, "info", fmu.name)
        shown = sum(
            bool(re.search(rf"^\s*{re.escape(n)}\s", info.stdout, re.M)) for n in case.truth
        )
        row["info"] = f"exit {info.returncode}, lists {shown}/{len(case.truth)} parameters"
        truth = starts | case.truth
        made, how = case.data(fmu, truth)
        rng = np.random.default_rng(1)
        for col in case.outputs:
            made[col] += rng.normal(0, 0.01 * made[col].std(), len(made))
        made.to_csv(folder / "data.csv", index=False)
        notes.append(f"data: {how}, 1 % noise")
        kinds = [("init", "init.toml", "out_init")]
        init = tsid(folder, env, "init", fmu.name, "data.csv", "-o", "init.toml")
        if init.returncode:
            row["init"] = f"init exit {init.returncode}"
            notes.append("init: " + (init.stderr.strip().splitlines() or ["?"])[-1])
            kinds = []
        if case.hand:
            (folder / "hand.toml").write_text(hand_toml(case, fmu), encoding="utf-8")
            kinds.append(("hand", "hand.toml", "out_hand"))
        judged, used = [], []
        for kind, study, out in kinds:
            spec = tomllib.loads((folder / study).read_text(encoding="utf-8"))
            row[kind], summary, note, ran = identify(folder, env, study, out, workers)
            asked = spec["study"].get("interface", "auto")
            used.append(f"{kind} {asked}" + (f"→{ran}" if asked != ran else ""))
            said = judge(summary, truth, case.combos) if summary is not None else note
            judged += [f"{kind}: {said}"] if summary is not None else []
            notes.append(f"{kind}: {note}")
            print(f"  {case.name:22s} {kind:5s} {row[kind]:22s} {said}", flush=True)
        row["interface"], row["judged"] = ", ".join(used) or "–", "<br>".join(judged) or "–"
    except Exception as exc:  # a measurement: the row says what went wrong
        notes.append(f"{type(exc).__name__}: {exc}".replace("\n", " ")[:300])
        print(f"  {case.name:22s} error  {notes[-1]}")
    row["notes"] = "<br>".join(notes)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="run the FMUs whose name contains this")
    parser.add_argument("--workers", type=int, default=2, help="tsid identify --workers")
    args = parser.parse_args(argv)
    WHEELS.mkdir(parents=True, exist_ok=True)
    t0, rows = time.monotonic(), []
    for case in [c for c in CASES if args.only in c.name]:
        rows.append((case.name, run_case(case, args.workers)))
    head = (
        "FMU | tool | FMI version | interface used | info | init → identify (exit, nfev) | "
        "hand study (exit, nfev) | determined params within 1 % with truth inside | notes"
    )
    print(f"\n| {head} |\n|" + "---|" * (head.count("|") + 1))
    for name, r in rows:
        cells = [name, r["tool"], r["fmi"], r["interface"], r["info"], r["init"], r["hand"],
                 r["judged"], r["notes"]]  # fmt: skip
        print("| " + " | ".join(c.replace("|", "/") for c in cells) + " |")
    print(f"\nwall time {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
