"""Compile the Model Exchange loop of :mod:`tsid_fmu.fmu.meloop` with Numba (imports Numba).

As for the step loops (:mod:`tsid_fmu.fmu._numba`, which gives ``ptr`` and ``seq``
their Numba implementations): no second copy of the loop.  The helpers the loop calls
are registered as jitable (``register_jitable`` leaves them plain Python functions
and lets compiled code call them) and the loop itself is handed to ``njit``; Numba's
on-disk cache keys the compiled code on ``meloop.py``.

Do not import this module directly; :func:`tsid_fmu.fmu.compiled.me_loop` does.
"""

from __future__ import annotations

from numba.extending import register_jitable

import tsid_fmu.fmu._numba as _numba
import tsid_fmu.fmu.meloop as meloop

__all__ = ["me_loop"]

HELPERS = (
    "_flag",
    "_set_inputs",
    "_time_and_states",
    "_point",
    "_indicators",
    "_crossed",
    "_copy",
    "_rk_step",
    "_discrete",
    "_event",
    "_completed",
    "_locate",
    "_trial",
    "_step",
    "_boundary",
    "_start",
)

#: small helpers called in every stage: inlined into their callers
INLINE = frozenset(
    {"_flag", "_set_inputs", "_time_and_states", "_point", "_indicators", "_crossed", "_copy"}
)

for _name in HELPERS:
    register_jitable(inline="always" if _name in INLINE else "never")(getattr(meloop, _name))

me_loop = _numba._jit(meloop._me_loop)
