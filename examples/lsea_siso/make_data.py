"""Make the measured data of the SISO example from the LSEA_SISO FMU.

The plant is simulated at the SISO paper's Table IV values (K_s in N/m) driven by a
sequence of square waves of several amplitudes (the paper's Fig. 6a), 10 s at 1 kHz.
1 % Gaussian noise (of each signal's peak) is added to the output force, which is then
split into the two compression-only load cells of the test bed: F_o = F_of - F_or.

The motor encoder's nut position x_m is recorded as well (with the same 1 % noise):
in the force F_o the linear dynamics depend only on the ratios M_m/K_s, F_vm/K_s and
B_s/K_s (scaling all four together changes F_o by less than the noise, see
tests/test_examples.py); only the dry-friction stick threshold carries the scale, so
the study uses the encoder to pin down K_s.

Run:  python examples/lsea_siso/make_data.py   (writes measured.csv beside this file)
"""

from pathlib import Path

import numpy as np
import pandas as pd

from tsid_fmu.fmu import FMUSession

HERE = Path(__file__).resolve().parent
FMU = HERE.parents[1] / "fmus" / "LSEA_SISO.fmu"
TRUTH = {"F_cm": 88.5, "F_vm": 51.5, "M_m": 4.3, "K_s": 8600.0, "B_s": 2.5}


def motor_force(t: np.ndarray) -> np.ndarray:
    """Square waves of 1 Hz whose amplitude changes every 2 s (N)."""
    amplitudes = np.array([150.0, 300.0, 110.0, 250.0, 200.0])
    segment = np.minimum((t // 2.0).astype(int), len(amplitudes) - 1)
    return amplitudes[segment] * np.where((t % 1.0) < 0.5, 1.0, -1.0)


def main() -> None:
    t = np.round(np.arange(0, 10000 + 1) * 1e-3, 9)
    f_m = motor_force(t)
    with FMUSession(FMU, inputs=["F_m"], outputs=["F_o", "x_m"], parameters=list(TRUTH)) as fmu:
        f_o, x_m = fmu.simulate(t, f_m[:, None], TRUTH).T
    rng = np.random.default_rng(2024)
    noisy = f_o + rng.normal(0.0, 0.01 * np.max(np.abs(f_o)), f_o.shape)
    x_m = x_m + rng.normal(0.0, 0.01 * np.max(np.abs(x_m)), x_m.shape)
    frame = pd.DataFrame(
        {
            "time": t,
            "F_m": f_m,
            "F_of": np.maximum(noisy, 0.0),  # front load cell: compression only
            "F_or": np.maximum(-noisy, 0.0),  # rear load cell: compression only
            "x_m": x_m,  # motor encoder: nut position (m)
        }
    )
    frame.to_csv(HERE / "measured.csv", index=False, float_format="%.6g")
    print(f"wrote {HERE / 'measured.csv'} ({len(frame)} rows); truth {TRUTH}")


if __name__ == "__main__":
    main()
