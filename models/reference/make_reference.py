"""Reference results of the plant models, from solutions independent of the FMUs.

For each model of ``models/TSID/`` this writes, in the layout of the FMI cross-check
rules (``<Model>/<Model>_in.csv``, ``<Model>_ref.csv``, ``<Model>_ref.opt``):

- ``_in.csv``: the input signal; linear interpolation between rows, a discontinuity as
  two rows with the same time (the value before and the value after);
- ``_ref.csv``: the reference outputs (and states) on the grid of ``StepSize``;
- ``_ref.opt``: ``StartTime``, ``StopTime``, ``StepSize`` and ``RelTol`` of the check.

The equations are written out here again, from the papers (they do not come from the
Modelica source or the FMU):

``LSEA_SISO``
    The measured square-wave force of ``examples/lsea_siso/measured.csv`` (its samples
    change at 0.5 s, 1.0 s, ...; here exact steps there), true parameters (the model's
    defaults, Table IV). Dry friction, eq. (3), as a hybrid system: the two conditions
    ``|v_m| <= V_z`` and ``|F_mt| <= F_cm`` are discrete states, changed only at
    events located by ``scipy.integrate.solve_ivp`` (DOP853, terminal events); the
    event functions have a hysteresis of 1e-12 m/s and 1e-9 N so that a condition that
    just changed does not trigger again at the same instant. Between events each mode
    is a smooth ODE; between input steps the input is constant.
``LSEA_MISO``
    The inputs of the combined experiment of ``examples/lsea_miso/make_data.py`` (its
    motor force and its stage motion with exact velocity and acceleration, from the
    functions that make the example data, not from the logged file), first 3 s at 1 kHz,
    model defaults (K_s = 5e4 N/m). The
    model is linear, so the solution for piecewise-linear inputs is exact: the matrix
    exponential of the system augmented with the input and its slope, over each
    sample interval.

Run:  python models/reference/make_reference.py   (rewrites the files beside it)
"""

from __future__ import annotations

import importlib.util
import itertools
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parents[1] / "examples"

#: Model defaults (the FMUs' parameter start values).
SISO_P = {"F_cm": 88.5, "F_vm": 51.5, "M_m": 4.3, "K_s": 8600.0, "B_s": 2.5, "V_z": 0.001}
MISO_P = {"m1": 0.45, "m2": 0.2, "K_s": 5e4, "C_d": 5.0, "C_1": 20.0, "C_2": 2.0}
SISO_OPT = {"StartTime": 0.0, "StopTime": 10.0, "StepSize": 2e-3, "RelTol": 1e-6}
MISO_OPT = {"StartTime": 0.0, "StopTime": 3.0, "StepSize": 1e-3, "RelTol": 1e-6}

# Hysteresis of the SISO event functions (see the module docstring).
_DV, _DF = 1e-12, 1e-9


def _write_csv(path: Path, names: list[str], columns: list[np.ndarray]) -> None:
    """Write a CSV in the cross-check convention (quoted header, time first)."""
    rows = np.column_stack(columns)
    with path.open("w", encoding="utf-8", newline="\n") as fh:
        fh.write(",".join(f'"{n}"' for n in names) + "\n")
        for row in rows:
            fh.write(",".join(f"{v:.10g}" for v in row) + "\n")


def _grid(opt: dict[str, float]) -> np.ndarray:
    """Return the output times StartTime, StartTime + StepSize, ..., StopTime."""
    n = round((opt["StopTime"] - opt["StartTime"]) / opt["StepSize"])
    return np.round(opt["StartTime"] + np.arange(n + 1) * opt["StepSize"], 12)


def _write_opt(path: Path, opt: dict[str, float]) -> None:
    path.write_text("".join(f"{k},{v!r}\n" for k, v in opt.items()), encoding="utf-8")


# ------------------------------------------------------------------------- SISO


