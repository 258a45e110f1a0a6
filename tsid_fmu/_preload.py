"""Imported by the ``forkserver`` of :mod:`tsid_fmu.parallel` before it forks workers.

Importing the package and loading the compiled step loops once here means every
worker forked from the server starts with them ready, in milliseconds.
"""

from __future__ import annotations

import tsid_fmu.parallel
import tsid_fmu.runner  # noqa: F401
from tsid_fmu.fmu.compiled import warm_up

warm_up()


def _warm_pickle() -> None:
    """Unpickle a small frame once: pandas imports its unpickling helpers lazily."""
    import pickle

    import pandas as pd

    pickle.loads(pickle.dumps(pd.DataFrame({"time": [0.0, 1.0]})))


_warm_pickle()
