"""Make the measured data of the SISO example with an independent simulator.

The data are *not* made with the FMU that the example identifies: the equations of
``models/TSID/LSEA_SISO.mo`` (eqs. (3), (4), (6) of the SISO paper) are solved here
piecewise exactly, the way a real rig would produce them:

- the motor force command ``F_m`` comes from a 1 kHz controller and is held constant
  (zero-order hold) over each 1 ms sample; the command is the paper's sequence of
  square waves of several amplitudes (Fig. 6a);
- the measured signals are the continuous plant outputs sampled at ``t_k = k * 1 ms``:
  two compression-only load cells, front ``F_of = max(F_o, 0) + noise`` and rear
  ``F_or = max(-F_o, 0) + noise`` (white Gaussian noise of one sigma per cell, the same
  in every run: 4 N, so that ``F_o = F_of - F_or`` has 5.7 N, about 1 % of its 549 N
  peak); and the motor encoder ``x_m``, quantised to 1 um and otherwise exact.

Solution method.  With the dry friction of eq. (3) the plant is piecewise linear: in
each friction mode (stick: ``der(v_m) = 0``; positive friction ``-F_cm``; negative
friction ``+F_cm``) and over one hold interval it is a linear ODE in ``z = (x_m, v_m,
F_m, 1)``, solved exactly by the matrix exponential.  The mode changes where the
trajectory crosses one of the boundaries of eq. (3) (``v_m = +-V_z`` and
``F_mt = +-F_cm``); the crossings are located by bisection on the exact solution to a
bracket of ``EVENT_TOL`` = 1e-12 s, and the solution continues from the far end of the
bracket with the mode that eq. (3) gives there (as in the Modelica model, ``V_z`` =
1 mm/s and a sticking mass keeps its velocity inside that band).  Within one hold
interval each boundary function is a damped sinusoid plus a constant whose extrema are
~70 ms apart, so a crossing and re-crossing inside one 1 ms interval is caught by
locating the extremum.  ``python make_data.py --check`` shows that halving the event
tolerance, or making it 100 times coarser, moves the outputs by far less than the noise,
and redoes every hold interval with a mode change by brute force (RK45 at h/2000).

Run:  python examples/lsea_siso/make_data.py   (writes measured.csv beside this file)
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp
from scipy.linalg import expm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/_datagen.py
from _datagen import command_line, load_cells, quantise, sample_times

HERE = Path(__file__).resolve().parent
#: Table IV of the SISO paper (K_s in N/m).
TRUTH: dict[str, float] = {"F_cm": 88.5, "F_vm": 51.5, "M_m": 4.3, "K_s": 8600.0, "B_s": 2.5}
#: Stick band of eq. (3), as in the Modelica model (m/s).
V_Z = 0.001
#: Encoder resolution of the motor position x_m (m).
ENCODER_STEP = 1e-6
#: One sigma per sensor: each load cell (N); the encoder's quantisation as a sigma (m).
NOISE: dict[str, float] = {"F_of": 4.0, "F_or": 4.0, "x_m": ENCODER_STEP / 12**0.5}
#: Bracket (s) to which mode changes are located.
EVENT_TOL = 1e-12

STICK, PLUS, MINUS = 0, 1, 2  # friction modes: stuck, friction -F_cm, friction +F_cm


def motor_force(t: np.ndarray) -> np.ndarray:
    """Square waves of 1 Hz whose amplitude changes every 2 s (N), one value per sample."""
    amplitudes = np.array([150.0, 300.0, 110.0, 250.0, 200.0])
    segment = np.minimum((t // 2.0).astype(int), len(amplitudes) - 1)
    return amplitudes[segment] * np.where((t % 1.0) < 0.5, 1.0, -1.0)


class _Plant:
    """The piecewise-linear LSEA_SISO plant: modes, flows and boundary functions."""

    def __init__(self, params: dict[str, float], v_z: float) -> None:
        f_cm, f_vm, m_m, k_s, b_s = (params[k] for k in ("F_cm", "F_vm", "M_m", "K_s", "B_s"))
        c = f_vm + b_s
        self.f_cm, self.c, self.k_s, self.v_z = f_cm, c, k_s, v_z
        self.a: dict[int, np.ndarray] = {}
        for mode, friction in ((STICK, 0.0), (PLUS, -f_cm), (MINUS, f_cm)):
            a = np.zeros((4, 4))
            a[0, 1] = 1.0  # der(x_m) = v_m; F_m and 1 are constant
            if mode != STICK:  # M_m der(v_m) = F_mt + F_dm
                a[1] = np.array([-k_s, -c, 1.0, friction]) / m_m
            self.a[mode] = a
        # boundary functions g = w . z: v -+ V_z, F_mt -+ F_cm
        self.w_v = np.array([[0.0, 1.0, 0.0, -v_z], [0.0, 1.0, 0.0, v_z]])
        self.w_f = np.array([[-k_s, -c, 1.0, -f_cm], [-k_s, -c, 1.0, f_cm]])
        # exact flows: stick is nilpotent (expm(A t) = I + A t); the friction modes are
        # diagonalisable (a damped pair and a double zero), expm(A t) = V e^(L t) V^-1
        # (scipy's expm where the pair is (nearly) repeated: critical damping)
        self._eig: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray] | None] = {}
        for mode in (PLUS, MINUS):
            lam, vec = np.linalg.eig(self.a[mode])
            ok = np.linalg.cond(vec) < 1e6
            self._eig[mode] = (lam, vec, np.linalg.inv(vec)) if ok else None
        self._cache: dict[tuple[int, float], np.ndarray] = {}

    def flow(self, mode: int, tau: float) -> np.ndarray:
        """Transition matrix ``expm(A tau)`` of ``mode`` (cached for repeated steps)."""
        key = (mode, round(tau, 15))
        e = self._cache.get(key)
        if e is None:
            eig = self._eig.get(mode)
            if mode == STICK:
                e = np.eye(4) + self.a[STICK] * tau
            elif eig is None:
                e = expm(self.a[mode] * tau)
            else:
                lam, vec, inv = eig
                e = ((vec * np.exp(lam * tau)) @ inv).real
            if len(self._cache) < 64:
                self._cache[key] = e
        return e

    def mode(self, z: np.ndarray) -> int:
        """Friction mode of eq. (3) at state ``z``."""
        v = z[1]
        f_mt = z[2] - self.c * v - self.k_s * z[0]
        if abs(v) <= self.v_z:
            if abs(f_mt) <= self.f_cm:
                return STICK
            return PLUS if f_mt > 0 else MINUS
        return PLUS if v > 0 else MINUS

    def boundaries(self, mode: int, z: np.ndarray) -> np.ndarray:
        """Boundary functions (rows ``w``) whose crossing can change the mode at ``z``."""
        if mode == STICK:
            return self.w_f
        if abs(z[1]) <= self.v_z:
            return np.vstack([self.w_v, self.w_f])
        return self.w_v


def _bisect(g: Callable[[float], float], lo: float, hi: float, tol: float) -> float:
    """Shrink ``[lo, hi]`` (``g`` changes sign on it) to ``tol``; return the far end."""
    g_lo = g(lo)
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        if (g(mid) >= 0.0) == (g_lo >= 0.0):
            lo = mid
        else:
            hi = mid
    return hi


def _first_crossing(
    plant: _Plant, mode: int, z0: np.ndarray, z1: np.ndarray, span: float, tol: float
) -> float | None:
    """Earliest time in ``(0, span]`` where a boundary of ``mode`` is crossed, or None.

    Returns the far end of a bracket of width ``tol`` around the crossing.
    """
    a = plant.a[mode]
    best = None
    for w in plant.boundaries(mode, z0):
        wa = w @ a
        g0, g1 = float(w @ z0), float(w @ z1)
        d0, d1 = float(wa @ z0), float(wa @ z1)
        end = span
        if (g0 >= 0.0) == (g1 >= 0.0):
            # no net sign change: only a crossing and re-crossing around an extremum
            if d0 * d1 >= 0.0 or abs(g0) > abs(d0) * span:
                continue
            t_ext = _bisect(lambda s, wa=wa: float(wa @ plant.flow(mode, s) @ z0), 0.0, span, tol)
            if (float(w @ plant.flow(mode, t_ext) @ z0) >= 0.0) == (g0 >= 0.0):
                continue
            end = t_ext
        if best is not None and end > best:
            end = best  # only an earlier crossing matters
            if (float(w @ plant.flow(mode, end) @ z0) >= 0.0) == (g0 >= 0.0):
                continue
        best = _bisect(lambda s, w=w: float(w @ plant.flow(mode, s) @ z0), 0.0, end, tol)
    return best


def _hold_interval(
    plant: _Plant, z: np.ndarray, h: float, tol: float, max_events: int = 50
) -> tuple[np.ndarray, int]:
    """Advance the state ``z`` (input already in ``z[2]``) over one hold interval ``h``."""
    done, events = 0.0, 0
    while True:
        mode = plant.mode(z)
        span = h - done
        z_end = plant.flow(mode, span) @ z
        hit = None if events >= max_events else _first_crossing(plant, mode, z, z_end, span, tol)
        if hit is None or hit >= span:
            return z_end, events
        z = plant.flow(mode, hit) @ z
        done += hit
        events += 1


def simulate(
    t: np.ndarray,
    f_m: np.ndarray,
    params: dict[str, float],
    *,
    v_z: float = V_Z,
    tol: float = EVENT_TOL,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Solve LSEA_SISO from rest for a command held over each sample interval.

    Parameters
    ----------
    t : numpy.ndarray
        Sample instants (s), strictly increasing, starting at the initial time.
    f_m : numpy.ndarray
        Motor force (N); ``f_m[k]`` is held over ``[t[k], t[k+1])``.
    params : dict
        ``F_cm, F_vm, M_m, K_s, B_s`` (SI units).
    v_z : float
        Stick band of eq. (3) (m/s).
    tol : float
        Width (s) of the bracket to which each mode change is located.

    Returns
    -------
    x_m, v_m, F_o : numpy.ndarray
        Nut position (m), velocity (m/s) and spring force ``B_s v_m + K_s x_m`` (N) at
        ``t`` (continuous outputs, sampled).
    """
    plant = _Plant(params, v_z)
    states = np.zeros((len(t), 2))
    z = np.array([0.0, 0.0, 0.0, 1.0])
    for k in range(len(t) - 1):
        z[2] = f_m[k]
        z, _ = _hold_interval(plant, z, float(t[k + 1] - t[k]), tol)
        states[k + 1] = z[:2]
    x_m, v_m = states.T
    return x_m, v_m, params["B_s"] * v_m + params["K_s"] * x_m


