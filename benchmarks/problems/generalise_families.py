"""Problem families of the generalisation benchmark (``benchmarks/generalise.py``).

Each family draws a :class:`~problems.generalise_draw.GenProblem` from a NumPy
``Generator``: random true values, excitation, sensor noise (white or AR(1)), model
mismatch, first ranges and level styles (:mod:`problems.generalise_draw`), and FMU start
values that are plausible but not the truth (for ``tsid init``).  The data always come
from an independent solution, never from the FMU.

=============  ==========================================  ============================
family         FMU (exporter)                              tests
=============  ==========================================  ============================
lsea_siso      fmus/LSEA_SISO.fmu (tsid-fmu's Modelica)    dry friction, stick-slip
lsea_miso      fmus/LSEA_MISO.fmu (tsid-fmu's Modelica)    two inputs, derived inputs
siso_rig       fmus/LSEA_SISO.fmu, the SISO example study  another truth, load cells and
                                                           a 1 um encoder (not in the
                                                           default mix: ``--family``)
dc_motor       pythonfmu DC motor (Python slave)           5 parameters, two outputs
duffing        hand-written C FMU (tests' C factory)       nonlinear oscillator
pendulum       DrivenPendulum (tsid-fmu's Modelica)        large swings, sin(theta)
second_order   RingingOscillator (tsid-fmu's Modelica)     linear second-order system
local_minima   RingingOscillator, lightly damped           a cost with local minima
=============  ==========================================  ============================
"""

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from problems import dc_motor as dc_mod
from problems import duffing_c
from problems import local_minima as lm_mod
from problems import miso as miso_mod
from problems import siso as siso_mod
from problems.base import Problem, ProblemExperiment, cached_build, sample_times
from problems.generalise_draw import (
    MISMATCHES,
    GenProblem,
    InitCase,
    add_noise,
    draw_noise_kind,
    draw_ranges,
    draw_sigma,
    draw_starts,
    fmu_with_starts,
    integrate,
    multilevel,
    perturb,
)


def _hand_names(
    rng: np.random.Generator, names: list[str], always: tuple[str, ...] = ()
) -> list[str]:
    """A random subset of 2 to 5 of ``names`` (in their order, with ``always``)."""
    count = int(rng.integers(2, min(5, len(names)) + 1))
    rest = [n for n in names if n not in always]
    chosen = set(always) | set(rng.choice(rest, count - len(always), replace=False).tolist())
    return [n for n in names if n in chosen]


def _assemble(
    rng: np.random.Generator,
    head: tuple[str, int],
    fmu_info: tuple,
    experiments: list[ProblemExperiment],
    noise: dict[str, float],
    init: InitCase,
    notes: dict[str, str],
    hold: dict[str, str] | None = None,
    fixed: dict[str, float] | None = None,
    always: tuple[str, ...] = (),
) -> GenProblem:
    """Draw the hand-written study's parameters and the FMU's start values; build it all.

    ``head`` is ``(family, seed)``; ``fmu_info`` is ``(fmu, truth, units)``; ``fixed``
    are model constants every run sets (not identified by either variant's user);
    ``always`` are always identified in the hand-written study.
    """
    fmu, truth, units = fmu_info
    names = _hand_names(rng, list(truth), always)
    parameters, placed = draw_ranges(rng, {n: truth[n] for n in names}, units)
    starts = draw_starts(rng, truth)
    problem = Problem(
        name=f"{head[0]}-{head[1]}",
        fmu=fmu_with_starts(fmu, starts),
        truth=dict(truth),
        parameters=parameters,
        experiments=experiments,
        noise=noise,
        start_values={**(fixed or {}), **{k: v for k, v in truth.items() if k not in names}},
    )
    notes = {**notes, **{f"range {k}": v for k, v in placed.items()}}
    notes["starts"] = ", ".join(f"{k} {v:g}" for k, v in starts.items())
    return GenProblem(head[0], head[1], problem, init, hold or {}, notes)


