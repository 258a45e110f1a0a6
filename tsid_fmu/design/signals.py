"""Candidate input signals of an experiment design, inside the rig's limits.

Each kind is tried in ``bands`` logarithmic sub-bands of the allowed band and in the
whole band (square waves at as many frequencies), so that the design compares
excitations that put their power in different places: the one that determines a
damping needs power near the resonance, the one that determines a static gain needs
power near zero frequency. Every signal spans the whole allowed amplitude of each
input (``[min, max]``), and several inputs get independent phases or sequences, plus
one multisine per input and band where that input alone moves (the others at the
middle of their range), so that a design can separate what each input drives.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

__all__ = ["Signal", "candidates"]


@dataclass(frozen=True)
class Signal:
    """One candidate input.

    Attributes
    ----------
    name : str
        Short label, e.g. ``"multisine 2.1-8.7 Hz"``.
    kind : str
        ``steps``, ``chirp``, ``multisine`` or ``prbs``.
    band : tuple of float
        The frequencies it carries (Hz); a square wave's fundamental twice.
    values : numpy.ndarray
        ``(n_samples, n_inputs)``: the input, in the order of the design's inputs.
    """

    name: str
    kind: str
    band: tuple[float, float]
    values: np.ndarray


def _unit_steps(t: np.ndarray, f: float, phase: float) -> np.ndarray:
    return np.where(np.sin(2 * np.pi * f * t + phase) >= 0, 1.0, -1.0)


def _unit_chirp(t: np.ndarray, f1: float, f2: float, reverse: bool) -> np.ndarray:
    span = max(float(t[-1] - t[0]), 1e-300)
    tau = (t - t[0]) / span
    if reverse:
        tau = 1.0 - tau
    rate = np.log(f2 / f1)
    # logarithmic sweep: instantaneous frequency f1 (f2/f1)^tau
    phase = 2 * np.pi * f1 * span * (np.exp(rate * tau) - 1.0) / rate
    return np.sin(phase if not reverse else -phase)


def _unit_multisine(t: np.ndarray, f1: float, f2: float, rng: np.random.Generator) -> np.ndarray:
    k = 12
    freqs = np.geomspace(f1, f2, k)
    n = np.arange(1, k + 1)
    phases = -np.pi * n * (n - 1) / k + rng.uniform(0, 2 * np.pi)  # Schroeder: low crest
    x = np.sin(2 * np.pi * freqs[None, :] * t[:, None] + phases[None, :]).sum(axis=1)
    return x / max(float(np.max(np.abs(x))), 1e-300)


def _unit_prbs(t: np.ndarray, f2: float, rng: np.random.Generator) -> np.ndarray:
    hold = 1.0 / (2.0 * f2)  # a clock at twice the band's top: power up to about f2
    slots = np.floor((t - t[0]) / hold).astype(int)
    bits = rng.integers(0, 2, slots.max() + 1) * 2.0 - 1.0
    return bits[slots]


def _below(band: tuple[float, float], cap: float) -> tuple[float, float]:
    """Return ``band`` moved down, its width in octaves kept, until its top is ``cap``."""
    if band[1] <= cap:
        return band
    return (band[0] * cap / band[1], cap)


def _sub_bands(f1: float, f2: float, n: int) -> list[tuple[float, float]]:
    edges = np.geomspace(f1, f2, n + 1)
    out = [(float(a), float(b)) for a, b in itertools.pairwise(edges)]
    return [*out, (f1, f2)] if n > 1 else out


def _unit(
    kind: str, t: np.ndarray, band: tuple[float, float], i: int, rng, smooth: bool, top: float
) -> np.ndarray:
    """Return the signal of input ``i`` in ``[-1, 1]``; inputs get independent phases.

    A ``smooth`` input gets a sine where a square wave is asked for, and a multisine
    where a PRBS is. ``top`` is the allowed band's highest frequency.
    """
    f1, f2 = band
    if kind == "steps":
        # several inputs at frequencies apart (not multiples), so they do not move together;
        # below the band's top
        ratio = 1.0 + 0.37 * i
        f, phase = (f1 * ratio if f1 * ratio <= top else f1 / ratio), 0.5 * np.pi * i
        return np.sin(2 * np.pi * f * t + phase) if smooth else _unit_steps(t, f, phase)
    if kind == "chirp":
        return _unit_chirp(t, f1, f2, reverse=bool(i % 2))
    if kind == "multisine" or smooth:
        return _unit_multisine(t, f1, f2, rng)
    return _unit_prbs(t, f2, rng)


def candidates(
    t: np.ndarray,
    limits: list[tuple[float, float]],
    band: tuple[float, float],
    kinds: list[str],
    bands: int,
    seed: int,
    *,
    smooth: list[bool] | None = None,
    caps: list[float] | None = None,
) -> list[Signal]:
    """Return the candidate inputs on the sample times ``t``.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times (s).
    limits : list of (float, float)
        ``(min, max)`` of each input.
    band : (float, float)
        Allowed frequencies (Hz).
    kinds : list of str
        Signal kinds (:data:`tsid_fmu.study.designopts.KINDS`).
    bands : int
        Sub-bands per kind.
    seed : int
        Seed of the random phases and sequences.
    smooth : list of bool, optional
        Per input: whether it must be smooth (a position whose derivatives the model
        takes): it then gets a sine at a square wave's frequency, and a multisine where
        a PRBS is asked for.
    caps : list of float, optional
        Per input: the highest frequency it may carry (default the band's top); a
        sub-band above it is moved down to it.
    """
    smooth = smooth or [False] * len(limits)
    caps = caps or [band[1]] * len(limits)
    rng = np.random.default_rng(seed)
    lo = np.array([a for a, _ in limits])
    hi = np.array([b for _, b in limits])
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    n_in = len(limits)
    out = []
    for kind in kinds:
        if kind == "steps":
            freqs = np.geomspace(band[0], band[1], bands + 1)
            trials = [(float(f), float(f)) for f in freqs]
        else:
            trials = _sub_bands(band[0], band[1], bands)
        for sub in trials:
            units = np.stack(
                [
                    _unit(kind, t, _below(sub, caps[i]), i, rng, smooth[i], caps[i])
                    for i in range(n_in)
                ],
                axis=1,
            )
            label = f"{sub[0]:.3g} Hz" if kind == "steps" else f"{sub[0]:.3g}-{sub[1]:.3g} Hz"
            out.append(Signal(f"{kind} {label}", kind, sub, mid + half * units))
            alone_too = n_in > 1 and kind == "multisine"
            for i in range(n_in if alone_too else 0):  # one input alone moving
                alone = np.zeros_like(units)
                alone[:, i] = units[:, i]
                out.append(Signal(f"{kind} {label}, input {i + 1} alone", kind, sub,
                                  mid + half * alone))  # fmt: skip
    return out
