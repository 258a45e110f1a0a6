"""The SISO plant under three friction laws, simulated independently of the FMUs.

The laws are those of ``models/TSID/LSEA_SISO_Friction.mo`` (parameter ``friction``):

1. Coulomb: ``F_cm`` only (no viscous friction);
2. Coulomb + viscous (``F_vm``): the law of ``LSEA_SISO`` and of ``make_data.py``;
3. Stribeck + viscous: break-away force ``F_sm``, kinetic friction
   ``F_cm + (F_sm - F_cm) exp(-(v/V_s)^2)``.

Laws 1 and 2 are piecewise linear and are solved piecewise exactly by ``make_data.py``'s
``simulate`` (law 1 with ``F_vm = 0``). Law 3 is not linear in slip: it is solved here as
a hybrid system, one friction mode at a time (stick, break-away with the sign of ``F_mt``,
slip with the sign of ``v_m``), by SciPy's ``solve_ivp`` (RK45, rtol 1e-10) with the
mode's boundaries as terminal events (``v_m = +-V_z``, ``F_mt = +-F_sm``); after each
event the mode is the one eq. (3) gives a moment later (1e-10 s along the old mode).

Run:  python examples/lsea_siso/friction_laws.py   (prints how law 3 differs from law 2)
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # examples/_datagen.py
import make_data as base
from _datagen import load_cells, quantise, sample_times

#: Names of the laws, by the value of the model's ``friction`` parameter.
LAWS = {1: "Coulomb", 2: "Coulomb + viscous", 3: "Stribeck + viscous"}
#: True parameters per law: Table IV of the SISO paper; law 1 has no F_vm, law 3 adds
#: a break-away force F_sm and a Stribeck velocity V_s.
TRUTH: dict[int, dict[str, float]] = {
    1: {"F_cm": 88.5, "M_m": 4.3, "K_s": 8600.0, "B_s": 2.5},
    2: dict(base.TRUTH),
    3: {**base.TRUTH, "F_sm": 120.0, "V_s": 0.02},
}
STICK, BREAK, SLIP = 0, 1, 2
_NUDGE = 1e-10  # s: how far past an event the next mode is read


def _stribeck(
    t: np.ndarray, f_m: np.ndarray, p: dict[str, float], v_z: float
) -> tuple[np.ndarray, np.ndarray]:
    """Law 3 from rest, ``f_m[k]`` held over ``[t[k], t[k+1])``: ``x_m, v_m`` at ``t``."""
    f_cm, f_vm, m_m, k_s, b_s = (p[k] for k in ("F_cm", "F_vm", "M_m", "K_s", "B_s"))
    f_sm, v_s, c = p["F_sm"], p["V_s"], p["F_vm"] + p["B_s"]

    def mode_of(s: np.ndarray, fm: float) -> tuple[int, float]:
        x, v = s
        f_mt = fm - c * v - k_s * x
        if abs(v) <= v_z:
            return (STICK, 0.0) if abs(f_mt) <= f_sm else (BREAK, float(np.sign(f_mt)))
        return SLIP, float(np.sign(v))

    def rhs(_t: float, s: np.ndarray, fm: float, mode: int, sgn: float) -> list[float]:
        x, v = s
        if mode == STICK:
            return [v, 0.0]
        f_mt = fm - c * v - k_s * x
        if mode == BREAK:
            return [v, (f_mt - sgn * f_sm) / m_m]
        kinetic = f_cm + (f_sm - f_cm) * np.exp(-((v / v_s) ** 2))
        return [v, (f_mt - sgn * kinetic) / m_m]

    def events(fm: float, mode: int, sgn: float) -> list:
        def ev(g):
            g.terminal = True
            return g

        f_mt = lambda s: fm - c * s[1] - k_s * s[0]  # noqa: E731
        if mode == STICK:
            return [ev(lambda _t, s, *_: abs(f_mt(s)) - f_sm)]
        if mode == BREAK:
            return [
                ev(lambda _t, s, *_: abs(s[1]) - v_z),
                ev(lambda _t, s, *_: abs(f_mt(s)) - f_sm),
            ]
        return [ev(lambda _t, s, *_: sgn * s[1] - v_z)]

    # note: f_vm and b_s enter through c only
    del f_vm, b_s
    out = np.zeros((len(t), 2))
    state = np.zeros(2)
    change = np.flatnonzero(np.diff(f_m[:-1])) + 1
    bounds = np.concatenate([[0], change, [len(t) - 1]])
    for a, b in itertools.pairwise(bounds):
        fm, t0, t1 = float(f_m[a]), float(t[a]), float(t[b])
        while t0 < t1:
            mode, sgn = mode_of(state, fm)
            keep = (t > t0) & (t <= t1)
            sol = solve_ivp(
                rhs, (t0, t1), state, args=(fm, mode, sgn), t_eval=t[keep],
                events=events(fm, mode, sgn), rtol=1e-10, atol=1e-13, max_step=5e-3,
            )  # fmt: skip
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed at t = {t0}: {sol.message}")
            ys = np.reshape(sol.y, (2, -1))
            out[np.flatnonzero(keep)[: ys.shape[1]]] = ys.T
            if sol.status == 0:
                state, t0 = ys[:, -1], t1
                continue
            te = float(next(e[0] for e in sol.t_events if len(e)))
            se = next(y[0] for y in sol.y_events if len(y))
            if te <= t0 + 1e-15:  # an event at the start: step the mode by the nudge
                te = t0
            nudge = min(_NUDGE, t1 - te)
            state = se + nudge * np.asarray(rhs(te, se, fm, mode, sgn))
            t0 = te + nudge
    return out[:, 0], out[:, 1]


def simulate(
    t: np.ndarray, f_m: np.ndarray, law: int, params: dict[str, float], v_z: float = base.V_Z
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Solve the plant with friction law ``law`` (1, 2 or 3) from rest.

    Parameters
    ----------
    t, f_m : numpy.ndarray
        Sample instants (s) and the motor force (N) held over each sample interval.
    law : int
        1 Coulomb, 2 Coulomb + viscous, 3 Stribeck + viscous.
    params : dict
        ``F_cm, M_m, K_s, B_s`` and, by law, ``F_vm`` (2, 3), ``F_sm``, ``V_s`` (3).
    v_z : float
        Stick band (m/s).

    Returns
    -------
    x_m, v_m, F_o : numpy.ndarray
        Nut position, velocity and spring force ``B_s v_m + K_s x_m`` at ``t``.
    """
    if law in (1, 2):
        p = {**params, "F_vm": params["F_vm"] if law == 2 else 0.0}
        return base.simulate(t, f_m, p, v_z=v_z)
    if law != 3:
        raise ValueError(f"friction law {law} is not 1, 2 or 3")
    x_m, v_m = _stribeck(t, np.asarray(f_m, dtype=float), params, v_z)
    return x_m, v_m, params["B_s"] * v_m + params["K_s"] * x_m


