"""Progress display of a running study on the terminal."""

from __future__ import annotations

import math
import shutil
import sys
import time
from typing import Any, TextIO

from tsid_fmu.report.style import counted, fmt

__all__ = ["COMPILING", "SLOW_ROW", "ConsoleProgress"]

SLOW_ROW = 1.0
"""Seconds per run above which, off a terminal, each run's progress is shown."""

COMPILING = "compiling the simulation loop (first run only) ..."
"""Said once when Numba compiles the simulation loop (a few seconds, cached on disk)."""

_BAR = 20  # characters of the live bar


class ConsoleProgress:
    """Print the progress of a study: a live status bar and one line per iteration.

    Parameters
    ----------
    stream : file-like, optional
        Where to print; default ``sys.stderr``.
    clock : callable, optional
        Seconds now (default :func:`time.perf_counter`).

    Notes
    -----
    On a terminal the last line is a status bar, redrawn as the runs finish: the
    stage, the iteration, the runs of its array done and planned, the simulations
    run so far in the study, the best cost so far in the stage and the time left for
    the array. Written to a file or a pipe, one line per finished run is printed, with
    the time left, but only for runs slower than :data:`SLOW_ROW` seconds.
    """

    def __init__(self, stream: TextIO | None = None, clock: Any = None) -> None:
        self.stream = stream or sys.stderr
        self.live = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.clock = clock or time.perf_counter
        self.t0 = self.clock()
        self._last = 0.0
        self._array_t0 = self.t0
        self._drawn = False  # a status bar is on the last line
        self._said_compiling = False
        self.stage = ""
        self.best = math.inf  # best cost so far in the current stage
        self.nfev = 0  # simulations so far in the study, as last reported

    def __call__(self, event: str, info: dict[str, Any]) -> None:
        """Handle one progress event of :func:`tsid_fmu.identify`."""
        now = self.clock()
        if event == "row":
            self._row(info, now)
        elif event == "iteration":
            self._array_t0 = now
            self.stage = str(info["stage"])
            self._print(f"{info['stage']}, iteration {info['iteration']}: running the array ...")
        elif event == "iteration done":
            self._iteration_done(info["record"], now)
        elif event == "compiling":
            if not self._said_compiling:
                self._said_compiling = True
                self._print(info.get("message", COMPILING))
        elif event == "start":
            self.stage, self.best = str(info["stage"]), float(info["cost"])
        elif event in ("fidelity", "sampled", "conformance"):
            self._print(info["message"])
        elif event in ("stage", "rerun"):
            if event == "stage":
                self.best = math.inf
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
                f"{res.message} ({counted(res.nit, 'Taguchi iteration')}, {now - self.t0:.1f} s)"
            )

    def _iteration_done(self, rec: Any, now: float) -> None:
        failed = sum(e is not None for e in rec.errors)
        self.best = min(self.best, float(rec.best_cost))
        self.nfev = max(self.nfev, int(rec.nfev_total))
        fails = f", {failed} failed runs" if failed else ""
        self._print(
            f"{rec.stage}, iteration {rec.index} ({rec.array}{fails}): best cost "
            f"{fmt(rec.best_cost)}; {rec.decision.message} [{rec.nfev_total} simulations "
            f"so far, {now - self.t0:.1f} s]"
        )

    def _row(self, info: dict[str, Any], now: float) -> None:
        """Show the runs done, and the time left (on a terminal always, else when slow)."""
        done, total = info["done"], info["total"]
        self.nfev = max(self.nfev, int(info.get("nfev", 0)))
        cost = info.get("cost")
        if cost is not None and math.isfinite(cost):  # the best follows the array's runs
            self.best = min(self.best, float(cost))
        per_run = (now - self._array_t0) / max(done, 1)
        left = per_run * (total - done)
        if not self.live:
            if per_run > SLOW_ROW:
                eta = f", about {left:.0f} s left" if done < total else ""
                self._print(f"  run {done}/{total} done ({per_run:.1f} s per run{eta})")
            return
        if now - self._last < 0.1 and done != total:
            return
        self._last = now
        self.stream.write("\r" + self.status_line(info, left) + "\033[K")
        self.stream.flush()
        self._drawn = True

    def status_line(self, info: dict[str, Any], left: float) -> str:
        """Return the status bar for a ``"row"`` event, cut to the terminal's width."""
        done, total = info["done"], info["total"]
        bar = "#" * int(_BAR * done / max(total, 1))
        parts = [
            f"{info.get('stage', self.stage)}, iteration {info.get('iteration', '?')} "
            f"[{bar:<{_BAR}}] {done}/{total} runs",
            f"{self.nfev} simulations" if self.nfev else "",
            f"best {fmt(self.best)}" if math.isfinite(self.best) else "",
            # an ETA only once it says something: not before a second run, never "0 s"
            f"ETA {left:.0f} s" if done < total and done >= 2 and left >= 0.5 else "",
        ]
        text = " | ".join(p for p in parts if p)
        width = shutil.get_terminal_size((100, 24)).columns - 1
        return text[:width]

    def _print(self, text: str) -> None:
        if self._drawn:
            self.stream.write("\r\033[K")
            self._drawn = False
        self.stream.write(text + "\n")
        self.stream.flush()
