"""Progress display of a running study on the terminal."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

from tsid_fmu.report.style import fmt

__all__ = ["SLOW_ROW", "ConsoleProgress"]

SLOW_ROW = 1.0
"""Seconds per run above which each run's progress is shown with the time left."""


class ConsoleProgress:
    """Print the progress of a study: a live row counter and one line per iteration.

    Parameters
    ----------
    stream : file-like, optional
        Where to print; default ``sys.stderr``.
    clock : callable, optional
        Seconds now (default :func:`time.perf_counter`).

    Notes
    -----
    On a terminal a live counter shows the runs of the current array; once a run takes
    more than :data:`SLOW_ROW` seconds on average, it shows the time left too. Written
    to a file or a pipe, one line per finished run is printed, with the time left, but
    only for such slow runs.
    """

    def __init__(self, stream: TextIO | None = None, clock: Any = None) -> None:
        self.stream = stream or sys.stderr
        self.live = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.clock = clock or time.perf_counter
        self.t0 = self.clock()
        self._last = 0.0
        self._array_t0 = self.t0

    def __call__(self, event: str, info: dict[str, Any]) -> None:
        """Handle one progress event of :func:`tsid_fmu.identify`."""
        now = self.clock()
        if event == "row":
            self._row(info, now)
        elif event == "iteration":
            self._array_t0 = now
            self._print(f"{info['stage']}, iteration {info['iteration']}: running the array ...")
        elif event == "iteration done":
            rec = info["record"]
            failed = sum(e is not None for e in rec.errors)
            if self.live:
                self.stream.write("\r" + " " * 70 + "\r")
            fails = f", {failed} failed runs" if failed else ""
            self._print(
                f"{rec.stage}, iteration {rec.index} ({rec.array}{fails}): best cost "
                f"{fmt(rec.best_cost)}; {rec.decision.message} [{rec.nfev_total} simulations "
                f"so far, {now - self.t0:.1f} s]"
            )
        elif event == "fidelity":
            self._print(info["message"])
        elif event in ("stage", "rerun"):
            self._print(f"== {info['message']}" if event == "stage" else f"  {info['message']}")
        elif event == "refinement":
            self._print(f"== refinement (least squares) from cost {fmt(info['cost'])} ...")
        elif event == "refinement done":
            self._print(
                f"refinement: cost {fmt(info['cost'])} [{info['nfev']} simulations in the stage, "
                f"{now - self.t0:.1f} s]"
            )
        elif event == "report done":
            self._print(
                f"report: {info['seconds']:.1f} s, of which plots {info['plots_seconds']:.1f} s"
            )
        elif event == "done":
            res = info["result"]
            self._print(
                f"{res.message} ({res.nit} Taguchi iterations, {res.nfev} simulations, "
                f"{now - self.t0:.1f} s)"
            )

    def _row(self, info: dict[str, Any], now: float) -> None:
        """Show the runs done, and the time left once runs are slow."""
        done, total = info["done"], info["total"]
        per_run = (now - self._array_t0) / max(done, 1)
        left = per_run * (total - done)
        eta = f", about {left:.0f} s left" if per_run > SLOW_ROW and done < total else ""
        if not self.live:
            if per_run > SLOW_ROW:
                self._print(f"  run {done}/{total} done ({per_run:.1f} s per run{eta})")
            return
        if now - self._last < 0.1 and done != total:
            return
        self._last = now
        bar = "#" * int(30 * done / total)
        self.stream.write(f"\r  runs [{bar:<30}] {done}/{total}{eta}   ")
        self.stream.flush()

    def _print(self, text: str) -> None:
        self.stream.write(text + "\n")
        self.stream.flush()
