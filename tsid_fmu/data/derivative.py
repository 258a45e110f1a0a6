"""Smoothing derivatives of sampled signals (the ``der()`` of derived channels).

A position-controlled stage logs its position only; a plant model that needs the
velocity and acceleration gets them from ``der(x_o)`` and ``der(x_o, 2)``. Differencing
a quantised, noisy position amplifies the noise by ``1/dt`` per order, so the derivative
is a Savitzky-Golay one (:func:`scipy.signal.savgol_filter`): a least-squares polynomial
of degree ``max(3, order + 1)`` over a centred window of ``window`` samples, evaluated
and differentiated at each sample; near the ends the polynomial fitted to the first or
last window is used (``mode="interp"``), so the result has no phase lag and no edge
transient. The default window of 21 samples spans 20 ms at 1 kHz: ample for motions of
a few hertz, and wide enough that a 1 um encoder's quantisation contributes well under
a millinewton through a 0.2 kg mass at the second order.
"""

from __future__ import annotations

import numpy as np

from tsid_fmu.errors import DataError

__all__ = ["DEFAULT_WINDOW", "derivative"]

DEFAULT_WINDOW = 21
"""Default Savitzky-Golay window, in samples (odd)."""


def derivative(
    signal: np.ndarray, sample_time: float, *, order: int = 1, window: int = DEFAULT_WINDOW
) -> np.ndarray:
    """Return the ``order``-th time derivative of a uniformly sampled signal.

    Parameters
    ----------
    signal : numpy.ndarray
        Samples, shape ``(n,)``.
    sample_time : float
        Sampling interval in seconds.
    order : int
        1 (velocity from position) or 2 (acceleration), up to 3.
    window : int
        Savitzky-Golay window length in samples: odd, at least ``order + 3``, at most
        the number of samples.

    Returns
    -------
    numpy.ndarray
        The derivative at every sample, in units of the signal per second**order.

    Raises
    ------
    DataError
        The order or window is out of range.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(0, 1, 1e-3)
    >>> v = derivative(np.sin(2 * np.pi * t), 1e-3)
    >>> bool(np.allclose(v, 2 * np.pi * np.cos(2 * np.pi * t), rtol=1e-3, atol=1e-3))
    True
    """
    from scipy.signal import savgol_filter

    x = np.asarray(signal, dtype=np.float64)
    if not 1 <= order <= 3:
        raise DataError(f"der() order must be 1, 2 or 3, got {order}")
    polyorder = max(3, order + 1)
    if window % 2 == 0 or window < polyorder + 2:
        raise DataError(
            f"der() window must be an odd number of samples >= {polyorder + 2}, got {window}"
        )
    if window > x.size:
        raise DataError(f"der() window of {window} samples is longer than the data ({x.size})")
    if not (np.isfinite(sample_time) and sample_time > 0):
        raise DataError(f"der() needs a positive sample time, got {sample_time}")
    return savgol_filter(x, window, polyorder, deriv=order, delta=sample_time, mode="interp")
