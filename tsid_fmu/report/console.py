"""Progress display of a running study on the terminal."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

__all__ = ["ConsoleProgress"]


class ConsoleProgress:
    """Print the progress of a study: a live row counter and one line per iteration.

    Parameters
    ----------
    stream : file-like, optional
        Where to print; default ``sys.stderr``.
    """

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stderr
        self.live = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.t0 = time.perf_counter()
        self._last = 0.0

    def __call__(self, event: str, info: dict[str, Any]) -> None:
        """Handle one progress event of :func:`tsid_fmu.identify`."""
        now = time.perf_counter()
        if event == "row":
            self._row(info, now)
        elif event == "iteration":
            self._print(f"{info['stage']}, iteration {info['iteration']}: running the array ...")
        elif event == "iteration done":
            rec = info["record"]
            failed = sum(e is not None for e in rec.errors)
            if self.live:
                self.stream.write("\r" + " " * 70 + "\r")
            fails = f", {failed} failed runs" if failed else ""
            self._print(
                f"{rec.stage}, iteration {rec.index} ({rec.array}{fails}): best cost "
                f"{rec.best_cost:.6g}; {rec.decision.message} [{rec.nfev_total} simulations, "
                f"{now - self.t0:.1f} s]"
            )
        elif event in ("stage", "rerun"):
            self._print(f"== {info['message']}" if event == "stage" else f"  {info['message']}")
        elif event == "refinement":
            self._print(f"== refinement (least squares) from cost {info['cost']:.6g} ...")
        elif event == "refinement done":
            self._print(
                f"refinement: cost {info['cost']:.6g} [{info['nfev']} simulations, "
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
        """Show a live run counter with the time left (on terminals only)."""
        done, total = info["done"], info["total"]
        if not self.live or (now - self._last < 0.1 and done != total):
            return
        self._last = now
        if done == 1 or not hasattr(self, "_row_t0") or done < getattr(self, "_row_done", 0):
            self._row_t0 = now
        self._row_done = done
        rate = (now - self._row_t0) / max(done - 1, 1)
        eta = f", {rate * (total - done):.0f} s left" if rate > 0.2 and done < total else ""
        bar = "#" * int(30 * done / total)
        self.stream.write(f"\r  runs [{bar:<30}] {done}/{total}{eta}   ")
        self.stream.flush()

    def _print(self, text: str) -> None:
        self.stream.write(text + "\n")
        self.stream.flush()