def _mismatch(rng: np.random.Generator, choices: tuple[str, ...] = MISMATCHES) -> str:
    return str(rng.choice(list(choices)))


def lsea_siso(rng: np.random.Generator, seed: int) -> GenProblem:
    """LSEA SISO: 4 s of the paper's square waves, two noisy load cells, random truth."""
    gen = siso_mod._generator()
    truth = perturb(rng, gen.TRUTH, 0.4)
    t = sample_times(4.0)
    f_m = gen.motor_force(t)
    _, _, f_o = gen.simulate(t, f_m, truth)
    kind = draw_noise_kind(rng)
    sigma = float(rng.uniform(2.0, 6.0))
    front = add_noise(rng, np.maximum(f_o, 0.0), sigma, kind)
    rear = add_noise(rng, np.maximum(-f_o, 0.0), sigma, kind)
    frame = pd.DataFrame({"time": t, "F_m": f_m, "F_of": front, "F_or": rear})
    derived = {"F_o": "F_of - F_or"}
    exp = ProblemExperiment("measured", frame, {"F_m": "F_m"}, {"F_o": "F_o"}, dict(derived))
    units = {k: unit for k, (_, _, unit) in siso_mod.TABLE_I.items()}
    return _assemble(
        rng,
        ("lsea_siso", seed),
        (siso_mod.FMU, truth, units),
        [exp],
        {"F_o": math.sqrt(2) * sigma},
        InitCase(frame, derived),
        {"mismatch": "none (FMU's RK4 vs exact)", "noise": kind},
        fixed={"V_z": gen.V_Z},
    )


def siso_rig(rng: np.random.Generator, seed: int) -> GenProblem:
    """The SISO example's study (Table I levels, L25) on the same rig with another truth.

    10 s of the paper's square waves at 1 kHz, two compression-only load cells and the
    motor encoder quantised to 1 um, from the example's independent generator: what a
    user of the example gets on their own rig. The hand-written study is the example's
    ``study.toml`` (its levels and ``[method]``); ``tsid init`` gets the same CSV.
    """
    gen = siso_mod._generator()
    truth = perturb(rng, gen.TRUTH, 0.4)
    t = gen.sample_times()
    f_m = gen.motor_force(t)
    x_m, _, f_o = gen.simulate(t, f_m, truth)
    cell = float(rng.uniform(2.0, 6.0))
    front, rear = gen.load_cells(f_o, cell, cell, rng)
    encoder = gen.quantise(x_m, gen.ENCODER_STEP)
    frame = pd.DataFrame({"time": t, "F_m": f_m, "F_of": front, "F_or": rear, "x_m": encoder})
    derived = {"F_o": "F_of - F_or"}
    outputs = {"F_o": "F_o", "x_m": "x_m"}
    exp = ProblemExperiment("measured", frame, {"F_m": "F_m"}, outputs, dict(derived))
    parameters = {
        k: {"levels": list(levels), "min": low, "max": None, "unit": unit}
        for k, (levels, low, unit) in siso_mod.TABLE_I.items()
    }
    problem = Problem(
        name=f"siso_rig-{seed}",
        fmu=siso_mod.FMU,
        truth=dict(truth),
        parameters=parameters,
        experiments=[exp],
        noise={"F_o": math.sqrt(2) * cell, "x_m": gen.NOISE["x_m"]},
        start_values={"V_z": gen.V_Z},
    )
    notes = {"mismatch": "none (FMU's RK4 vs exact)", "noise": f"load cells {cell:.3g} N"}
    notes["truth"] = ", ".join(f"{k} {v:g}" for k, v in truth.items())
    method = {"array": "L25", "max_iterations": 25, "start": "centre"}
    init = InitCase(frame, derived)
    stated = {"x_m": gen.NOISE["x_m"]}  # the example's study states the encoder's
    return GenProblem("siso_rig", seed, problem, init, {}, notes, method, stated)


