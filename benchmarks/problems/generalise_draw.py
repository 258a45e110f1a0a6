"""Random draws shared by the generalisation benchmark's families (``generalise.py``).

A family (``generalise_families.py``) draws a :class:`GenProblem` from a NumPy
``Generator``: random true values, then with the helpers here

- the first ranges a user would type (:func:`draw_ranges`): spanning a factor 3 to 10,
  with the truth inside, at an edge, or (about a quarter of the time) outside by up to
  2x, and levels linear, log-spaced or rounded the way people type them;
- the rig's sensor noise (:func:`add_noise`): white or coloured (AR(1));
- the model mismatch (:data:`MISMATCHES`): none, another solver, the input interpolated
  by the drive where the study holds it, or a small unmodelled actuator lag, which the
  independent simulator (:func:`integrate`) applies;
- the FMU's start values (:func:`fmu_with_starts`): a copy of the family's FMU whose
  ``modelDescription.xml`` gives plausible start values that are not the truth, which
  ``tsid init`` centres its levels on.

The truth never comes from the FMU: every data set is an independent solution.
"""

import hashlib
import itertools
import math
import re
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

from problems.base import CACHE, Problem

#: Where the truth sits in the first range: probability of each placement.
PLACEMENTS = {"inside": 0.45, "edge": 0.30, "outside": 0.25}
#: How the five first levels are spaced: probability of each style.
LEVEL_STYLES = {"linear": 0.3, "log": 0.35, "hand": 0.35}
#: Model mismatches an independent simulator can apply.
MISMATCHES = ("none", "solver", "interpolated", "lag")


@dataclass
class InitCase:
    """What ``tsid init`` is given: one data file's frame and the derived channels.

    Attributes
    ----------
    data : pandas.DataFrame
        Columns named like the FMU's variables (a ``time`` column first).
    derived : dict of str to str
        Derived channels, as given on ``tsid init --derived``.
    """

    data: pd.DataFrame
    derived: dict[str, str] = field(default_factory=dict)


@dataclass
class GenProblem:
    """One randomly drawn problem of a family, with both ways of running it.

    Attributes
    ----------
    family : str
        Family name.
    seed : int
        The seed it was drawn from.
    problem : Problem
        The hand-written study's content (``parameters`` with the drawn levels;
        ``start_values`` fixes the parameters not identified, at the truth).
    init : InitCase
        The data ``tsid init`` gets (with ``problem.fmu``, whose start values are off).
    hold : dict of str to str
        Per input, how the hand-written study holds it (default ``previous``).
    notes : dict of str to str
        What was drawn (placements, level styles, mismatch, noise), for the table.
    method : dict of str to object
        ``[method]`` keys the hand-written study gives beyond the user's defaults (a
        family that reproduces a published study, e.g. the SISO example's).
    noise : dict of str to float
        Sensor noise the hand-written study states (an encoder's quantisation); the
        others are estimated from the data, as for a user who does not know them.
    """

    family: str
    seed: int
    problem: Problem
    init: InitCase
    hold: dict[str, str] = field(default_factory=dict)
    notes: dict[str, str] = field(default_factory=dict)
    method: dict[str, object] = field(default_factory=dict)
    noise: dict[str, float] = field(default_factory=dict)


def pick(rng: np.random.Generator, weights: dict[str, float]) -> str:
    """One key of ``weights``, drawn with the (normalised) weights as probabilities."""
    keys = list(weights)
    p = np.array([weights[k] for k in keys], dtype=float)
    return keys[int(rng.choice(len(keys), p=p / p.sum()))]


def perturb(rng: np.random.Generator, nominal: dict[str, float], spread: float) -> dict[str, float]:
    """``nominal`` with each value times ``exp(U(-spread, spread))`` (4 figures)."""
    return {
        k: float(f"{v * math.exp(rng.uniform(-spread, spread)):.4g}") for k, v in nominal.items()
    }


def _nice(value: float, digits: int) -> float:
    """``value`` rounded to ``digits`` significant figures, as a person types it."""
    return float(f"{value:.{digits}g}")


def _hand_levels(low: float, high: float, n: int) -> list[float]:
    """Levels a person types: rounded to 1 figure (2 where 1 would merge two levels)."""
    raw = np.geomspace(low, high, n) if high / low > 4 else np.linspace(low, high, n)
    for digits in (1, 2, 3, 6):
        values = sorted({_nice(float(v), digits) for v in raw})
        if len(values) == n and values[0] > 0:
            return values
    return [float(v) for v in raw]


