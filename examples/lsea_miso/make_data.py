"""Make the three experiments of the MISO example with an independent simulator.

The data are *not* made with the FMU that the example identifies: the equations of
``models/TSID/LSEA_MISO.mo`` (eqs. (1)-(2) of the MISO paper) are solved here, with the
conventions of the real rig:

- the motor force command ``F_m`` comes from a 1 kHz controller and is held constant
  (zero-order hold) over each 1 ms sample: a sequence of 1-5 Hz sinusoids of 150 N;
- the position-controlled stage moves the output block along a smooth walking-like
  trajectory (hip-like, ~1 Hz with two harmonics, a few centimetres) that starts from
  rest: the sum of sines is multiplied by a quintic ramp-in window over the first
  second, so that ``x_o``, ``v_o`` and ``a_o`` are 0 at t = 0 and continuous.  The
  plant sees this motion *continuously* (evaluated inside the integrator), not held;
- the logged signals are ``time, F_m, x_o, F_of, F_or``: the stage encoder ``x_o``
  (quantised to 1 um) and the two compression-only load cells, front
  ``F_of = max(F_o, 0) + noise`` and rear ``F_or = max(-F_o, 0) + noise``, with white
  Gaussian noise of one sigma per cell, the same in all three experiments.  The stage's
  velocity and acceleration are *not* logged (a position-controlled stage logs its
  position only): a tool must differentiate ``x_o``.

The experiments, as in the MISO paper (Section 4.2): ``force_only`` (stage locked),
``motion_only`` (motor force off), ``combined`` (both, for the superposition check).

Solution method.  The plant is linear, so its response is the sum of the response to
the held force, solved exactly per hold interval by the matrix exponential, and the
response to the stage motion, integrated by ``solve_ivp`` (DOP853, ``RTOL`` = 1e-11)
with the exact, smooth ``x_o(t), v_o(t)`` inside the right-hand side (both from rest).
``python make_data.py --check`` shows that a ten times tighter tolerance moves the
output by far less than the noise.

The known parameters are the FMU defaults except K_s = 5000 N/m: with the default
5e4 N/m the spring resonance (53 Hz) lies so far above the 1-5 Hz excitation that the
dynamics show at about 1 % of the force, the size of the noise.

Run:  python examples/lsea_miso/make_data.py   (writes the CSV files beside this file)
"""

import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/_datagen.py
from _datagen import command_line, load_cells, quantise, sample_times, zoh_response

HERE = Path(__file__).resolve().parent
TRUTH: dict[str, float] = {
    "m1": 0.45,
    "m2": 0.2,
    "K_s": 5000.0,
    "C_d": 5.0,
    "C_1": 20.0,
    "C_2": 2.0,
}
#: Stage encoder resolution (m).
ENCODER_STEP = 1e-6
#: One sigma per sensor: each load cell (N); the stage encoder's quantisation (m).
NOISE: dict[str, float] = {"F_of": 1.0, "F_or": 1.0, "x_o": ENCODER_STEP / 12**0.5}
#: Relative tolerance of the integration of the stage-driven response.
RTOL = 1e-11
EXPERIMENTS = ("force_only", "motion_only", "combined")