def siso_input() -> tuple[np.ndarray, np.ndarray]:
    """Return the measured square-wave force as exact steps (time, value rows)."""
    data = np.genfromtxt(EXAMPLES / "lsea_siso" / "measured.csv", delimiter=",", names=True)
    t, f = data["time"], data["F_m"]
    rows = [(t[0], f[0])]
    for k in np.flatnonzero(np.diff(f)) + 1:
        rows += [(t[k], f[k - 1]), (t[k], f[k])]
    rows.append((t[-1], f[-1]))
    ti, fi = np.array(rows).T
    return np.round(ti, 9), fi


class SisoHybrid:
    """Eqs. (3), (4), (6) of the SISO paper with the friction case as a discrete state."""

    def __init__(self, p: dict[str, float]) -> None:
        self.p = p
        self.in_band = True  # |v_m| <= V_z
        self.holds = True  # |F_mt| <= F_cm
        self.events_seen = 0

    def f_mt(self, y: np.ndarray, force: float) -> float:
        """Return the total force on the nut block except dry friction, eq. (4)."""
        p = self.p
        return force - (p["F_vm"] + p["B_s"]) * y[1] - p["K_s"] * y[0]

    def rhs(self, _t: float, y: np.ndarray, force: float) -> list[float]:
        """Return the derivatives ``[v_m, a_m]`` in the current friction case."""
        p = self.p
        fmt = self.f_mt(y, force)
        if self.in_band and self.holds:
            fdm = -fmt  # stick
        elif self.in_band:
            fdm = -p["F_cm"] * np.sign(fmt)  # break-away
        else:
            fdm = -p["F_cm"] * np.sign(y[1])  # slip
        return [y[1], (fmt + fdm) / p["M_m"]]

    def events(self, force: float) -> list:
        """Return the terminal event functions that change a condition."""
        p = self.p
        if self.in_band:

            def band(_t, y, _f):
                return abs(y[1]) - p["V_z"] - _DV

            band.direction = 1.0  # leaves the band
        else:

            def band(_t, y, _f):
                return abs(y[1]) - p["V_z"] + _DV

            band.direction = -1.0  # enters the band
        if self.holds:

            def hold(_t, y, f):
                return abs(self.f_mt(y, f)) - p["F_cm"] - _DF

            hold.direction = 1.0
        else:

            def hold(_t, y, f):
                return abs(self.f_mt(y, f)) - p["F_cm"] + _DF

            hold.direction = -1.0
        band.terminal = hold.terminal = True
        return [band, hold]

    def update(self, y: np.ndarray, force: float) -> None:
        """Change the conditions that crossed their (hysteresis) thresholds."""
        p = self.p
        for _ in range(10):
            v, fmt = abs(y[1]), abs(self.f_mt(y, force))
            band = v <= p["V_z"] + _DV if self.in_band else v < p["V_z"] - _DV
            holds = fmt <= p["F_cm"] + _DF if self.holds else fmt < p["F_cm"] - _DF
            if (band, holds) == (self.in_band, self.holds):
                return
            self.in_band, self.holds = band, holds
        raise RuntimeError("friction conditions do not settle")


def siso_reference(opt: dict[str, float]) -> dict[str, np.ndarray]:
    """Solve the SISO plant for the step input; outputs on the ``StepSize`` grid."""
    p = SISO_P
    t_in, f_in = siso_input()
    grid = _grid(opt)
    plant = SisoHybrid(p)
    y = np.zeros(2)
    plant.in_band = abs(y[1]) <= p["V_z"]
    plant.holds = abs(plant.f_mt(y, f_in[0])) <= p["F_cm"]
    out = np.full((len(grid), 2), np.nan)
    # intervals of constant force: between distinct times of the input rows
    knots = np.unique(t_in)
    for a, b in itertools.pairwise(knots):
        force = f_in[np.flatnonzero(t_in == a)[-1]]  # value after a step at a
        plant.update(y, force)
        t = a
        while t < b:
            want = grid[(grid >= t) & (grid <= b)]
            sol = solve_ivp(
                plant.rhs,
                (t, b),
                y,
                args=(force,),
                method="DOP853",
                t_eval=want,
                dense_output=True,
                events=plant.events(force),
                rtol=1e-11,
                atol=1e-13,
                max_step=0.01,
            )
            if sol.status < 0:
                raise RuntimeError(sol.message)
            if len(sol.t):
                out[np.searchsorted(grid, sol.t)] = np.asarray(sol.y).T
            if sol.status == 1:  # a condition changed: flip it, then settle the other
                k = next(i for i, te in enumerate(sol.t_events) if len(te))
                t, y = float(sol.t_events[k][0]), np.array(sol.y_events[k][0])
                if k == 0:
                    plant.in_band = not plant.in_band
                else:
                    plant.holds = not plant.holds
                plant.update(y, force)
                plant.events_seen += 1
            else:
                t, y = b, sol.sol(b)
    if np.isnan(out).any():
        raise RuntimeError("reference grid not filled")
    x, v = out.T
    return {
        "time": grid,
        "F_o": p["B_s"] * v + p["K_s"] * x,
        "x_m": x,
        "v_m": v,
    }