def lsea_miso(rng: np.random.Generator, seed: int) -> GenProblem:
    """LSEA MISO: 3 s force-only and motion-only experiments (hand), combined (init)."""
    gen = miso_mod._generator()
    truth = perturb(rng, gen.TRUTH, 0.4)
    t = sample_times(3.0)
    kind = draw_noise_kind(rng)
    sigma = float(rng.uniform(0.5, 2.0))
    frames = {}
    for name in ("force_only", "motion_only", "combined"):
        f_m, stage = gen.experiment_inputs(name, t)
        f_o = gen.simulate(t, f_m, stage, truth)
        x_o = np.zeros_like(t) if stage is None else stage(t)[0]
        frames[name] = pd.DataFrame(
            {
                "time": t,
                "F_m": f_m,
                "x_o": np.round(x_o / gen.ENCODER_STEP) * gen.ENCODER_STEP,
                "F_of": add_noise(rng, np.maximum(f_o, 0.0), sigma, kind),
                "F_or": add_noise(rng, np.maximum(-f_o, 0.0), sigma, kind),
            }
        )
    derived = {"F_o": "F_of - F_or", "v_o": "der(x_o)", "a_o": "der(x_o, 2)"}
    inputs = {k: k for k in miso_mod.INPUTS}
    exps = [
        ProblemExperiment(name, frames[name], dict(inputs), {"F_o": "F_o"}, dict(derived))
        for name in ("force_only", "motion_only")
    ]
    units = {"m1": "kg", "m2": "kg", "K_s": "N/m", "C_d": "N.s/m", "C_1": "N.s/m", "C_2": "N.s/m"}
    return _assemble(
        rng,
        ("lsea_miso", seed),
        (miso_mod.FMU, truth, units),
        exps,
        {"F_o": math.sqrt(2) * sigma},
        InitCase(frames["combined"], derived),
        {"mismatch": "held stage inputs (see miso.py)", "noise": kind},
        hold={k: "linear" for k in ("x_o", "v_o", "a_o")},
    )


def _single_output(
    rng: np.random.Generator,
    t: np.ndarray,
    u: np.ndarray,
    clean: dict[str, np.ndarray],
    columns: tuple[str, str],
) -> tuple[pd.DataFrame, dict[str, float], str]:
    """The logged frame (``time``, input, outputs with noise), the sigmas, the noise kind."""
    kind = draw_noise_kind(rng)
    frame = pd.DataFrame({"time": t, columns[0]: u})
    sigmas = {}
    for name, y in clean.items():
        sigmas[name] = draw_sigma(rng, y)
        frame[name] = add_noise(rng, y, sigmas[name], kind)
    return frame, sigmas, kind


def _ode_problem(
    rng: np.random.Generator,
    head: tuple[str, int],
    fmu_info: tuple,
    signal: tuple[np.ndarray, np.ndarray, str],
    simulate: Callable[[str, float], dict[str, np.ndarray]],
    lag_range: tuple[float, float],
    mismatches: tuple[str, ...] = MISMATCHES,
    always: tuple[str, ...] = (),
) -> GenProblem:
    """A one-input problem whose data ``simulate(mismatch, lag)`` solves independently."""
    t, u, input_name = signal
    mismatch = _mismatch(rng, mismatches)
    lag = float(rng.uniform(*lag_range))
    clean = simulate(mismatch, lag)
    frame, sigmas, kind = _single_output(rng, t, u, clean, (input_name, ""))
    outputs = {k: k for k in clean}
    exp = ProblemExperiment("measured", frame, {input_name: input_name}, outputs, {})
    note = f"lag {lag * 1e3:.2g} ms" if mismatch == "lag" else mismatch
    return _assemble(
        rng,
        head,
        fmu_info,
        [exp],
        sigmas,
        InitCase(frame),
        {"mismatch": note, "noise": kind},
        always=always,
    )


