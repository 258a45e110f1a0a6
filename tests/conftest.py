"""Test-session setup shared by every test module."""

from __future__ import annotations

import signal


def pytest_configure(config) -> None:
    """Make Ctrl-C deliverable even when pytest was started with SIGINT ignored.

    A shell starts a background job (``pytest &``, ``nohup``) with SIGINT ignored;
    Python then installs no ``KeyboardInterrupt`` handler, and every child inherits the
    ignored signal across ``exec``. The interrupt tests press Ctrl-C on ``tsid`` as a
    terminal would, so they need the disposition a terminal gives: Python's default.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
