"""Input delays: a parameter ``delay(<input>)`` shifts that input's samples in time.

A drive or controller latency shows as a constant delay between the logged command and
the plant's response. A study identifies it like any other factor: the parameter
``delay(F_m)`` (seconds, any sign; levels such as ``[0, 0.5e-3, 1e-3]``) is not an FMU
variable but is applied to the input ``F_m`` before each simulation:

    u_d(t_k) = u(t_k - d)

evaluated by linear interpolation between the samples (the first sample before the
record starts, the last after it ends). For an input held linearly that is the shifted
signal itself at the samples. For a held input (zero-order hold, ``hold = "previous"``)
it is each interval's time average of the shifted staircase: a shift by a fraction
``f`` of a sample puts ``f`` of the previous value and ``1 - f`` of the current one into
every interval, so the input's integral is kept exactly and the response is shifted
by ``d`` to within a fraction of a sample's curvature. Both are smooth in ``d``, which
is what lets the array's levels and a least-squares refinement resolve sub-sample
delays.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

import numpy as np

from tsid_fmu.errors import StudyError

__all__ = ["check_delays", "delay_input", "delayed_inputs", "split_delays"]

_DELAY = re.compile(r"^delay\(\s*([^()\s]+)\s*\)$")


def delay_input(name: str) -> str | None:
    """Return the input named by ``delay(<input>)``, or None for any other name."""
    m = _DELAY.match(name)
    return m.group(1) if m else None


def split_delays(values: Mapping[str, float]) -> tuple[dict[str, float], dict[str, float]]:
    """Split a parameter set into FMU values and input delays (by input name)."""
    fmu: dict[str, float] = {}
    delays: dict[str, float] = {}
    for name, value in values.items():
        target = delay_input(name)
        if target is None:
            fmu[name] = value
        else:
            delays[target] = float(value)
    return fmu, delays


def check_delays(names: Sequence[str], input_names: Sequence[str], where: str) -> None:
    """Check that every ``delay(<input>)`` among ``names`` names one of ``input_names``.

    ``where`` names the inputs' owner in the message (``"experiment 'a'"``).

    Raises
    ------
    StudyError
        A delay of an input that is not among ``input_names``.
    """
    for name in names:
        target = delay_input(name)
        if target is not None and target not in input_names:
            listed = ", ".join(input_names) or "none"
            raise StudyError(
                f"{name!r}: {target!r} is not an input of {where} (its inputs: {listed})"
            )


def delayed_inputs(
    time: np.ndarray,
    inputs: np.ndarray | None,
    input_names: Sequence[str],
    delays: Mapping[str, float],
) -> np.ndarray | None:
    """Return ``inputs`` with each named column delayed by its delay in seconds.

    Parameters
    ----------
    time : numpy.ndarray
        Sample times, shape ``(n,)``.
    inputs : numpy.ndarray or None
        Shape ``(n, len(input_names))``.
    input_names : sequence of str
        Column names of ``inputs``.
    delays : mapping of str to float
        Delay per input name (seconds; negative values advance the input).

    Returns
    -------
    numpy.ndarray or None
        A new array when any delay is non-zero, else ``inputs`` itself.
    """
    if inputs is None or not any(delays.values()):
        return inputs
    out = np.array(inputs, dtype=np.float64, order="C", copy=True)
    for j, name in enumerate(input_names):
        d = delays.get(name, 0.0)
        if d:
            out[:, j] = np.interp(time - d, time, inputs[:, j])
    return out