def dc_motor(rng: np.random.Generator, seed: int) -> GenProblem:
    """pythonfmu DC motor: 1 s of a random voltage at 1 kHz, speed and current logged."""
    truth = perturb(rng, dc_mod.TRUTH, 0.5)
    t = sample_times(1.0)
    v = multilevel(rng, t, 12.0, (0.005, 0.2))
    r, ind, j, b, kt = (truth[k] for k in ("R", "L", "J", "b", "Kt"))

    def rhs(_t: float, s: np.ndarray, volts: float) -> list[float]:
        return [(volts - r * s[0] - kt * s[1]) / ind, (kt * s[0] - b * s[1]) / j]

    def simulate(mismatch: str, lag: float) -> dict[str, np.ndarray]:
        i, w = integrate(rhs, [0.0, 0.0], t, v, mismatch, lag).T
        return {"w": w, "i": i}

    units = {k: u for k, (_, _, u) in dc_mod.RANGES.items()}
    return _ode_problem(
        rng,
        ("dc_motor", seed),
        (dc_mod.build_fmu(), truth, units),
        (t, v, "V"),
        simulate,
        (2e-4, 1e-3),
    )


def duffing(rng: np.random.Generator, seed: int) -> GenProblem:
    """C-factory Duffing oscillator: 8 s at 100 Hz of a random force, position logged."""
    truth = perturb(rng, {"m": 1.0, "c": 0.6, "k": 40.0, "k3": 60.0}, 0.5)
    t = sample_times(8.0, 100.0)
    u = multilevel(rng, t, truth["k"] * rng.uniform(0.8, 1.5), (0.3, 2.0))
    mismatch = _mismatch(rng)
    fmu = duffing_c.build_fmu(0.02 if mismatch == "solver" else 1e-3)
    # the "solver" mismatch is the FMU's: one RK4 step per sample; the data stay exact
    data_mismatch = {"solver": "none"}

    def simulate(_: str, lag: float) -> dict[str, np.ndarray]:
        x = integrate(
            duffing_c.rhs(truth), [0.0, 0.0], t, u, data_mismatch.get(mismatch, mismatch), lag
        )
        return {"x": x[:, 0]}

    units = {"m": "kg", "c": "N.s/m", "k": "N/m", "k3": "N/m3"}
    return _ode_problem(
        rng,
        ("duffing", seed),
        (fmu, truth, units),
        (t, u, "u"),
        simulate,
        (0.005, 0.02),
        mismatches=(mismatch,),
    )


def _ringing(truth: dict[str, float], t: np.ndarray, u: np.ndarray) -> Callable[[str, float], dict]:
    omega, zeta, k = truth["omega"], truth["zeta"], truth["k"]

    def rhs(_t: float, s: np.ndarray, level: float) -> list[float]:
        return [s[1], omega**2 * (k * level - s[0]) - 2 * zeta * omega * s[1]]

    def simulate(mismatch: str, lag: float) -> dict[str, np.ndarray]:
        return {"y": integrate(rhs, [0.0, 0.0], t, u, mismatch, lag)[:, 0]}

    return simulate


def _log_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(f"{math.exp(rng.uniform(math.log(low), math.log(high))):.4g}")


RING_UNITS = {"omega": "rad/s", "zeta": "1", "k": "1"}


def second_order(rng: np.random.Generator, seed: int) -> GenProblem:
    """Modelica second-order system, damping 0.15-0.7: 6 s at 200 Hz, random steps."""
    truth = {
        "omega": _log_uniform(rng, 3.0, 30.0),
        "zeta": _log_uniform(rng, 0.15, 0.7),
        "k": _log_uniform(rng, 0.5, 5.0),
    }
    t = sample_times(6.0, 200.0)
    u = multilevel(rng, t, 1.0, (0.2, 1.5))
    fmu = (lm_mod.build_fmu(), truth, RING_UNITS)
    return _ode_problem(
        rng, ("second_order", seed), fmu, (t, u, "u"), _ringing(truth, t, u), (0.005, 0.02)
    )


