"""LSEA SISO with dry friction (SISO paper), data from the independent example generator.

The data are ``examples/lsea_siso/make_data.py``'s (imported by path, not copied):
piecewise-exact solution of LSEA_SISO with the rig's conventions (force held per 1 ms
sample, continuous outputs sampled, two compression-only load cells of 4 N each, motor
encoder quantised to 1 um).  First levels: Table I of the SISO paper.

Run:  python benchmarks/problems/siso.py   (self-check: independent data vs the FMU)
"""

import math
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # run as a script, or loaded from a file path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from problems.base import REPO, Problem, ProblemExperiment, introduce, load_module, rms_over_sigma

FMU = REPO / "fmus" / "LSEA_SISO.fmu"
GENERATOR = REPO / "examples" / "lsea_siso" / "make_data.py"

#: Table I of the SISO paper (K_s in N/m).
TABLE_I = {
    "F_cm": ([10.0, 50.0, 80.0, 100.0, 110.0], 0.0, "N"),
    "F_vm": ([1.0, 5.0, 10.0, 50.0, 80.0], 0.0, "N.s/m"),
    "M_m": ([4.0, 6.0, 8.0, 10.0, 12.0], 0.01, "kg"),
    "K_s": ([1000.0, 4000.0, 6000.0, 8000.0, 10000.0], 1.0, "N/m"),
    "B_s": ([0.1, 2.0, 5.0, 10.0, 20.0], 0.0, "N.s/m"),
}

NOTES = """\
Data: independent piecewise-exact solution (examples/lsea_siso/make_data.py), F_m held
per sample. F_o = F_of - F_or is the sum of two independent load-cell noises, so its
sigma is sqrt(2) times a cell's. x_m is an encoder reading (quantised to 1 um, no
other noise): its sigma is the quantisation's, 1 um/sqrt(12) = 0.29 um, which makes it
a very precise channel. The FMU (internal RK4 step fixedStepSize = 1e-4 s, relations
frozen over a step, switches located by bisection, including a passage through the
stick band |v_m| <= V_z that lasts less than one internal step, e.g. ~40-80 us where
the velocity reverses under a large spring force) agrees with the independent solution
to x_m RMS 0.001 sigma (0.3 nm) and F_o RMS ~5e-7 sigma at its default step (0.01 s
per run), so x_m can be weighed by its true sigma.
V_z = 0.001 m/s is a fixed model constant (start_values)."""


def _generator():
    return load_module(GENERATOR, "tsid_examples_lsea_siso_make_data")


def siso(encoder: bool, seed: int = 1) -> Problem:
    """Return the SISO problem (load-cell force, and the motor encoder if ``encoder``).

    Parameters
    ----------
    encoder : bool
        Whether the motor encoder ``x_m`` is logged and compared.
    seed : int
        Seed of the sensor noise.

    Returns
    -------
    Problem
        One experiment ``measured``: columns ``time, F_m, F_of, F_or`` (and ``x_m``).
    """
    gen = _generator()
    data = gen.make_data(seed)
    outputs = {"F_o": "F_o"}
    noise = {"F_o": math.hypot(gen.NOISE["F_of"], gen.NOISE["F_or"])}
    if encoder:
        outputs["x_m"] = "x_m"
        noise["x_m"] = gen.NOISE["x_m"]
    else:
        data = data.drop(columns="x_m")
    experiment = ProblemExperiment(
        name="measured",
        data=data,
        inputs={"F_m": "F_m"},
        outputs=outputs,
        derived={"F_o": "F_of - F_or"},
    )
    parameters = {
        name: {"levels": list(lv), "min": lo, "max": math.inf, "unit": unit}
        for name, (lv, lo, unit) in TABLE_I.items()
    }
    return Problem(
        name="lsea_siso_encoder" if encoder else "lsea_siso",
        fmu=FMU,
        truth=dict(gen.TRUTH),
        parameters=parameters,
        experiments=[experiment],
        noise=noise,
        start_values={"V_z": gen.V_Z},
        notes=NOTES,
    )


def self_check() -> None:
    """Print the problem and how the independent simulation compares with the FMU."""
    from tsid_fmu.fmu import FMUSession

    gen = _generator()
    problem = introduce(lambda: siso(encoder=True))
    data = problem.experiments[0].data
    t, f_m = data["time"].to_numpy(), data["F_m"].to_numpy()
    x_m, v_m, f_o = gen.simulate(t, f_m, problem.truth)
    band = np.abs(v_m) <= gen.V_Z
    print(f"stick band |v_m| <= V_z: {100 * band.mean():.0f} % of the samples")
    names = [*problem.truth, "fixedStepSize"]
    with FMUSession(FMU, ["F_m"], ["F_o", "x_m"], parameters=names) as fmu:
        fmu.simulate(t, f_m, {**problem.truth, **problem.start_values})  # warm-up
        for step in (1e-4, 2e-5, 1e-5, 1e-6):
            t1 = time.perf_counter()
            y = fmu.simulate(
                t, f_m, {**problem.truth, **problem.start_values, "fixedStepSize": step}
            )
            took = time.perf_counter() - t1
            rf, mf = rms_over_sigma(y[:, 0], f_o, problem.noise["F_o"])
            rx, mx = rms_over_sigma(y[:, 1], x_m, problem.noise["x_m"])
            print(
                f"FMU (fixedStepSize {step:.0e} s, {took:.2f} s) vs independent at the truth: "
                f"F_o RMS {rf:.2g} sigma (max {mf:.2g}); x_m RMS {rx:.2g} sigma (max {mx:.2g}), "
                f"i.e. {rx * problem.noise['x_m'] * 1e6:.2g} um RMS"
            )


if __name__ == "__main__":
    self_check()
