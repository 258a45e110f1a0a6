"""Communication grid and input values of one Co-Simulation run.

Measured inputs are samples; between two samples each input is held (``"previous"``,
a zero-order hold, the default) or linearly interpolated (``"linear"``).  A linear
input reaches the FMU in one of two ways:

- the FMU interpolates itself (FMI 2.0 ``canInterpolateInputs``): it gets the slope
  ``(u[k+1] - u[k]) / h`` through ``fmi2SetRealInputDerivatives`` before each step;
- otherwise every sample interval is split into ``substeps`` communication steps. At
  each communication point the input is set to the line's value there (so an output
  with direct feed-through reads exactly the interpolated signal); then, before a step
  that starts inside the interval, it is set to the line's value at the step's
  midpoint, which the FMU holds over the step, so that the held staircase does not lag
  the line by half a step.

A ``step_size`` splits long sample intervals the same way (inputs held or
interpolated).  :func:`refine` returns the grid the step loop runs on and the rows of it
that are the original samples.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from tsid_fmu.errors import FMUError, SimulationError
from tsid_fmu.fmu.variables import suggest

__all__ = [
    "HOLDS",
    "MAX_SUBSTEPS",
    "Grid",
    "check_finite",
    "check_step_size",
    "check_substeps",
    "check_tolerance",
    "frozen",
    "model_exchange",
    "refine",
    "validate",
]

HOLDS = ("previous", "linear")
"""Input holds: zero-order hold, linear interpolation between samples."""

MAX_SUBSTEPS = 1_000_000
"""Largest number of communication steps one sample interval may be split into."""


class Grid(NamedTuple):
    """What the step loop runs on (every array C-contiguous, float64, writeable).

    Attributes
    ----------
    time : numpy.ndarray
        Communication points, shape ``(m,)``.
    inputs : numpy.ndarray
        Input values at the communication points, shape ``(m, n_inputs)``.
    slopes : numpy.ndarray
        Derivatives of the inputs the FMU interpolates, per step, shape
        ``(m - 1, n_interpolated)`` (``n_interpolated`` is 0 without such inputs).
    keep : numpy.ndarray or None
        Rows of the communication points that are the original samples; None when
        the grid is the samples themselves.
    held : numpy.ndarray
        Input values set again just before each step and held over it, shape
        ``(m - 1, n_inputs)``; no rows (shape ``(0, n_inputs)``) when every step holds
        the values of its starting point.
    """

    time: np.ndarray
    inputs: np.ndarray
    slopes: np.ndarray
    keep: np.ndarray | None
    held: np.ndarray


def frozen(a: Any) -> bool:
    """Return True for a read-only, C-contiguous float64 array (checked only once).

    A read-only view of a writeable array can still change, so every array it is a
    view of must be read-only too.
    """
    if not (isinstance(a, np.ndarray) and a.flags.c_contiguous and a.dtype == np.float64):
        return False
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return True


def validate(
    fmu: str, input_names: tuple[str, ...], time: Any, inputs: Any
) -> tuple[np.ndarray, np.ndarray]:
    """Check the sample times and inputs of one run; return them as float64 arrays.

    Raises
    ------
    SimulationError
        Fewer than 2 samples, time not finite and strictly increasing, inputs of the
        wrong shape, missing, or not finite (the message names the input and time).
    """
    t = np.ascontiguousarray(time, dtype=np.float64)
    if t.ndim != 1 or t.size < 2:
        raise SimulationError(
            f"{fmu}: time must be a 1-D array of at least 2 samples, got shape {t.shape}"
        )
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise SimulationError(f"{fmu}: time must be finite and strictly increasing")
    n_in = len(input_names)
    if inputs is None:
        if n_in:
            raise SimulationError(f"{fmu}: inputs missing for {', '.join(input_names)}")
        return t, np.zeros((t.size, 0))
    u = np.asarray(inputs, dtype=np.float64)
    if u.ndim == 1 and n_in == 1:
        u = u[:, None]
    if u.shape != (t.size, n_in):
        raise SimulationError(
            f"{fmu}: inputs must have shape ({t.size}, {n_in}) "
            f"for {list(input_names)}, got {u.shape}"
        )
    if not np.all(np.isfinite(u)):
        row, col = np.argwhere(~np.isfinite(u))[0]
        raise SimulationError(
            f"{fmu}: input {input_names[col]!r} is not finite at t={t[row]:g} (row {row})"
        )
    return t, np.ascontiguousarray(u)


def _splits(fmu: str, h: np.ndarray, step_size: float | None, substeps: int) -> np.ndarray | None:
    """Return the number of communication steps per sample interval (None: all 1)."""
    n_sub = np.ones(h.size, dtype=np.int64)
    if step_size is not None:
        ratio = h / step_size
        if not np.all(ratio <= MAX_SUBSTEPS):
            raise SimulationError(
                f"{fmu}: step_size {step_size:g} s would split a sample "
                f"interval into more than {MAX_SUBSTEPS} steps"
            )
        n_sub = np.maximum(np.ceil(ratio - 1e-9), 1).astype(np.int64)
    n_sub = np.maximum(n_sub, substeps)
    return n_sub if n_sub.max() > 1 else None


def _writeable(a: np.ndarray) -> np.ndarray:
    # the compiled loop is specialised for writeable arrays: one signature, one compile
    return a if a.flags.writeable else a.copy()


def refine(
    fmu: str,
    t: np.ndarray,
    u: np.ndarray,
    linear: np.ndarray,
    *,
    native: bool,
    step_size: float | None = None,
    substeps: int = 1,
) -> Grid:
    """Return the communication grid and input values for samples ``t``, ``u``.

    Parameters
    ----------
    fmu : str
        The FMU's name, for messages.
    t, u : numpy.ndarray
        Checked samples (see :func:`validate`).
    linear : numpy.ndarray of bool
        Per input: interpolate linearly (else hold).
    native : bool
        The FMU interpolates inputs itself given their derivatives.
    step_size : float, optional
        Largest communication step.
    substeps : int
        Communication steps per sample interval when some input is linear and the FMU
        does not interpolate.
    """
    h = np.diff(t)
    interpolate = bool(linear.any())
    if native and interpolate:
        slopes = np.diff(u[:, linear], axis=0) / h[:, None]
    else:
        slopes = np.zeros((t.size - 1, 0))
    n_sub = _splits(fmu, h, step_size, substeps if interpolate and not native else 1)
    keep = None
    held = np.empty((0, u.shape[1]))
    if n_sub is not None:
        keep = np.concatenate([[0], np.cumsum(n_sub)])
        # t[k] + j * (h[k] / n[k]), the same floating-point operations as
        # np.linspace(t[k], t[k + 1], n[k], endpoint=False)
        j = np.arange(keep[-1]) - np.repeat(keep[:-1], n_sub)
        fine = np.repeat(t[:-1], n_sub) + j * np.repeat(h / n_sub, n_sub)
        t_fine = np.concatenate([fine, t[-1:]])
        u_fine = np.concatenate([np.repeat(u[:-1], n_sub, axis=0), u[-1:]])
        for c in np.flatnonzero(linear):
            u_fine[:, c] = np.interp(t_fine, t, u[:, c])
        if interpolate and not native:  # (an FMU that interpolates gets the slopes)
            # over each communication step inside a sample interval a linear input holds
            # its value at the step's midpoint: a staircase centred on the line, without
            # the lag of half a step that the value at the step's start would give (a
            # step from a sample holds the sample, as before the substeps existed)
            inner = np.ones(t_fine.size - 1, dtype=bool)
            inner[keep[:-1]] = False
            mid = t_fine[:-1][inner] + 0.5 * np.diff(t_fine)[inner]
            held = u_fine[:-1].copy()
            for c in np.flatnonzero(linear):
                held[inner, c] = np.interp(mid, t, u[:, c])
        t, u = t_fine, u_fine
        slopes = np.repeat(slopes, n_sub, axis=0)
    return Grid(_writeable(t), _writeable(u), np.ascontiguousarray(slopes), keep, held)


def model_exchange(t: np.ndarray, u: np.ndarray, linear: np.ndarray) -> Grid:
    """Return the grid of a Model Exchange run: the samples, the slopes of linear inputs.

    ``slopes`` has one column per input (zero for held inputs), shape ``(n - 1, n_in)``.
    """
    slopes = np.zeros((t.size - 1, u.shape[1]))
    if linear.any():
        slopes[:, linear] = np.diff(u[:, linear], axis=0) / np.diff(t)[:, None]
    return Grid(_writeable(t), _writeable(u), slopes, None, np.empty((0, u.shape[1])))


def check_tolerance(fmu: str, tolerance: Any) -> float | None:
    """Return ``tolerance`` as a float in (0, 1) (or None); FMUError otherwise."""
    if tolerance is None:
        return None
    number = not isinstance(tolerance, bool) and isinstance(tolerance, int | float | np.floating)
    value = float(tolerance) if number else math.nan
    if not 0 < value < 1:
        raise FMUError(
            f"{fmu}: tolerance must be a relative tolerance in (0, 1), got {tolerance!r}"
        )
    return value


def check_finite(fmu: str, names: tuple[str, ...], t: np.ndarray, out: np.ndarray) -> None:
    """Raise SimulationError naming the first output that is not finite (and its time)."""
    # NaN and inf always make the sum non-finite (one pass, no temporary array);
    # only then (or for a sum that overflowed) are the elements looked at
    if math.isfinite(float(out.sum())):
        return
    bad = ~np.isfinite(out)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise SimulationError(
            f"{fmu}: output {names[col]!r} is {out[row, col]} at "
            f"t={t[row]:g} (step {row}); check the parameters of this run"
        )


class Checked:
    """The grids of read-only ``(time, inputs)`` pairs, remembered by identity.

    A study simulates the same (read-only) time and input arrays hundreds of times: the
    checks and the grid are done once for them. Only arrays that cannot be changed in
    place (not writeable, already float64 and C-contiguous, :func:`frozen`) are
    remembered, holding a reference so that the identity cannot be reused. A study
    alternates between its replicates' inputs, so ``size`` pairs are kept.
    """

    def __init__(self, size: int = 32) -> None:
        self.size = size
        self._pairs: dict[tuple[int, int], tuple[Any, Any, Grid]] = {}

    def get(self, time: np.ndarray, inputs: np.ndarray | None) -> Grid | None:
        """Return the grid of this very pair of arrays, if remembered."""
        hit = self._pairs.get((id(time), id(inputs)))
        if hit is not None and hit[0] is time and hit[1] is inputs:
            return hit[2]
        return None

    def put(self, time: np.ndarray, inputs: np.ndarray | None, g: Grid) -> None:
        """Remember ``g`` for this pair, if neither array can change."""
        if frozen(time) and (inputs is None or frozen(inputs)):
            if len(self._pairs) >= self.size:
                self._pairs.pop(next(iter(self._pairs)))
            self._pairs[(id(time), id(inputs))] = (time, inputs, g)


def check_holds(fmu: str, input_names: Sequence[str], hold: Mapping[str, str]) -> dict[str, str]:
    """Return the hold of every input (``"previous"`` unless ``hold`` names it).

    Raises
    ------
    FMUError
        ``hold`` names something that is not an input, or a hold that is not one of
        :data:`HOLDS`.
    """
    for name, kind in hold.items():
        if name not in input_names:
            raise FMUError(
                f"{fmu}: hold given for {name!r}, which is not one of the "
                f"inputs {list(input_names)}.{suggest(name, input_names)}"
            )
        if kind not in HOLDS:
            raise FMUError(
                f"{fmu}: hold of input {name!r} must be 'previous' or 'linear', not {kind!r}"
            )
    return {name: hold.get(name, "previous") for name in input_names}


def check_substeps(fmu: str, substeps: Any) -> int:
    """Return ``substeps`` as an int in ``1 .. MAX_SUBSTEPS``; FMUError otherwise."""
    if isinstance(substeps, bool) or not isinstance(substeps, int | np.integer):
        raise FMUError(f"{fmu}: substeps must be an integer, got {substeps!r}")
    if not 1 <= substeps <= MAX_SUBSTEPS:
        raise FMUError(f"{fmu}: substeps must be 1 to {MAX_SUBSTEPS}, got {substeps}")
    return int(substeps)


def check_step_size(fmu: str, step_size: Any) -> float | None:
    """Return ``step_size`` as a positive finite float (or None); FMUError otherwise."""
    if step_size is None:
        return None
    try:
        value = float(step_size)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise FMUError(f"{fmu}: step_size must be a positive time in seconds, got {step_size!r}")
    return value