def level_values(low: float, high: float, style: str, n: int = 5) -> list[float]:
    """``n`` first levels from ``low`` to ``high`` (both > 0) in ``style``."""
    if style == "linear":
        values = np.linspace(low, high, n)
    elif style == "log":
        values = np.geomspace(low, high, n)
    else:
        return _hand_levels(low, high, n)
    return [_nice(float(v), 6) for v in values]


def draw_range(rng: np.random.Generator, truth: float) -> tuple[float, float, str]:
    """A first range ``(low, high)`` for a positive ``truth``, and where the truth sits.

    The range spans a factor 3 to 10 (log-uniform); the truth is inside it (at 15-85 %
    of the log range), at an edge (within 5 % of an end), or outside by a factor 1.1 to
    2 on either side.
    """
    span = math.exp(rng.uniform(math.log(3.0), math.log(10.0)))
    placement = pick(rng, PLACEMENTS)
    if placement == "inside":
        position = rng.uniform(0.15, 0.85)
    elif placement == "edge":
        position = rng.choice([rng.uniform(0.0, 0.05), rng.uniform(0.95, 1.0)])
    else:
        beyond = math.log(rng.uniform(1.1, 2.0)) / math.log(span)
        position = rng.choice([-beyond, 1.0 + beyond])
    low = truth / span**position
    return low, low * span, placement


def draw_ranges(
    rng: np.random.Generator, truth: dict[str, float], units: dict[str, str]
) -> tuple[dict[str, dict], dict[str, str]]:
    """First levels for every parameter of ``truth``, and a note per parameter.

    Returns
    -------
    parameters : dict
        Name -> ``{"levels", "min": 0, "max": inf, "unit"}`` (see ``Problem``).
    notes : dict
        Name -> ``"<placement>/<style>"``.
    """
    parameters, notes = {}, {}
    for name, value in truth.items():
        low, high, placement = draw_range(rng, value)
        style = pick(rng, LEVEL_STYLES)
        parameters[name] = {
            "levels": level_values(low, high, style),
            "min": 0.0,
            "max": math.inf,
            "unit": units.get(name, ""),
        }
        notes[name] = f"{placement}/{style}"
    return parameters, notes


def draw_starts(rng: np.random.Generator, truth: dict[str, float]) -> dict[str, float]:
    """Plausible FMU start values, not the truth: each within a factor 4 of it."""
    return {
        k: _nice(v * math.exp(rng.uniform(-math.log(4), math.log(4))), 3) for k, v in truth.items()
    }