def make_data(seed: int = 2024) -> pd.DataFrame:
    """Return the measured data: 10 s at 1 kHz, as the rig logs them.

    Parameters
    ----------
    seed : int
        Seed of the sensor noise (the command is always the same).

    Returns
    -------
    pandas.DataFrame
        Columns ``time, F_m, F_of, F_or, x_m``.
    """
    t = sample_times()
    f_m = motor_force(t)
    x_m, _, f_o = simulate(t, f_m, TRUTH)
    rng = np.random.default_rng(seed)
    front, rear = load_cells(f_o, NOISE["F_of"], NOISE["F_or"], rng)
    encoder = quantise(x_m, ENCODER_STEP)
    return pd.DataFrame({"time": t, "F_m": f_m, "F_of": front, "F_or": rear, "x_m": encoder})


def _brute_force_step(z: np.ndarray, h: float, params: dict[str, float]) -> np.ndarray:
    """One hold interval by plain RK45 at tiny steps (no event location), for the check."""
    f_cm, f_vm, m_m, k_s, b_s = (params[k] for k in ("F_cm", "F_vm", "M_m", "K_s", "B_s"))

    def rhs(_t: float, s: np.ndarray) -> list[float]:
        x, v = s
        f_mt = z[2] - (f_vm + b_s) * v - k_s * x
        if abs(v) <= V_Z and abs(f_mt) <= f_cm:
            f_dm = -f_mt
        elif abs(v) <= V_Z:
            f_dm = -f_cm * np.sign(f_mt)
        else:
            f_dm = -f_cm * np.sign(v)
        return [v, (f_mt + f_dm) / m_m]

    sol = solve_ivp(rhs, (0.0, h), z[:2], rtol=1e-12, atol=1e-14, max_step=h / 2000)
    return sol.y[:, -1]