# ------------------------------------------------------------------------- MISO

MISO_INPUTS = ["F_m", "x_o", "v_o", "a_o"]


def miso_input(opt: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """Return the combined experiment's inputs (1 kHz) up to StopTime."""
    spec = importlib.util.spec_from_file_location(
        "tsid_miso_make_data", EXAMPLES / "lsea_miso" / "make_data.py"
    )
    gen = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(gen)  # type: ignore[union-attr]
    t = np.round(np.arange(round(opt["StopTime"] * 1000) + 1) * 1e-3, 9)
    x_o, v_o, a_o = gen.stage_motion(t)[:3]
    return t, np.column_stack([gen.motor_force(t), x_o, v_o, a_o])


def miso_reference(opt: dict[str, float]) -> dict[str, np.ndarray]:
    """Exact solution of eqs. (1)-(2) for piecewise-linear inputs (first-order hold)."""
    p = MISO_P
    t_in, u_in = miso_input(opt)
    m1, k, cd, c1 = p["m1"], p["K_s"], p["C_d"], p["C_1"]
    a = np.array([[0.0, 1.0], [-k / m1, -(cd + c1) / m1]])
    b = np.array([[0.0, 0.0, 0.0, 0.0], [1 / m1, k / m1, cd / m1, 0.0]])
    # augmented state [x, v, u (4), du/dt (4)]: d/dt u = du, d/dt du = 0
    n = 2 + 4 + 4
    big = np.zeros((n, n))
    big[:2, :2], big[:2, 2:6], big[2:6, 6:] = a, b, np.eye(4)
    cache: dict[float, np.ndarray] = {}
    s = np.zeros(2)
    states = [s]
    for j in range(len(t_in) - 1):
        h = float(t_in[j + 1] - t_in[j])
        key = round(h, 12)
        if key not in cache:
            cache[key] = expm(big * h)
        slope = (u_in[j + 1] - u_in[j]) / h
        s = (cache[key] @ np.concatenate([s, u_in[j], slope]))[:2]
        states.append(s)
    x, v = np.array(states).T
    grid = _grid(opt)
    if not np.allclose(grid, t_in):
        raise RuntimeError("the MISO input grid must be the output grid")
    _f, xo, vo, ao = u_in.T
    f_o = k * (x - xo) + cd * (v - vo) - p["C_2"] * vo - p["m2"] * ao
    return {"time": grid, "F_o": f_o, "x": x, "v": v}


def main() -> None:
    """Write the reference files of both models beside this script."""
    for name, opt, ref, inputs in (
        ("LSEA_SISO", SISO_OPT, siso_reference, lambda o: siso_input()),
        ("LSEA_MISO", MISO_OPT, miso_reference, miso_input),
    ):
        folder = HERE / name
        folder.mkdir(exist_ok=True)
        t_in, u_in = inputs(opt)
        u_cols = [u_in] if u_in.ndim == 1 else list(u_in.T)
        in_names = ["F_m"] if u_in.ndim == 1 else MISO_INPUTS
        _write_csv(folder / f"{name}_in.csv", ["time", *in_names], [t_in, *u_cols])
        res = ref(opt)
        _write_csv(folder / f"{name}_ref.csv", list(res), list(res.values()))
        _write_opt(folder / f"{name}_ref.opt", opt)
        print(f"wrote {folder} ({len(res['time'])} reference rows)")


if __name__ == "__main__":
    main()
