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
        """Handle one progress event of :func:`tsid_fmu.engine.identify`."""
        now = time.perf_counter()
        if event == "iteration":
            self._print(f"iteration {info['iteration']}/{info['limit']}: running the array ...")
        elif (
            event == "row"
            and self.live
            and (now - self._last > 0.1 or info["done"] == info["total"])
        ):
            self._last = now
            done, total = info["done"], info["total"]
            bar = "#" * int(30 * done / total)
            self.stream.write(f"\r  rows [{bar:<30}] {done}/{total}")
            self.stream.flush()
        elif event == "iteration done":
            rec = info["record"]
            failed = sum(e is not None for e in rec.errors)
            if self.live:
                self.stream.write("\r" + " " * 60 + "\r")
            fails = f", {failed} failed rows" if failed else ""
            self._print(
                f"iteration {rec.index} ({rec.array}, {len(rec.errors)} runs{fails}): "
                f"best cost {rec.best_cost:.6g}; {rec.decision.message} "
                f"[{rec.nfev} simulations, {now - self.t0:.1f} s]"
            )
        elif event == "canonical":
            self._print(
                f"canonical iteration {info['iteration']}/{info['limit']}: running the array ..."
            )
        elif event == "canonical done":
            rec = info["record"]
            state = (
                "converged" if rec.converged else f"spread {max(rec.extra['sn_spread_db']):.2g} dB"
            )
            self._print(
                f"canonical iteration {rec.index} ({rec.array}): best cost {rec.best_cost:.6g} "
                f"(measured input) from {rec.best_source}; {state} "
                f"[{rec.nfev} simulations, {now - self.t0:.1f} s]"
            )
        elif event == "phase":
            self._print(f"== {info['message']}")
        elif event == "rerun":
            self._print(f"  {info['message']}")
        elif event == "done":
            res = info["result"]
            self._print(f"{res.message} after {res.nit} iterations, {res.nfev} simulations")

    def _print(self, text: str) -> None:
        self.stream.write(text + "\n")
        self.stream.flush()
