"""Imported by the ``forkserver`` of :mod:`tsid_fmu.evaluate.workers` before it forks workers.

Importing the package and loading the compiled step loops once here means every
worker forked from the server starts with them ready, in milliseconds.
"""

from __future__ import annotations

import tsid_fmu.evaluate.workers  # noqa: F401
from tsid_fmu.evaluate.runner import warm_up

warm_up()
