"""Make the three experiments of the MISO example from the LSEA_MISO FMU.

As in the MISO paper (Section 4.2), each input first acts alone, then both together:

- ``force_only.csv``: motor force, a sequence of 1-5 Hz sinusoids of +/-150 N, with
  the stage locked (x_o = v_o = a_o = 0);
- ``motion_only.csv``: the stage moves the output link along a walking-like
  trajectory of a few centimetres (hip-like, ~1 Hz with a harmonic), motor force off;
- ``combined.csv``: both at once (for the superposition check).

10 s at 1 kHz; 1 % Gaussian noise (of each experiment's peak force) on the load-cell
force, split into the front/rear compression-only cells: F_o = F_of - F_or.

The known parameters are the FMU defaults except K_s = 5000 N/m: with the default
5e4 N/m the spring resonance (53 Hz) lies so far above the 1-5 Hz excitation that the
dynamics show at about 1 % of the force, the size of the noise.

Run:  python examples/lsea_miso/make_data.py   (writes the CSV files beside this file)
"""

from pathlib import Path

import numpy as np
import pandas as pd

from tsid_fmu.fmu import FMUSession

HERE = Path(__file__).resolve().parent
FMU = HERE.parents[1] / "fmus" / "LSEA_MISO.fmu"
TRUTH = {"m1": 0.45, "m2": 0.2, "K_s": 5000.0, "C_d": 5.0, "C_1": 20.0, "C_2": 2.0}
INPUTS = ["F_m", "x_o", "v_o", "a_o"]


def motor_force(t: np.ndarray) -> np.ndarray:
    """1, 2, 3, 4, 5 Hz sinusoids of 150 N, two seconds each (phase-continuous)."""
    freq = np.minimum(1 + (t // 2.0), 5.0)
    phase = 2 * np.pi * np.cumsum(freq) * (t[1] - t[0])
    return 150.0 * np.sin(phase)


def stage_motion(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Walking-like stage position (m), velocity and acceleration: 1 Hz plus harmonics."""
    parts = [(0.025, 1.0, 0.0), (0.008, 2.0, 0.6), (0.003, 3.0, 1.9)]
    x = sum(a * np.sin(2 * np.pi * f * t + p) for a, f, p in parts)
    v = sum(a * 2 * np.pi * f * np.cos(2 * np.pi * f * t + p) for a, f, p in parts)
    acc = sum(-a * (2 * np.pi * f) ** 2 * np.sin(2 * np.pi * f * t + p) for a, f, p in parts)
    return x, v, acc


def main() -> None:
    t = np.round(np.arange(10001) * 1e-3, 9)
    zero = np.zeros_like(t)
    f_m = motor_force(t)
    x_o, v_o, a_o = stage_motion(t)
    experiments = {
        "force_only": (f_m, zero, zero, zero),
        "motion_only": (zero, x_o, v_o, a_o),
        "combined": (f_m, x_o, v_o, a_o),
    }
    rng = np.random.default_rng(7)
    with FMUSession(FMU, inputs=INPUTS, outputs=["F_o"], parameters=list(TRUTH)) as fmu:
        for name, cols in experiments.items():
            u = np.column_stack(cols)
            f_o = fmu.simulate(t, u, TRUTH)[:, 0]
            noisy = f_o + rng.normal(0.0, 0.01 * np.max(np.abs(f_o)), f_o.shape)
            frame = pd.DataFrame(dict(zip(["time", *INPUTS], [t, *cols], strict=True)))
            frame["F_of"] = np.maximum(noisy, 0.0)
            frame["F_or"] = np.maximum(-noisy, 0.0)
            frame.to_csv(HERE / f"{name}.csv", index=False, float_format="%.7g")
            print(f"{name}: output range {np.ptp(f_o):.1f} N")


if __name__ == "__main__":
    main()
