"""Model Exchange runs with FMPy's solver (CVode) on the session's instance.

The session's default is the project's own integrator (:mod:`tsid_fmu.fmu.mesolver`);
this is ``me_solver="cvode"``.

The session's extracted folder, model description and instance are reused; the
inputs become FMPy input signals (held inputs as events at every sample, linear ones
continuous), and the results are interpolated at the sample times.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["input_signal", "simulate_me"]


def input_signal(
    t: np.ndarray, u: np.ndarray, names: Sequence[str], linear: np.ndarray
) -> np.ndarray | None:
    """Return FMPy's structured input signal for samples ``t``, ``u``.

    Every time stamp appears twice (an event at each sample); a held input keeps its
    previous value up to the event, a linear input has the new value on both sides, so
    FMPy interpolates it linearly in between.
    """
    if not len(names):
        return None
    n = t.size
    signal = np.zeros(
        2 * n - 1, dtype=[("time", np.float64)] + [(name, np.float64) for name in names]
    )
    signal["time"][0::2] = t
    signal["time"][1::2] = t[1:]
    for j, name in enumerate(names):
        signal[name][0::2] = u[:, j]
        signal[name][1::2] = u[1:, j] if linear[j] else u[:-1, j]
    return signal


def simulate_me(
    fmu: Any,
    md: Any,
    t: np.ndarray,
    signal: np.ndarray | None,
    outputs: Sequence[str],
    start_values: dict[str, Any],
    step_size: float | None,
    tolerance: float | None,
    on_error: Callable[[Exception, float], Exception],
) -> np.ndarray:
    """Integrate the Model Exchange instance ``fmu`` over ``t``; return the outputs at ``t``.

    Parameters
    ----------
    fmu : fmpy.fmi2.FMU2Model or fmpy.fmi3.FMU3Model
        The instantiated (or reset) FMU.
    md : fmpy.model_description.ModelDescription
        Its model description.
    t : numpy.ndarray
        Sample times.
    signal : numpy.ndarray or None
        Input signal from :func:`input_signal`.
    outputs : sequence of str
        Variables to record.
    start_values : dict
        Start values and parameters of this run.
    step_size : float, optional
        The solver's step size hint.
    tolerance : float, optional
        CVode's relative tolerance (default: the model description's default
        experiment's, else FMPy's 1e-5).
    on_error : callable
        ``on_error(exc, time)`` returns the exception to raise when FMPy fails at
        ``time``.
    """
    from fmpy import simulate_fmu

    current = {"t": float(t[0])}

    def step_finished(time: float, recorder: Any) -> bool:
        current["t"] = time
        return True

    try:
        result = simulate_fmu(
            str(fmu.unzipDirectory),
            validate=False,
            start_time=float(t[0]),
            stop_time=float(t[-1]),
            step_size=step_size,
            relative_tolerance=tolerance,
            output_interval=float(np.min(np.diff(t))),
            record_events=False,
            start_values=start_values,
            input=signal,
            output=list(outputs),
            model_description=md,
            fmu_instance=fmu,
            step_finished=step_finished,
        )
    except Exception as exc:  # FMICallException or bare Exception from FMPy's solver
        raise on_error(exc, current["t"]) from exc
    rt = result["time"]
    return np.column_stack([np.interp(t, rt, result[name]) for name in outputs])
