"""Test-session setup shared by every test module."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest
from crash_factory import build_crash_fmu
from fmu_factory import build_c_fmu


def pytest_configure(config) -> None:
    """Make Ctrl-C deliverable even when pytest was started with SIGINT ignored.

    A shell starts a background job (``pytest &``, ``nohup``) with SIGINT ignored;
    Python then installs no ``KeyboardInterrupt`` handler, and every child inherits the
    ignored signal across ``exec``. The interrupt tests press Ctrl-C on ``tsid`` as a
    terminal would, so they need the disposition a terminal gives: Python's default.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="module")
def lag_crash_fmus(tmp_path_factory) -> dict[str, Path]:
    """The evaluator tests' FMUs, built once per test module that asks for them.

    ``"lag"``: the first-order lag of ``fmu_factory`` (Co-Simulation only); ``"crash"``:
    the feed-through of ``crash_factory`` that crashes or hangs on demand.
    """
    d = tmp_path_factory.mktemp("lag_crash")
    return {"lag": build_c_fmu(d, "Lag", interfaces=("cs",)), "crash": build_crash_fmu(d)}