def make_data(law: int, seed: int, params: dict[str, float] | None = None) -> pd.DataFrame:
    """The rig's data (as ``make_data.make_data``) from friction law ``law``.

    Parameters
    ----------
    law : int
        The true friction law (1, 2 or 3).
    seed : int
        Seed of the sensor noise.
    params : dict, optional
        The true parameters (default ``TRUTH[law]``).

    Returns
    -------
    pandas.DataFrame
        Columns ``time, F_m, F_of, F_or, x_m``.
    """
    t = sample_times()
    f_m = base.motor_force(t)
    x_m, _, f_o = simulate(t, f_m, law, TRUTH[law] if params is None else params)
    rng = np.random.default_rng(seed)
    front, rear = load_cells(f_o, base.NOISE["F_of"], base.NOISE["F_or"], rng)
    encoder = quantise(x_m, base.ENCODER_STEP)
    return pd.DataFrame({"time": t, "F_m": f_m, "F_of": front, "F_or": rear, "x_m": encoder})


if __name__ == "__main__":
    times = sample_times()
    force = base.motor_force(times)
    ref = simulate(times, force, 2, TRUTH[2])
    for k in (1, 3):
        y = simulate(times, force, k, TRUTH[k])
        print(
            f"law {k} ({LAWS[k]}) vs law 2: max |dF_o| {np.max(np.abs(y[2] - ref[2])):.1f} N, "
            f"max |dx_m| {np.max(np.abs(y[0] - ref[0])) * 1e6:.0f} um"
        )
    nested = simulate(times, force, 3, {**TRUTH[2], "F_sm": TRUTH[2]["F_cm"], "V_s": 0.02})
    print(f"law 3 with F_sm = F_cm vs law 2: max |dF_o| {np.max(np.abs(nested[2] - ref[2])):.2e} N")
