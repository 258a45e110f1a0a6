"""Imported by the ``forkserver`` of :mod:`tsid_fmu.evaluate.workers` before it forks workers.

Importing the package and loading the compiled step loops once here means every
worker forked from the server starts with them ready, in milliseconds.
"""

from __future__ import annotations

import pickle
import sys

import tsid_fmu.evaluate.workers  # noqa: F401
from tsid_fmu.evaluate.runner import warm_up

warm_up()


def _quiet_orphan(kind: type[BaseException], value: BaseException, tb: object) -> None:
    """Say nothing for a worker whose parent vanished while it started.

    The forkserver's child reads its start data from the parent; a parent killed in that
    instant (Ctrl-C, SIGTERM) cuts it short, and the child would print an
    ``UnpicklingError`` or ``BrokenPipeError`` traceback under the parent's one-line
    message. The parent reports what matters; anything else is printed as usual.
    """
    if issubclass(kind, pickle.UnpicklingError | EOFError | BrokenPipeError | ConnectionError):
        return
    _DEFAULT_HOOK(kind, value, tb)  # type: ignore[arg-type]


_DEFAULT_HOOK = sys.excepthook
sys.excepthook = _quiet_orphan  # inherited by every worker forked from the server