def local_minima(rng: np.random.Generator, seed: int) -> GenProblem:
    """Modelica lightly damped oscillator (damping 0.01-0.03): two steps ring for 10 s."""
    truth = {
        "omega": _log_uniform(rng, 8.0, 20.0),
        "zeta": _log_uniform(rng, 0.01, 0.03),
        "k": _log_uniform(rng, 1.0, 4.0),
    }
    t = sample_times(10.0, 200.0)
    u = lm_mod.input_signal(t)
    fmu = (lm_mod.build_fmu(), truth, RING_UNITS)
    return _ode_problem(
        rng,
        ("local_minima", seed),
        fmu,
        (t, u, "u"),
        _ringing(truth, t, u),
        (0.002, 0.01),
        mismatches=("none", "solver", "lag"),
        always=("omega",),
    )


PENDULUM_NAME = "DrivenPendulum"
PENDULUM = """\
model DrivenPendulum "Pendulum driven by a torque, with viscous friction"
  parameter Real J(unit = "kg.m2") = 0.05 "Moment of inertia about the pivot";
  parameter Real b(unit = "N.m.s") = 0.02 "Viscous friction";
  parameter Real mgl(unit = "N.m") = 0.5 "Gravity torque at 90 degrees (m g l)";
  input Real tau(start = 0) "Torque";
  output Real y "Measured angle";
  Real theta(start = 0, fixed = true) "Angle from the bottom";
  Real w(start = 0, fixed = true) "Angular velocity";
equation
  der(theta) = w;
  J * der(w) = tau - b * w - mgl * sin(theta);
  y = theta;
end DrivenPendulum;
"""


def pendulum_fmu() -> Path:
    """Build the pendulum FMU from :data:`PENDULUM` (tsid_fmu.build) into the cache."""
    from tsid_fmu.build import build_fmu

    def build_in(folder: Path) -> Path:
        mo = folder / f"{PENDULUM_NAME}.mo"
        mo.write_text(PENDULUM)
        return build_fmu(mo, PENDULUM_NAME, folder / f"{PENDULUM_NAME}.fmu")

    return cached_build(PENDULUM_NAME, PENDULUM, build_in)


def pendulum(rng: np.random.Generator, seed: int) -> GenProblem:
    """Modelica pendulum, torque up to 1.5x its gravity torque: large swings, 8 s at 100 Hz."""
    truth = perturb(rng, {"J": 0.05, "b": 0.02, "mgl": 0.5}, 0.6)
    t = sample_times(8.0, 100.0)
    tau = multilevel(rng, t, truth["mgl"] * rng.uniform(0.6, 1.5), (0.5, 3.0))
    j, b, mgl = truth["J"], truth["b"], truth["mgl"]

    def rhs(_t: float, s: np.ndarray, torque: float) -> list[float]:
        return [s[1], (torque - b * s[1] - mgl * math.sin(s[0])) / j]

    def simulate(mismatch: str, lag: float) -> dict[str, np.ndarray]:
        return {"y": integrate(rhs, [0.0, 0.0], t, tau, mismatch, lag)[:, 0]}

    units = {"J": "kg.m2", "b": "N.m.s", "mgl": "N.m"}
    return _ode_problem(
        rng,
        ("pendulum", seed),
        (pendulum_fmu(), truth, units),
        (t, tau, "tau"),
        simulate,
        (0.005, 0.02),
    )


#: Family name -> (draw function, problems per seed set).
FAMILIES: dict[str, tuple[Callable[[np.random.Generator, int], GenProblem], int]] = {
    "lsea_siso": (lsea_siso, 5),
    "lsea_miso": (lsea_miso, 1),
    "siso_rig": (siso_rig, 0),
    "dc_motor": (dc_motor, 4),
    "duffing": (duffing, 8),
    "pendulum": (pendulum, 6),
    "second_order": (second_order, 6),
    "local_minima": (local_minima, 6),
}