def motor_force(t: np.ndarray) -> np.ndarray:
    """1, 2, 3, 4, 5 Hz sinusoids of 150 N, two seconds each, one value per sample (N)."""
    freq = np.minimum(1 + (t // 2.0), 5.0)
    phase = 2 * np.pi * np.cumsum(freq) * (t[1] - t[0])
    return 150.0 * np.sin(phase)


class Stage:
    """Walking-like stage motion from rest: ``x_o(t) = w(t / ramp) * sum a sin(2 pi f t + p)``.

    ``w`` is the quintic smoothstep ``10 s^3 - 15 s^4 + 6 s^5`` (0 -> 1 with zero first
    and second derivatives at both ends), so ``x_o, v_o, a_o`` start at 0 and are
    continuous.

    Parameters
    ----------
    parts : sequence of (amplitude, frequency, phase)
        Sines in m, Hz and rad.
    ramp : float
        Duration of the ramp-in window (s).
    """

    def __init__(
        self,
        parts: tuple[tuple[float, float, float], ...] = (
            (0.025, 1.0, 0.0),
            (0.008, 2.0, 0.6),
            (0.003, 3.0, 1.9),
        ),
        ramp: float = 1.0,
    ) -> None:
        self.parts = tuple((a, 2 * math.pi * f, p) for a, f, p in parts)
        self.ramp = ramp

    def __call__(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the exact position (m), velocity (m/s) and acceleration (m/s2) at ``t``."""
        t = np.asarray(t, dtype=float)
        s = np.clip(t / self.ramp, 0.0, 1.0)
        inside = (t > 0) & (t < self.ramp)
        w = s**3 * (10 - 15 * s + 6 * s**2)
        dw = np.where(inside, 30 * s**2 * (1 - s) ** 2 / self.ramp, 0.0)
        ddw = np.where(inside, 60 * s * (1 - s) * (1 - 2 * s) / self.ramp**2, 0.0)
        y = dy = ddy = np.zeros_like(t)
        for amp, om, phase in self.parts:
            y = y + amp * np.sin(om * t + phase)
            dy = dy + amp * om * np.cos(om * t + phase)
            ddy = ddy - amp * om**2 * np.sin(om * t + phase)
        return w * y, dw * y + w * dy, ddw * y + 2 * dw * dy + w * ddy

    def position_velocity(self, t: float) -> tuple[float, float]:
        """Return ``x_o(t), v_o(t)`` for one time (fast, for the integrator)."""
        y = dy = 0.0
        for amp, om, phase in self.parts:
            y += amp * math.sin(om * t + phase)
            dy += amp * om * math.cos(om * t + phase)
        if t >= self.ramp:
            return y, dy
        s = max(t / self.ramp, 0.0)
        w = s**3 * (10 - 15 * s + 6 * s**2)
        dw = 30 * s**2 * (1 - s) ** 2 / self.ramp
        return w * y, dw * y + w * dy


def stage_motion(t: np.ndarray, stage: Stage | None = None) -> tuple[np.ndarray, ...]:
    """Exact ``x_o, v_o, a_o`` of ``stage`` (default: the example's) at ``t``, for diagnostics."""
    return (stage or Stage())(t)


def _force_response(t: np.ndarray, f_m: np.ndarray, p: dict[str, float]) -> np.ndarray:
    """States ``(x, v)`` at ``t`` for the held force alone (stage at rest), exact ZOH."""
    m1, k_s, c_d, c_1 = p["m1"], p["K_s"], p["C_d"], p["C_1"]
    a = np.array([[0.0, 1.0, 0.0], [-k_s / m1, -(c_d + c_1) / m1, 1.0 / m1], [0.0, 0.0, 0.0]])
    return zoh_response(a, t, f_m)


def _stage_response(
    t: np.ndarray, stage: Stage, p: dict[str, float], rtol: float = RTOL
) -> np.ndarray:
    """States ``(x, v)`` at ``t`` for the continuous stage motion alone (no motor force)."""
    m1, k_s, c_d, c_1 = p["m1"], p["K_s"], p["C_d"], p["C_1"]

    def rhs(time_: float, s: np.ndarray) -> list[float]:
        x_o, v_o = stage.position_velocity(time_)
        return [s[1], (-k_s * (s[0] - x_o) - c_d * (s[1] - v_o) - c_1 * s[1]) / m1]

    sol = solve_ivp(
        rhs,
        (t[0], t[-1]),
        [0.0, 0.0],
        method="DOP853",
        t_eval=t,
        rtol=rtol,
        atol=[1e-9 * rtol, 1e-7 * rtol],
    )
    if not sol.success:
        raise RuntimeError(f"stage response: {sol.message}")
    return sol.y.T


def simulate(
    t: np.ndarray,
    f_m_held: np.ndarray,
    stage: Stage | None,
    params: dict[str, float],
    *,
    rtol: float = RTOL,
) -> np.ndarray:
    """Solve LSEA_MISO from rest and return the output force ``F_o`` at ``t``.

    Parameters
    ----------
    t : numpy.ndarray
        Sample instants (s), strictly increasing, starting at the initial time.
    f_m_held : numpy.ndarray
        Motor force (N); ``f_m_held[k]`` is held over ``[t[k], t[k+1])``.
    stage : Stage or None
        Continuous stage motion (evaluated exactly inside the integrator); ``None``
        for a locked stage.
    params : dict
        ``m1, m2, K_s, C_d, C_1, C_2`` (SI units).
    rtol : float
        Relative tolerance of the stage-driven part.

    Returns
    -------
    numpy.ndarray
        ``F_o = K_s (x - x_o) + C_d (v - v_o) - C_2 v_o - m2 a_o`` at ``t`` (N), with
        the stage motion taken at the sample instants themselves.
    """
    states = _force_response(t, f_m_held, params)
    if stage is None:
        x_o = v_o = a_o = np.zeros_like(t)
    else:
        states = states + _stage_response(t, stage, params, rtol)
        x_o, v_o, a_o = stage(t)
    x, v = states.T
    p = params
    return p["K_s"] * (x - x_o) + p["C_d"] * (v - v_o) - p["C_2"] * v_o - p["m2"] * a_o


def experiment_inputs(name: str, t: np.ndarray) -> tuple[np.ndarray, Stage | None]:
    """Held motor force and stage motion of experiment ``name``."""
    force = motor_force(t) if name in ("force_only", "combined") else np.zeros_like(t)
    stage = Stage() if name in ("motion_only", "combined") else None
    return force, stage


def make_data(seed: int = 7, truth: dict[str, float] | None = None) -> dict[str, pd.DataFrame]:
    """Return the three experiments, 10 s at 1 kHz each, as the rig logs them.

    Parameters
    ----------
    seed : int
        Seed of the sensor noise (the commands are always the same).
    truth : dict, optional
        The true parameters (default :data:`TRUTH`); ``m2 = C_2 = 0`` gives the one-mass
        load side (``LSEA_MISO_OneMass``), whose load cells carry the spring force.

    Returns
    -------
    dict of str to pandas.DataFrame
        ``force_only``, ``motion_only``, ``combined``; columns
        ``time, F_m, x_o, F_of, F_or``.
    """
    t = sample_times()
    rng = np.random.default_rng(seed)
    frames = {}
    for name in EXPERIMENTS:
        f_m, stage = experiment_inputs(name, t)
        f_o = simulate(t, f_m, stage, TRUTH if truth is None else truth)
        x_o = np.zeros_like(t) if stage is None else stage(t)[0]
        front, rear = load_cells(f_o, NOISE["F_of"], NOISE["F_or"], rng)
        frames[name] = pd.DataFrame(
            {
                "time": t,
                "F_m": f_m,
                "x_o": quantise(x_o, ENCODER_STEP),
                "F_of": front,
                "F_or": rear,
            }
        )
    return frames


def check_tolerance() -> None:
    """Print how much ``F_o`` moves with a ten times tighter tolerance."""
    t = sample_times()
    f_m, stage = experiment_inputs("combined", t)
    base = simulate(t, f_m, stage, TRUTH)
    fine = simulate(t, f_m, stage, TRUTH, rtol=RTOL / 10)
    d = np.max(np.abs(fine - base))
    print(
        f"combined: rtol {RTOL / 10:.0e} vs {RTOL:.0e}: max |dF_o| {d:.2e} N "
        f"({d / NOISE['F_of']:.1e} sigma of one cell); peak |F_o| {np.abs(base).max():.1f} N"
    )


if __name__ == "__main__":
    command_line(
        __doc__,
        seed=7,
        make=make_data,
        folder=HERE,
        truth=TRUTH,
        noise=NOISE,
        check=check_tolerance,
    )