def ar1(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    """Unit-variance AR(1) noise ``e_k = phi e_(k-1) + sqrt(1 - phi^2) w_k``."""
    from scipy.signal import lfilter

    w = rng.normal(0.0, 1.0, n) * math.sqrt(1.0 - phi**2)
    w[0] = rng.normal()
    return lfilter([1.0], [1.0, -phi], w)


def add_noise(rng: np.random.Generator, clean: np.ndarray, sigma: float, kind: str) -> np.ndarray:
    """``clean`` plus noise of standard deviation ``sigma``: ``white`` or ``ar1:<phi>``."""
    if kind == "white":
        return clean + rng.normal(0.0, sigma, clean.size)
    phi = float(kind.split(":")[1])
    return clean + sigma * ar1(rng, clean.size, phi)


def draw_noise_kind(rng: np.random.Generator) -> str:
    """``white`` (60 %) or coloured ``ar1:<phi>`` with ``phi`` in 0.5-0.95 (40 %)."""
    return "white" if rng.uniform() < 0.6 else f"ar1:{rng.uniform(0.5, 0.95):.2f}"


def draw_sigma(rng: np.random.Generator, clean: np.ndarray) -> float:
    """A sensor sigma of 0.5 % to 5 % (log-uniform) of the output's RMS."""
    rms = float(np.sqrt(np.mean(np.square(clean)))) or 1.0
    return _nice(rms * math.exp(rng.uniform(math.log(0.005), math.log(0.05))), 3)


def multilevel(
    rng: np.random.Generator, t: np.ndarray, amplitude: float, hold: tuple[float, float]
) -> np.ndarray:
    """A random multi-level command, one value per sample (held by the drive).

    Levels uniform in ``+-amplitude``, each held ``hold[0]`` to ``hold[1]`` seconds
    (log-uniform), starting at 0 for the first tenth of the hold.
    """
    edges = [float(t[0]) + hold[0] / 10]
    while edges[-1] <= t[-1]:
        edges.append(edges[-1] + math.exp(rng.uniform(math.log(hold[0]), math.log(hold[1]))))
    level = np.concatenate([[0.0], rng.uniform(-amplitude, amplitude, len(edges))])
    return level[np.searchsorted(edges, t, side="right")]


Rhs = Callable[[float, np.ndarray, float], list[float]]


def integrate(
    rhs: Rhs,
    x0: list[float],
    t: np.ndarray,
    u: np.ndarray,
    mismatch: str = "none",
    lag: float = 0.0,
) -> np.ndarray:
    """Independent solution of ``der(x) = rhs(t, x, u)`` at the sample instants ``t``.

    Parameters
    ----------
    rhs : callable
        ``rhs(t, x, u) -> der(x)``.
    x0 : list of float
        Initial state.
    t : numpy.ndarray
        Sample instants.
    u : numpy.ndarray
        The command per sample: held over ``[t[k], t[k+1])`` by the drive, except with
        ``mismatch = "interpolated"`` (linear between samples).
    mismatch : str
        One of :data:`MISMATCHES`: ``solver`` integrates with RK45 at ``rtol`` 1e-5
        instead of DOP853 at 1e-10; ``lag`` puts a first-order actuator lag of time
        constant ``lag`` between the command and the plant.
    lag : float
        Actuator time constant (s), for ``mismatch = "lag"``.

    Returns
    -------
    numpy.ndarray
        States at ``t``, shape ``(len(t), len(x0))``.
    """
    method, rtol = ("RK45", 1e-5) if mismatch == "solver" else ("DOP853", 1e-10)
    n = len(x0)
    if mismatch == "interpolated":
        dt = float(t[1] - t[0])
        sol = solve_ivp(
            lambda s, x: rhs(s, x, float(np.interp(s, t, u))),
            (t[0], t[-1]),
            x0,
            method=method,
            t_eval=t,
            rtol=rtol,
            atol=1e-12,
            max_step=dt,
        )
        return _checked(sol).y.T
    if mismatch == "lag":

        def full(s: float, x: np.ndarray, level: float) -> list[float]:
            return [*rhs(s, x[:n], x[n]), (level - x[n]) / lag]

        return _piecewise(full, [*x0, 0.0], t, u, method, rtol)[:, :n]
    return _piecewise(rhs, x0, t, u, method, rtol)


def _checked(sol):
    if not sol.success:
        raise RuntimeError(sol.message)
    return sol


def _piecewise(
    rhs: Rhs, x0: list[float], t: np.ndarray, u: np.ndarray, method: str, rtol: float
) -> np.ndarray:
    """Integrate between the instants where the held command changes."""
    out = np.zeros((len(t), len(x0)))
    state = np.asarray(x0, dtype=float)
    cuts = [0, *(np.flatnonzero(np.diff(u[:-1])) + 1), len(t) - 1]
    for a, b in itertools.pairwise(cuts):
        sol = _checked(
            solve_ivp(
                rhs,
                (t[a], t[b]),
                state,
                method=method,
                t_eval=t[a : b + 1],
                args=(float(u[a]),),
                rtol=rtol,
                atol=1e-12,
            )
        )
        out[a : b + 1] = sol.y.T
        state = sol.y[:, -1]
    return out


def fmu_with_starts(fmu: Path, starts: dict[str, float]) -> Path:
    """A copy of ``fmu`` whose ``modelDescription.xml`` gives ``starts`` as start values.

    Only the XML changes: ``tsid init`` reads the start values there and centres its
    levels on them; tsid sets every identified parameter on each run, so the binary's
    own defaults do not enter a fit. Cached under ``benchmarks/.cache/starts``.
    """
    key = hashlib.sha256(
        f"{fmu.resolve()}:{fmu.stat().st_mtime_ns}:{sorted(starts.items())}".encode()
    )
    out = CACHE / "starts" / key.hexdigest()[:16] / fmu.name
    if out.exists():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".part")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = _set_starts(data.decode("utf-8"), starts).encode("utf-8")
            dst.writestr(item, data)
    tmp.replace(out)
    return out


def _set_starts(xml: str, starts: dict[str, float]) -> str:
    """``xml`` with the ``start`` attribute of each named scalar variable replaced."""
    for name, value in starts.items():
        pattern = re.compile(
            rf'(<ScalarVariable[^>]*name="{re.escape(name)}"[^>]*>\s*<Real[^>]*?start=")[^"]*(")',
            re.S,
        )
        xml, count = pattern.subn(rf"\g<1>{value!r}\g<2>", xml)
        if count != 1:
            raise ValueError(f"start value of {name!r} not found once in the model description")
    return xml