def check_tolerance() -> None:
    """Print how much the outputs move with the event tolerance, and a brute-force check."""
    t = sample_times()
    f_m = motor_force(t)
    base = simulate(t, f_m, TRUTH)
    for tol in (EVENT_TOL / 2, EVENT_TOL * 100):
        other = simulate(t, f_m, TRUTH, tol=tol)
        d_x = np.max(np.abs(other[0] - base[0]))
        d_f = np.max(np.abs(other[2] - base[2]))
        print(
            f"event tolerance {tol:.1e} s vs {EVENT_TOL:.0e} s: max |dx_m| {d_x:.2e} m "
            f"({d_x / ENCODER_STEP:.1e} encoder steps), max |dF_o| {d_f:.2e} N "
            f"({d_f / NOISE['F_of']:.1e} sigma of one cell)"
        )
    # the hold intervals in which the mode changes, each redone by brute force
    plant = _Plant(TRUTH, V_Z)
    worst = np.zeros(2)
    n_events = 0
    for k in range(len(t) - 1):
        z = np.array([base[0][k], base[1][k], f_m[k], 1.0])
        z_end, events = _hold_interval(plant, z.copy(), t[k + 1] - t[k], EVENT_TOL)
        if events:
            n_events += events
            ref = _brute_force_step(z, t[k + 1] - t[k], TRUTH)
            worst = np.maximum(worst, np.abs(ref - z_end[:2]))
    print(
        f"{n_events} mode changes; RK45 at h/2000 steps over each interval that has one: "
        f"max |dx_m| {worst[0]:.1e} m, max |dv_m| {worst[1]:.1e} m/s"
    )


def files(seed: int = 2024) -> dict[str, pd.DataFrame]:
    """The data by CSV file name: ``measured``."""
    return {"measured": make_data(seed)}


if __name__ == "__main__":
    command_line(
        __doc__, seed=2024, make=files, folder=HERE, truth=TRUTH, noise=NOISE, check=check_tolerance
    )
